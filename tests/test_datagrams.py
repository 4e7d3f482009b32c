"""Zenoh over UDP (`TransportOptions.protocol`) and its emulated link
(`gmmap.eval.links.datagrams.DatagramRelay`): counts, cap, loss and outages, and robots that catch
up after a link lost what they sent."""

import json
import socket
import threading
import time
from pathlib import Path

import pytest
from test_links import _demo

from conftest import wait
from gmmap.errors import TransportConfigError
from gmmap.eval.links import relayed_pair
from gmmap.eval.links.datagrams import MAX_SENDERS, DatagramRelay, datagram_wire
from gmmap.fleet.net.session import open_session
from gmmap.fleet.storage.store import Store
from gmmap.options import LinkOptions, TransportOptions


@pytest.fixture
def udp_echo():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.1)
    stop = threading.Event()

    def serve() -> None:
        while not stop.is_set():
            try:
                data, addr = sock.recvfrom(65536)
            except TimeoutError:
                continue
            sock.sendto(data, addr)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield sock.getsockname()
    stop.set()
    thread.join()
    sock.close()


def exchange(relay: DatagramRelay, messages: list[bytes], gap_s: float = 0.0) -> list[bytes]:
    """Sends each message through the relay to the echo server; the echoes that came back
    within a second of the last."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect(("127.0.0.1", relay.port))
        for m in messages:
            sock.send(m)
            time.sleep(gap_s)
        sock.settimeout(1.0)
        back = []
        try:
            while len(back) < len(messages):
                back.append(sock.recv(65536))
        except TimeoutError:
            pass
    return back


def test_every_datagram_is_carried_and_counted_with_its_fragments(udp_echo) -> None:
    sizes = [40, 700, 1472, 1473, 3000, 9000]
    messages = [bytes([k]) * n for k, n in enumerate(sizes)]
    with DatagramRelay(udp_echo) as relay:
        assert relay.endpoint.startswith("udp/127.0.0.1:")
        back = exchange(relay, messages, gap_s=0.02)
        counts = relay.counts()
    assert sorted(back) == sorted(messages)
    assert [datagram_wire(n)[0] for n in sizes] == [1, 1, 1, 2, 3, 7]  # 1,480 B of IP payload
    assert datagram_wire(40)[1] == 40 + 8 + 20 + 14  # UDP, IPv4, Ethernet
    for d in counts.values():
        assert d.bytes == sum(sizes) and d.chunks == len(sizes) and d.stalls == 0
        assert d.packets == sum(datagram_wire(n)[0] for n in sizes)
        assert d.wire_bytes == sum(datagram_wire(n)[1] for n in sizes)


def test_the_rate_cap_holds_and_a_full_queue_drops(udp_echo) -> None:
    """30 datagrams of 1 kB at once into 10 kB/s: the queue holds about a second of them,
    which cross at the cap; the rest is dropped, as a radio's full queue drops."""
    start = time.monotonic()
    with DatagramRelay(udp_echo, LinkOptions(rate=10_000)) as relay:
        back = exchange(relay, [bytes(1000)] * 30)
        elapsed = time.monotonic() - start
        counts = relay.counts()
    assert 8 <= counts["forward"].chunks <= 12
    assert len(back) == counts["backward"].chunks <= counts["forward"].chunks
    assert elapsed >= 1.0


@pytest.mark.parametrize("cut", ["outage", "gate"])
def test_what_an_outage_or_a_closed_gate_meets_is_lost_and_not_counted(udp_echo, cut) -> None:
    opened = time.monotonic() + 0.5
    shape = LinkOptions(outages=((0.0, 0.5),)) if cut == "outage" else None
    gate = None if cut == "outage" else (lambda: time.monotonic() >= opened)
    with DatagramRelay(udp_echo, shape, gate=gate) as relay:
        assert exchange(relay, [b"apart"]) == []  # it waits a second: the link is back
        assert relay.counts()["forward"].chunks == 0
        assert exchange(relay, [b"met"]) == [b"met"]
        assert relay.counts()["forward"].bytes == 3


def test_loss_drops_datagrams(udp_echo) -> None:
    with DatagramRelay(udp_echo, LinkOptions(loss=0.5, seed=1)) as relay:
        back = exchange(relay, [bytes([k]) for k in range(200)], gap_s=0.001)
        counts = relay.counts()
    assert 60 <= counts["forward"].chunks <= 140
    assert len(back) == counts["backward"].chunks < counts["forward"].chunks


def test_robots_talk_over_udp_through_the_relay_without_acks() -> None:
    got: list[int] = []
    with relayed_pair(protocol="udp") as (relay, a, b):
        assert a.listen_endpoints[0].startswith("udp/")
        b.subscribe(lambda robot, kind, seq, payload: got.append(seq))
        time.sleep(0.5)  # the subscription reaches a
        before = relay.counts()
        a.publish("submap", 0, bytes(713))
        assert wait(lambda: got == [0])
        time.sleep(0.3)
        after = relay.counts()
    carried = {d: after[d].packets - before[d].packets for d in after}
    assert carried == {"forward": 0, "backward": 1}  # one datagram, no ACK back
    assert 713 < after["backward"].bytes - before["backward"].bytes < 713 + 80


def test_a_protocol_is_checked_and_udp_carries_no_tls() -> None:
    with pytest.raises(TransportConfigError, match="protocol"):
        TransportOptions(protocol="quic")
    with pytest.raises(TransportConfigError, match="TLS"):
        open_session("a", TransportOptions(protocol="udp"), credentials=object())


def test_robots_catch_up_on_what_an_outage_lost(tmp_path: Path) -> None:
    """Over UDP, robots mapping in real time, each submap sent at once: the link is cut from
    2 s to 14 s, shorter than the lease, so they never see each other leave, and what they
    sent meanwhile is lost on the way. Once they hear each other again they tell each other
    what they hold and fetch the gaps: each submap arrives before the sender's last one,
    not at the end, and both end holding everything."""
    config = tmp_path / "outage.yaml"
    config.write_text(
        "link:\n  outages: [[2, 14]]\ntransport:\n  protocol: udp\nsim:\n  pace: 1.0\n"
    )
    flags = ("--config", str(config), "--max-frames", "200", "--bundle", "1", "--deadline", "60")
    _, r = _demo(tmp_path, 2, *flags, timeout=240)
    assert sum(sum(link["dropped"]) for link in r["links"]) > 0
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    reports = {n: json.loads((tmp_path / f"{n}.json").read_text()) for n in r["received"]}
    for a, b in (("robot_0", "robot_1"), ("robot_1", "robot_0")):
        last = reports[a]["submaps_built"] - 1
        assert reports[b]["held"].get(a) == last + 1 > 2, (a, b)
        assert reports[b]["complete"]
        with Store(tmp_path / f"{b}.sqlite", durable=False) as store:
            when = {x.seq: x.received for x in store.submaps() if x.robot == a}
        assert max(when.values()) == when[last], (a, b, when)


def test_a_flood_from_many_senders_gets_no_sockets_beyond_the_cap(udp_echo) -> None:
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(MAX_SENDERS + 8)]
    try:
        with DatagramRelay(udp_echo) as relay:
            for sock in senders:
                sock.sendto(b"x", ("127.0.0.1", relay.port))

            def forward() -> tuple[int, int]:
                count = relay.counts()["forward"]
                return count.chunks, count.dropped

            assert wait(lambda: forward() == (MAX_SENDERS, 8))
            assert exchange(relay, [b"after"]) == []  # a new sender, still over the cap
    finally:
        for sock in senders:
            sock.close()
