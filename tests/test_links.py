"""The emulated link (`gmmap.eval.links`): counts, rate cap, stalls, outages, and Zenoh
through it."""

import json
import os
import socket
import socketserver
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from conftest import wait
from gmmap.cli.demo import rendezvous
from gmmap.config import load_config
from gmmap.errors import InvalidInputError
from gmmap.eval.fleetplots import completeness
from gmmap.eval.links import (
    HEADER_BYTES,
    TIMESTAMP_BYTES,
    ZENOH_NO_GOSSIP,
    Relay,
    Rendezvous,
    relayed_pair,
)
from gmmap.eval.links.datagrams import DatagramRelay
from gmmap.fleet.net.keys import listen_port
from gmmap.fleet.storage.store import Store
from gmmap.options import LinkOptions


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
    for d in counts.values():  # the kernel's packets, each with its headers
        assert d.packets >= len(payload) // 65536 + 2  # the handshake and the data
        assert d.wire_bytes >= d.bytes + d.packets * HEADER_BYTES


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


def test_nothing_crosses_while_the_gate_is_closed(echo) -> None:
    """A rendezvous link apart: the bytes wait, and go once the robots meet again."""
    opened = time.monotonic() + 0.6
    with Relay(echo, gate=lambda: time.monotonic() >= opened) as relay:
        back, elapsed = round_trip(relay, b"ping")
    assert back == b"ping" and elapsed >= 0.5


def test_what_a_closed_link_never_carried_is_not_counted(echo) -> None:
    """The relay's kernel takes in what is sent while the gate is closed; if the link never
    opens again, none of it counts on the wire, only the handshake and the ACKs."""
    payload = b"x" * 20_000
    with Relay(echo, gate=lambda: False) as relay:
        with socket.create_connection(("127.0.0.1", relay.port), timeout=5) as sock:
            sock.sendall(payload)
            time.sleep(0.3)
        time.sleep(0.3)
        counts = relay.counts()
    forward = counts["forward"]
    assert forward.bytes == 0
    assert forward.wire_bytes < 20 * (HEADER_BYTES + TIMESTAMP_BYTES) < len(payload)


def test_rendezvous_follows_where_the_robots_are() -> None:
    """In reach within the range and, with a sight test, only where nothing is in between;
    the robots move one frame per second of the clock, and a robot past its last frame stays
    where it ended."""
    now = [0.0]
    tracks = [np.array([[0.0, 0, 0], [0, 0, 0]]), np.array([[10.0, 0, 0], [3, 0, 0], [4, 0, 0]])]
    reach = Rendezvous(tracks, range_m=5.0, start=0.0, fps=1.0, clock=lambda: now[0])
    assert not reach.up(0, 1) and reach.frame() == 0
    now[0] = 1.5
    assert reach.up(0, 1) and reach.gate(0, 1)()
    now[0] = 9.0  # robot 0 ended at frame 1, robot 1 at frame 2, 4 m apart
    assert reach.frame() == 9 and reach.up(0, 1)
    assert not reach.up(0, 1, frame=0)
    wall = Rendezvous(tracks, range_m=None, sight=lambda a, b: a[0] == b[0], clock=lambda: 1.0)
    assert not wall.up(0, 1)


def test_the_office_walls_block_the_line_of_sight() -> None:
    from gmmap.io.sim import get_world

    office = get_world("office")
    lo, hi = office.bounds()
    inside = (lo + hi) / 2
    assert office.in_sight(inside, inside)
    assert not office.in_sight(lo - 1.0, hi + 1.0)  # through every wall in between


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
        dict(range_m=0.0),
        dict(range_m=5.0, topology="router"),
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

    port = listen_port()
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


def test_a_bundle_shares_packets_and_segments_are_ethernet_sized() -> None:
    """Messages put back to back leave in one Zenoh batch: fewer packets than the same
    messages apart. And the relay's sockets offer Ethernet's segment size, so a message
    over 1,448 B is counted as the several packets it would be on a radio link."""
    got: list[int] = []
    with relayed_pair() as (relay, a, b):
        b.subscribe(lambda robot, kind, seq, payload: got.append(seq))
        time.sleep(0.5)  # the subscription reaches a

        def packets(send) -> int:
            before, n = relay.counts(), len(got)
            send()
            assert wait(lambda: len(got) > n)
            time.sleep(0.3)  # the ACKs
            after = relay.counts()
            return sum(after[d].packets - before[d].packets for d in after)

        def apart() -> None:
            for seq in range(4):
                a.publish("submap", seq, bytes(750))
                time.sleep(0.2)

        bundled = packets(lambda: [a.publish("submap", 10 + s, bytes(750)) for s in range(4)])
        separate = packets(apart)
        big = packets(lambda: a.publish("submap", 20, bytes(6000)))
    assert sorted(got)[:4] == [0, 1, 2, 3] and len(got) == 9
    assert separate >= 8  # each message its packet and an ACK
    assert bundled < separate
    assert big >= 5  # 6,000 B in 1,448-byte segments, and at least one ACK


def _demo(tmp_path: Path, robots: int, *flags: str, timeout: float) -> tuple:
    """``gmmap demo`` with ``robots`` robot processes, lingering 1.5 s and joining on one
    match, its output in ``tmp_path``: what the robots said (stderr) and its JSON summary."""
    out = subprocess.run(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "demo",
         "--robots", str(robots), "--linger", "1.5", "--out", str(tmp_path), "--json",
         "--min-matches", "1", *flags],
        capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    return out.stderr, json.loads(out.stdout)


def test_robots_behind_500_bytes_per_second_deliver_everything(tmp_path):
    """Two robot processes talk only through a relay capped at 500 B/s each way, slower than
    they build submaps: neither quits before the other holds all it holds. Every payload byte
    a robot received crossed the relay, with Zenoh's own traffic on top."""
    _, r = _demo(tmp_path, 2, "--link-rate", "500", "--deadline", "40", timeout=180)
    print(json.dumps({k: r[k] for k in ("wire", "lost", "received", "bytes_received")}))
    assert load_config(tmp_path / "robot_0.yaml").transport.connect != ()
    assert [link["robots"] for link in r["links"]] == [["robot_0", "robot_1"]]
    for name, wire in r["wire"].items():  # what arrived crossed the relay, and more
        assert wire["received_bytes"] > r["bytes_received"][name] > 0
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    assert r["wire_bytes_per_delivered_submap"] > r["bytes_per_submap"]["wire"]
    for name in r["received"]:  # each ended because the other held everything, not by deadline
        assert json.loads((tmp_path / f"{name}.json").read_text())["complete"], name


def test_a_rendezvous_link_delivers_the_backlog_when_the_robots_meet(tmp_path) -> None:
    """Robots 0 and 1 start 8.5 m apart and come within 8 m after about 45 frames: each has
    built two submaps by then, kept them, and delivers them once the link is up."""
    _, r = _demo(
        tmp_path, 2, "--link-range", "8", "--max-frames", "120", "--deadline", "60", timeout=240
    )
    config = load_config(tmp_path / "robot_0.yaml")
    assert config.robot.wait_for == ()  # apart at the start
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    assert r["out_of_reach"] == {"robot_0": 0, "robot_1": 0}  # they stay together
    reach = rendezvous(config, 120)
    met = next(k for k in range(120) if reach.up(0, 1, frame=k))
    assert met >= 40, met  # two submaps of 20 frames each built apart
    with Store(tmp_path / "robot_1.sqlite", durable=False) as store:
        when = {(x.robot, x.seq): x.received for x in store.submaps()}
    assert when[("robot_0", 0)] >= config.sim.start + met / (config.sim.rate * config.sim.pace)
    for name in r["received"]:
        assert json.loads((tmp_path / f"{name}.json").read_text())["complete"], name


def test_a_partition_heals_and_nothing_is_lost(tmp_path) -> None:
    """The link is cut from 4 s to 16 s, long enough for a 10 s Zenoh lease to expire: each
    robot sees the other leave without saying it is done and waits; both end holding
    everything."""
    config = tmp_path / "outage.yaml"
    lease = "transport:\n  zenoh_options:\n    transport/link/tx/lease: 10000\n"
    config.write_text("link:\n  outages: [[4, 16]]\n" + lease)
    said, r = _demo(tmp_path, 2, "--config", str(config), timeout=180)
    assert "waiting for" in said
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    assert r["received"]["robot_0"] > 0 and r["received"]["robot_1"] > 0


def test_a_robot_reaches_another_only_through_a_third(tmp_path) -> None:
    """Three robots in a chain (0 - 1 - 2, no link between 0 and 2): robot_1 hands each end's
    submaps on to the other, and every robot ends holding everything."""
    flags = ("--link-topology", "chain", "--deadline", "60", "--max-frames", "120")
    _, r = _demo(tmp_path, 3, *flags, "--plots", str(tmp_path / "plots"), timeout=240)
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
    # Each robot's completeness over time, from its store, ends at every submap held.
    curves = completeness({n: tmp_path / f"{n}.sqlite" for n in reports})
    assert all(share[-1] == 1.0 and np.all(np.diff(t) >= 0) for t, share in curves.values())
    assert [Path(p).name for p in r["plots"]] == ["bytes.png", "completeness.png"]
    assert all(Path(p).read_bytes()[:4] == b"\x89PNG" for p in r["plots"])


NETNS_CLIENT = """
import socket, sys, time
sock = socket.create_connection((sys.argv[1], int(sys.argv[2])), timeout=30)
for k in range(300):  # small and large messages, each echoed before the next
    message = bytes([k % 256]) * (40 + (k * 997) % 3000)
    sock.sendall(message)
    got = 0
    while got < len(message):
        got += len(sock.recv(65536))
time.sleep(0.3)  # the last ACKs
sock.close()
"""
NETNS_ECHO = """
import socket, sys
server = socket.create_server((sys.argv[1], int(sys.argv[2])))
print("ready", flush=True)
conn, _ = server.accept()
while data := conn.recv(65536):
    conn.sendall(data)
"""


# Without ethtool: its legacy ioctls, TSO and GSO off, so that the kernel hands the veth pair
# packets no larger than the MTU, as a real interface puts them on the wire.
NO_OFFLOADS = """
import ctypes, fcntl, socket, struct, sys
for cmd in (0x1F, 0x24):  # ETHTOOL_STSO, ETHTOOL_SGSO
    value = ctypes.create_string_buffer(struct.pack("II", cmd, 0))
    request = struct.pack("16sP", sys.argv[1].encode(), ctypes.addressof(value))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        fcntl.ioctl(sock.fileno(), 0x8946, request)  # SIOCETHTOOL
"""


def _run(*cmd: str, ns: str | None = None) -> None:
    where = ["ip", "netns", "exec", ns] if ns else []
    subprocess.run([*where, *cmd], check=True, capture_output=True, timeout=10)


def _rx(dev: str) -> tuple[int, int]:
    """Packets and bytes ``dev`` received: what its namespace's side sent."""
    stats = [f"/sys/class/net/{dev}/statistics/rx_{k}" for k in ("packets", "bytes")]
    return tuple(int(Path(f).read_text()) for f in stats)


@pytest.fixture
def namespaces():
    """Two network namespaces, each joined to this one by a veth pair with IPv6 off, so that
    only the test's traffic and ARP cross it. Yields per namespace (name, our address, its
    address, our device)."""
    made, out = [], []
    try:
        for k in (1, 2):
            ns, ours, theirs = f"gmmap{os.getpid()}n{k}", f"gmv{os.getpid()}n{k}", "gmw"
            _run("ip", "netns", "add", ns)
            made.append((ns, ours))
            _run("ip", "link", "add", ours, "type", "veth", "peer", "name", theirs, "netns", ns)
            _run("sysctl", "-qw", f"net.ipv6.conf.{ours}.disable_ipv6=1")
            _run("sysctl", "-qw", f"net.ipv6.conf.{theirs}.disable_ipv6=1", ns=ns)
            _run("ip", "addr", "add", f"10.{k}.77.1/24", "dev", ours)
            _run("ip", "link", "set", ours, "up")
            _run("ip", "addr", "add", f"10.{k}.77.2/24", "dev", theirs, ns=ns)
            _run("ip", "link", "set", theirs, "up", ns=ns)
            _run(sys.executable, "-c", NO_OFFLOADS, ours)
            _run(sys.executable, "-c", NO_OFFLOADS, theirs, ns=ns)
            out.append((ns, f"10.{k}.77.1", f"10.{k}.77.2", ours))
    except (OSError, subprocess.SubprocessError) as err:
        _remove(made)
        pytest.skip(f"cannot make network namespaces here (needs root and iproute2): {err}")
    yield out
    _remove(made)


def _remove(made: list[tuple[str, str]]) -> None:
    for ns, dev in made:
        subprocess.run(["ip", "link", "del", dev], capture_output=True, timeout=10)
        subprocess.run(["ip", "netns", "del", ns], capture_output=True, timeout=10)


NETNS_UDP_CLIENT = """
import socket, sys, time
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.connect((sys.argv[1], int(sys.argv[2])))
sock.settimeout(5)
for k in range(300):  # small datagrams and ones over Ethernet's MTU, each echoed before the next
    sock.send(bytes([k % 256]) * (40 + (k * 997) % 3000))
    sock.recv(65536)
time.sleep(0.3)
"""
NETNS_UDP_ECHO = """
import socket, sys
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind((sys.argv[1], int(sys.argv[2])))
print("ready", flush=True)
while True:
    data, addr = sock.recvfrom(65536)
    sock.sendto(data, addr)
"""


def _through_relay(namespaces, relay_class, echo_script: str, client_script: str) -> tuple:
    """A client in one namespace talks through a relay (here) to an echo server in another:
    per direction, the relay's counts and what the veth pair on that side carried (packets,
    bytes)."""
    (ns_a, here_a, _, dev_a), (ns_b, _, there_b, dev_b) = namespaces
    port = listen_port()
    echo = [sys.executable, "-c", echo_script, there_b, str(port)]
    server = subprocess.Popen(["ip", "netns", "exec", ns_b, *echo], stdout=subprocess.PIPE)
    try:
        assert server.stdout.readline().strip() == b"ready"
        with relay_class((there_b, port), host=here_a) as relay:
            before = _rx(dev_a), _rx(dev_b)
            _run(sys.executable, "-c", client_script, here_a, str(relay.port), ns=ns_a)
            time.sleep(0.3)
            after = _rx(dev_a), _rx(dev_b)
            counts = relay.counts()
    finally:
        server.kill()
        server.wait()
    out = []
    for name, was, now in zip(("forward", "backward"), before, after, strict=True):
        packets, size = now[0] - was[0], now[1] - was[1]
        d = counts[name]
        print(f"{name}: relay {d.packets} packets {d.wire_bytes} B, interface {packets} {size}")
        assert abs(d.packets - packets) <= 0.05 * packets, (name, d, packets)
        assert abs(d.wire_bytes - size) <= 0.05 * size, (name, d, size)
        out.append(d)
    return tuple(out)


def test_wire_accounting_matches_an_interface_counter(namespaces) -> None:
    """What the relay reports for each direction, packets and bytes with headers, is what the
    veth pair on that side carried, within 5 %."""
    for d in _through_relay(namespaces, Relay, NETNS_ECHO, NETNS_CLIENT):
        assert d.bytes > 400_000


def test_datagram_accounting_matches_an_interface_counter(namespaces) -> None:
    """The same over UDP (`DatagramRelay`): datagrams, their IP fragments and headers."""
    for d in _through_relay(namespaces, DatagramRelay, NETNS_UDP_ECHO, NETNS_UDP_CLIENT):
        assert d.chunks == 300 and d.packets > d.chunks  # the large ones went as fragments


def test_robots_as_clients_of_one_router(tmp_path) -> None:
    """Three robots, each a Zenoh client linked only to one router: it routes their submaps,
    adverts and fetches, and every robot ends holding everything."""
    flags = ("--link-topology", "router", "--deadline", "60", "--max-frames", "120")
    _, r = _demo(tmp_path, 3, *flags, timeout=240)
    assert [link["robots"] for link in r["links"]] == [[n, "router"] for n in r["received"]]
    transport = load_config(tmp_path / "robot_0.yaml").transport
    assert transport.mode == "client" and transport.listen == ()
    reports = {n: json.loads((tmp_path / f"{n}.json").read_text()) for n in r["received"]}
    built = {n: rep["submaps_built"] for n, rep in reports.items()}
    assert all(rep["held"] == built for rep in reports.values()), (built, reports)
    assert r["lost"] == {"robot_0": 0, "robot_1": 0, "robot_2": 0}
    for name, wire in r["wire"].items():  # it sent its submaps and received the others'
        assert wire["bytes"] > 0 and wire["received_bytes"] > r["bytes_received"][name] > 0
