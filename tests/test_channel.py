"""Robots on one shared radio channel (`gmmap.eval.links.channel`): a broadcast goes on the air
once for every robot that hears it, and what robots missed they ask for over unicast and hear
again, once for all of them.

Each robot is its own process, as in the field and the demo."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import time

import pytest

from gmmap.errors import TransportConfigError
from gmmap.eval.links.channel import ChannelUnavailable, SharedChannel
from gmmap.fleet.net.air import header, parse
from gmmap.fleet.net.keys import listen_port
from gmmap.options import TransportOptions

GROUP = "udp/224.0.0.224:7447"  # the channel routes it on its loopback
PAYLOAD = 700  # bytes: a submap's wire size

# argv: name, own port, peers' ports, what to do ("send", "listen", "repair" or "peers").
ROBOT = """
import json, sys, time
from gmmap.fleet.net.transport import Transport, TransportConfig, TransportOptions
name, port, peers, role = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
connect = tuple(f"tcp/127.0.0.1:{p}" for p in peers.split(",") if p)
options = TransportOptions(port=port, connect=connect, broadcast=sys.argv[5])
with Transport(TransportConfig("air", name, options)) as t:
    got = []
    t.subscribe(lambda robot, kind, seq, payload: got.append([robot, seq, len(payload)]))
    t.serve(lambda robot, kind, since: [(0, b"s" * 700)] if robot == name else [])
    print("ready", flush=True)
    if role == "send":
        sys.stdin.readline()  # the go
        t.publish("submap", 0, b"s" * 700)
        sys.stdin.readline()
        print(t.stats()["totals"]["sent"]["fetch_messages"], flush=True)  # answers sent
    elif role == "listen":
        deadline = time.monotonic() + 20
        while not got and time.monotonic() < deadline:
            time.sleep(0.05)
        print(json.dumps(got), flush=True)
        sys.stdin.readline()  # leaving would put the session's farewells on the air
    elif role == "repair":  # missed the broadcast: ask its owner over unicast, at the word
        t.wait_for_peers(["r0"], 10)
        print("met", flush=True)
        sys.stdin.readline()
        t.fetch("r0", timeout=5)
        deadline = time.monotonic() + 20
        while not got and time.monotonic() < deadline:
            time.sleep(0.05)
        print(json.dumps(got), flush=True)
        sys.stdin.readline()
    else:  # role "peers": who is present once all are, and after the next line
        t.wait_for_peers({"r0", "r1", "r2"} - {name}, 10)
        print(json.dumps(t.peers()), flush=True)
        sys.stdin.readline()
        time.sleep(0.5)
        print(json.dumps(t.peers()), flush=True)
        sys.stdin.readline()
"""


@pytest.fixture
def channel(request):
    """A shared channel, capped at ``request.param`` B/s where a test parametrizes it."""
    try:
        with SharedChannel(rate=getattr(request, "param", None)) as air:
            yield air
    except ChannelUnavailable as err:
        pytest.skip(f"no shared channel here: {err}")


def _robot(air: SharedChannel, name: str, port: int, peers: list[int], role: str):
    argv = [sys.executable, "-c", ROBOT, name, str(port), ",".join(map(str, peers)), role, GROUP]
    p = subprocess.Popen(
        air.command(argv), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert p.stdout.readline().strip() == "ready"
    return p


def test_one_broadcast_reaches_both_peers_and_crosses_the_air_once(channel):
    ports = [listen_port() for _ in range(3)]
    sender = _robot(channel, "r0", ports[0], [], "send")
    listeners = [_robot(channel, f"r{i}", ports[i], ports[:i], "listen") for i in (1, 2)]
    try:
        time.sleep(1.0)  # the unicast links settle: their traffic stays out of the count
        before = channel.bytes_sent()
        sender.stdin.write("go\n")
        sender.stdin.flush()
        heard = [json.loads(p.stdout.readline()) for p in listeners]
        on_air = channel.bytes_sent() - before
    finally:
        for p in (sender, *listeners):
            p.stdin.write("done\n")
            p.stdin.flush()
            p.wait(timeout=20)
    assert heard == [[["r0", 0, PAYLOAD]], [["r0", 0, PAYLOAD]]]
    # Once on the air, with its key and the UDP/IP headers; unicast to each peer would be
    # twice the payload at least.
    assert PAYLOAD <= on_air < 1.5 * PAYLOAD, on_air


def test_robots_that_missed_a_broadcast_fetch_it_and_hear_it_again_once(channel):
    """Two robots ask the owner over unicast for the submap they missed, at once: it goes on
    the air again once, for both, not once per asker."""
    ports = [listen_port() for _ in range(3)]
    sender = _robot(channel, "r0", ports[0], [], "send")
    late = []
    try:
        _say(sender, "go")  # nobody listens yet: the broadcast is lost to all
        late = [_robot(channel, f"r{i}", ports[i], ports[:1], "repair") for i in (1, 2)]
        assert [p.stdout.readline().strip() for p in late] == ["met", "met"]
        for p in late:
            _say(p, "fetch")
        heard = [json.loads(p.stdout.readline()) for p in late]
        _say(sender, "done")
        answers = json.loads(sender.stdout.readline())
    finally:
        for p in (sender, *late):
            with contextlib.suppress(OSError):
                _say(p, "done", "done")
            p.wait(timeout=20)
    assert heard == [[["r0", 0, PAYLOAD]], [["r0", 0, PAYLOAD]]]
    assert answers == 1


def test_robots_on_a_channel_meet_and_part_by_greetings_alone(channel):
    """Presence on a shared channel is what is heard on it: no unicast session opens, and a
    robot that leaves is gone for the others at once."""
    ports = [listen_port() for _ in range(3)]
    before = channel.bytes_sent()
    robots = [_robot(channel, f"r{i}", ports[i], ports[:i], "peers") for i in range(3)]
    try:
        met = [json.loads(p.stdout.readline()) for p in robots]
        on_air = channel.bytes_sent() - before
        _say(robots[2], "who", "leave")
        robots[2].wait(timeout=20)
        _say(robots[0], "who")
        after = json.loads(robots[0].stdout.readline())
    finally:
        for p in robots:
            with contextlib.suppress(OSError):
                _say(p, "done", "done")
            p.wait(timeout=20)
    assert met == [["r1", "r2"], ["r0", "r2"], ["r0", "r1"]]
    # Three greetings and at most one answer per pair, ~60 B each: one Zenoh session's
    # handshakes and declarations alone take ~960 B.
    assert on_air < 600, on_air
    assert after == ["r1"]


def _say(p: subprocess.Popen, *lines: str) -> None:
    p.stdin.write("".join(f"{line}\n" for line in lines))
    p.stdin.flush()


def test_a_datagram_on_the_air_carries_its_message_in_a_compact_header():
    message = ("demo", "robot_0", "submap", 12)
    datagram = header(*message) + b"payload"
    assert len(header(*message)) == 17  # the key expression alone would take 28
    assert parse(datagram) == (message, b"payload")
    late = ("demo", "robot_0", "have", 1_733_400_000_000)  # adverts count milliseconds
    assert parse(header(*late)) == (late, b"")
    other = ("demo", "robot_0", "odd-kind", 3)
    assert parse(header(*other) + b"x") == (other, b"x")
    for bad in (datagram[:9], b"GMA1" + datagram[2:], b"G2\x02..\x01r\x00\x00", b""):
        assert parse(bad) is None, bad


@pytest.mark.parametrize(
    "group",
    [
        "udp/10.0.0.1:7447",
        "tcp/224.0.0.224:7447",
        "udp/224.0.0.224",
        "udp/[ff02::1]:7447",
        "multicast",
        GROUP + "#lo",
    ],
)
def test_a_broadcast_group_must_be_udp_multicast(group):
    with pytest.raises(TransportConfigError, match="broadcast must be udp"):
        TransportOptions(broadcast=group)
    assert TransportOptions(broadcast=GROUP + "#iface=lo").broadcast == GROUP + "#iface=lo"


def test_handshakes_wait_for_a_slow_channel():
    from gmmap.fleet.net.session import handshake_timeout_ms, zenoh_config

    assert handshake_timeout_ms(None) == handshake_timeout_ms(10_000) == 10_000
    assert handshake_timeout_ms(500) == 30_000 and handshake_timeout_ms(250) == 60_000
    config = zenoh_config(TransportOptions(broadcast=GROUP, channel_rate=500), ())
    assert config.get_json("transport/unicast/open_timeout") == "30000"


@pytest.mark.parametrize("channel", [500], indirect=True)
def test_a_fleet_on_a_500_bytes_per_second_channel_loses_nothing(channel):
    """Three robots, the demo's first 60 frames each, one channel of 500 B/s for all: every
    submap reaches every robot, and the whole run stays within the channel's rate."""
    gmmap = [sys.executable, "-c", "from gmmap.cli import main; main()"]
    args = ["demo", "--json", "--max-frames", "60", "--linger", "2", "--broadcast", GROUP]
    before = channel.bytes_sent()
    start = time.monotonic()
    done = subprocess.run(
        channel.command([*gmmap, *args, "--channel-rate", "500"]),
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    seconds, on_air = time.monotonic() - start, channel.bytes_sent() - before
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert sum(report["lost"].values()) == 0, report["lost"]
    assert all(n > 0 for n in report["received"].values()), report["received"]
    assert on_air <= 500 * seconds + 1600  # the kernel, not gmmap, held the fleet to 500 B/s
