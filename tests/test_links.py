"""The emulated link (`gmmap.fleet.links`): counts, rate cap, stalls, outages, and Zenoh
through it."""

import json
import socket
import socketserver
import subprocess
import sys
import threading
import time

import pytest
import zenoh

from gmmap.config import load_config
from gmmap.errors import InvalidInputError
from gmmap.fleet.keys import free_port
from gmmap.fleet.links import ZENOH_NO_GOSSIP, LinkOptions, Relay


class _Echo(socketserver.BaseRequestHandler):
    def handle(self) -> None:
        while data := self.request.recv(65536):
            self.request.sendall(data)


@pytest.fixture
def echo():
    server = socketserver.ThreadingTCPServer(("127.0.0.1", 0), _Echo)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server.server_address
    server.shutdown()
    server.server_close()


def round_trip(relay: Relay, payload: bytes) -> tuple[bytes, float]:
    """Sends ``payload`` through the relay to the echo server; what came back and how long."""
    start = time.monotonic()
    with socket.create_connection(("127.0.0.1", relay.port), timeout=30) as sock:
        sender = threading.Thread(target=sock.sendall, args=(payload,))
        sender.start()
        back = b""
        while len(back) < len(payload):
            chunk = sock.recv(65536)
            assert chunk, "the relay closed early"
            back += chunk
        sender.join()
    return back, time.monotonic() - start


def test_every_byte_is_carried_and_counted(echo) -> None:
    payload = bytes(range(256)) * 400
    with Relay(echo) as relay:
        back, _ = round_trip(relay, payload)
        time.sleep(0.05)
        counts = relay.counts()
    assert back == payload
    assert counts["forward"].bytes == counts["backward"].bytes == len(payload)
    assert counts["forward"].chunks >= 1


def test_the_rate_cap_holds(echo) -> None:
    """20 kB each way at 40 kB/s: the round trip cannot take less than half a second."""
    payload = b"x" * 20_000
    with Relay(echo, LinkOptions(rate=40_000)) as relay:
        back, elapsed = round_trip(relay, payload)
    assert back == payload
    assert elapsed >= 0.45


def test_nothing_crosses_during_an_outage(echo) -> None:
    with Relay(echo, LinkOptions(outages=((0.0, 0.8),))) as relay:
        back, elapsed = round_trip(relay, b"ping")
    assert back == b"ping" and elapsed >= 0.7


def test_loss_is_a_stall_not_missing_bytes(echo) -> None:
    payload = bytes(range(256)) * 100
    with Relay(echo, LinkOptions(rate=200_000, loss=0.3, stall_s=0.01, seed=3)) as relay:
        back, _ = round_trip(relay, payload)
        time.sleep(0.05)
        counts = relay.counts()
    assert back == payload
    assert counts["forward"].stalls + counts["backward"].stalls > 0


def test_bad_shapes_are_refused() -> None:
    for bad in (
        dict(rate=0.0),
        dict(rate=float("nan")),
        dict(delay_s=-1.0),
        dict(loss=1.0),
        dict(outages=((2.0, 1.0),)),
    ):
        with pytest.raises(InvalidInputError):
            LinkOptions(**bad)


def test_zenoh_peers_talk_through_the_relay_and_it_sees_the_framing() -> None:
    """A listens; B reaches A only through the relay (gossip off). Everything B receives
    crossed the relay, Zenoh's framing and session traffic on top of the payload."""

    def config(listen: list[str], connect: list[str]) -> zenoh.Config:
        cfg = zenoh.Config()
        cfg.insert_json5("mode", '"peer"')
        cfg.insert_json5("listen/endpoints", str(listen).replace("'", '"'))
        cfg.insert_json5("connect/endpoints", str(connect).replace("'", '"'))
        cfg.insert_json5("scouting/multicast/enabled", "false")
        for key, value in ZENOH_NO_GOSSIP.items():
            cfg.insert_json5(key, "false" if value is False else str(value))
        return cfg

    port = free_port()
    received: list[bytes] = []
    with Relay(("127.0.0.1", port)) as relay:
        a = zenoh.open(config([f"tcp/127.0.0.1:{port}"], []))
        b = zenoh.open(config([], [relay.endpoint]))
        try:
            sub = b.declare_subscriber(
                "test/links/**", lambda s: received.append(s.payload.to_bytes())
            )
            deadline = time.monotonic() + 10
            while not list(a.info.peers_zid()) and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(0.3)  # the subscription reaches A
            for k in range(10):
                a.put(f"test/links/{k}", bytes([k]) * 1000)
            while len(received) < 10 and time.monotonic() < deadline:
                time.sleep(0.05)
            sub.undeclare()
        finally:
            b.close()
            a.close()
        counts = relay.counts()
    assert len(received) == 10 and all(len(r) == 1000 for r in received)
    assert counts["backward"].bytes > 10 * 1000  # A → B: payload plus framing
    assert counts["forward"].bytes > 0  # B's handshake and subscription


def test_robots_behind_500_bytes_per_second_deliver_everything(tmp_path):
    """Two robot processes talk only through a relay capped at 500 B/s each way, slower than
    they build submaps: neither quits before the other holds all it holds. Every payload byte
    a robot received crossed the relay, with Zenoh's own traffic on top."""
    out = subprocess.run(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "demo", "--robots", "2",
         "--linger", "1.5", "--out", str(tmp_path), "--json", "--min-matches", "1",
         "--link-rate", "500", "--deadline", "40"],
        capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    print(json.dumps({k: r[k] for k in ("wire", "lost", "received", "bytes_received")}))
    assert load_config(tmp_path / "robot_0.yaml").transport.connect != ()
    assert [link["robots"] for link in r["links"]] == [["robot_0", "robot_1"]]
    for name, wire in r["wire"].items():  # what arrived crossed the relay, and more
        assert wire["received_bytes"] > r["bytes_received"][name] > 0
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    assert r["wire_bytes_per_delivered_submap"] > r["bytes_per_submap"]["wire"]


def test_a_partition_heals_and_nothing_is_lost(tmp_path) -> None:
    """The link is cut from 4 s to 16 s, long enough for Zenoh's lease to expire: each robot
    sees the other leave without saying it is done and waits; both end holding everything."""
    config = tmp_path / "outage.yaml"
    config.write_text("link:\n  outages: [[4, 16]]\n")
    out = subprocess.run(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "demo", "--robots", "2",
         "--linger", "1.5", "--out", str(tmp_path), "--json", "--min-matches", "1",
         "--config", str(config)],
        capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert "waiting for" in out.stderr
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    assert r["received"]["robot_0"] > 0 and r["received"]["robot_1"] > 0


def test_a_robot_reaches_another_only_through_a_third(tmp_path) -> None:
    """Three robots in a chain (0 - 1 - 2, no link between 0 and 2): robot_1 hands each end's
    submaps on to the other, and every robot ends holding everything."""
    out = subprocess.run(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "demo", "--robots", "3",
         "--linger", "1.5", "--out", str(tmp_path), "--json", "--min-matches", "1",
         "--link-topology", "chain", "--deadline", "60", "--max-frames", "120"],
        capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert [link["robots"] for link in r["links"]] == [
        ["robot_0", "robot_1"],
        ["robot_1", "robot_2"],
    ]
    assert load_config(tmp_path / "robot_0.yaml").robot.wait_for == ("robot_1",)
    reports = {n: json.loads((tmp_path / f"{n}.json").read_text()) for n in r["received"]}
    for a, b in (("robot_0", "robot_2"), ("robot_2", "robot_0")):
        built = reports[a]["submaps_built"]
        assert built > 0 and reports[b]["held"].get(a) == built, (a, b)
    assert r["lost"] == {"robot_0": 0, "robot_1": 0, "robot_2": 0}
