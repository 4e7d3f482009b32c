"""A secured fleet (`gmmap.fleet.security.access`, `gmmap.fleet.security.door`): only members
connect, read and publish, each only under its own name, and every submap is checked end to end."""

import json
import os
import time
from dataclasses import replace

import pytest
import zenoh

from conftest import wait
from gmmap.config import Config
from gmmap.fleet.net.keys import data_key, listen_port
from gmmap.fleet.net.session import zenoh_config
from gmmap.fleet.node.robot import RobotNode
from gmmap.fleet.security.access import issue_fleet
from gmmap.fleet.security.credentials import add_member, load, revoke
from gmmap.fleet.security.door import CRL_EVERY_S
from gmmap.fleet.security.seal import seal
from gmmap.fleet.wire.codec import encode
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.mapping.submap import SubmapBuilder
from gmmap.options import (
    BackendOptions,
    BuildOptions,
    RobotOptions,
    SecurityOptions,
    SelectOptions,
    TransportOptions,
)

BLOCK = zenoh.CongestionControl.BLOCK
BUILD = BuildOptions(frames_per_submap=2, covariance="full", n_components=60)
_OPEN: list = []


@pytest.fixture(autouse=True)
def _close():
    yield
    while _OPEN:
        _OPEN.pop().close() if not isinstance(_OPEN[-1], RobotNode) else _OPEN.pop().stop()


@pytest.fixture(scope="module")
def frames():
    return TumRgbd(BUNDLED_TUM_SLICE, stride=2)


@pytest.fixture
def fleet(tmp_path):
    """A fleet ``f`` of robots a, b and c and a station; its authority in tmp_path/fleet."""
    members = issue_fleet(tmp_path / "fleet", "f", ["a", "b", "c"])
    return {**members, "station": add_member(tmp_path / "fleet", "station", role="station")}


def node(tmp_path, name, folder, port=None, peers=(), **security) -> RobotNode:
    config = Config(
        robot=RobotOptions(name=name, fleet="f", store=str(tmp_path / f"{name}.db")),
        transport=TransportOptions(
            port=port or listen_port(), connect=[f"tls/127.0.0.1:{p}" for p in peers]
        ),
        build=BUILD,
        backend=BackendOptions(min_matches=1),
        security=SecurityOptions(credentials=None if folder is None else str(folder), **security),
    )
    _OPEN.append(RobotNode(config))
    return _OPEN[-1]


def session(port: int, credentials=None, ca=None) -> zenoh.Session | None:
    """A raw Zenoh session connecting to a robot's port: a member's (its TLS and access
    control), or an intruder's: plain TCP, or with ``ca`` TLS that trusts the fleet's
    authority but brings no certificate of its own. None where Zenoh refuses to open it."""
    plain = credentials is None and ca is None
    options = TransportOptions(connect=[f"{'tcp' if plain else 'tls'}/127.0.0.1:{port}"])
    cfg = zenoh_config(options, (), credentials)
    if ca is not None:
        cfg.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(ca)))
    try:
        _OPEN.append(zenoh.open(cfg))
    except zenoh.ZError:
        return None
    return _OPEN[-1]


def linked(s: zenoh.Session) -> bool:
    return len(list(s.info.peers_zid())) > 0


def submap_bytes(frames, robot: str, seq: int) -> bytes:
    builder = SubmapBuilder(robot, BUILD, SelectOptions())
    builder.seq = seq
    s = builder.add(frames[0]) or builder.add(frames[1])
    return encode(s)


def test_secured_robots_share_signed_submaps_and_strangers_get_nothing(tmp_path, fleet, frames):
    a = node(tmp_path, "a", fleet["a"])
    a.start()
    port = int(a.transport.listen_endpoints[0].rsplit(":", 1)[1])
    heard = []
    for intruder in (session(port), session(port, ca=tmp_path / "fleet" / "ca.pem")):
        if intruder is None:  # refused at once
            continue
        assert not wait(lambda s=intruder: linked(s), 2)
        intruder.declare_subscriber("gmmap/**", heard.append, allowed_origin=zenoh.Locality.REMOTE)
        intruder.put(data_key("f", "b", "submap", 0), submap_bytes(frames, "b", 0))
    b = node(tmp_path, "b", fleet["b"], peers=[port])
    b.start()
    b.start_frames(frames[0:4]).join()
    assert wait(lambda: a.store.seqs("b") == [0, 1])
    assert a.counts["received"] == 2 and a.door.refusals.snapshot() == {}
    assert a.transport.peers() == ["b"] and heard == []
    stored = a.store.submaps()[0].payload
    assert len(stored) == len(a.door.inner(stored)) + 65  # stored as sealed: handed on so


def test_a_member_of_another_fleet_is_refused(tmp_path, fleet, frames):
    other = issue_fleet(tmp_path / "other", "f", ["b"])  # the same names, another authority
    a = node(tmp_path, "a", fleet["a"])
    a.start()
    port = int(a.transport.listen_endpoints[0].rsplit(":", 1)[1])
    b = node(tmp_path, "b", other["b"], peers=[port])
    b.start()
    b.start_frames(frames[0:2]).join()
    time.sleep(1.5)
    assert a.transport.peers() == [] and a.store.robots() == []


def test_a_member_cannot_publish_under_another_robots_name(tmp_path, fleet, frames):
    a = node(tmp_path, "a", fleet["a"])
    a.start()
    port = int(a.transport.listen_endpoints[0].rsplit(":", 1)[1])
    b = load(fleet["b"])
    s = session(port, b)
    assert wait(lambda: linked(s))
    time.sleep(0.5)  # the subscriber's declaration has reached b's session
    forged = seal(b.sign, "f", "c", "submap", 0, submap_bytes(frames, "c", 0))
    s.put(data_key("f", "c", "submap", 0), forged)  # access control drops it at a
    s.put(data_key("f", "b", "submap", 0), seal(b.sign, "f", "b", "submap", 0, b"x" * 700))
    own = seal(b.sign, "f", "b", "submap", 1, submap_bytes(frames, "b", 1))
    s.put(data_key("f", "b", "submap", 1), own)
    assert wait(lambda: a.store.seqs("b") == [1])
    assert a.store.robots() == ["b"]
    assert "c" not in a.door.refusals.snapshot() and a.store.seqs("c") == []
    assert a.counts["decode_errors"] == 1  # b's own seal on bytes that are no submap
    station = load(fleet["station"])
    watcher = session(port, station)
    assert wait(lambda: linked(watcher))
    time.sleep(0.5)
    sealed = seal(station.sign, "f", "station", "submap", 0, submap_bytes(frames, "b", 0))
    watcher.put(data_key("f", "station", "submap", 0), sealed)  # a station only reads
    later = seal(b.sign, "f", "b", "submap", 2, submap_bytes(frames, "b", 2))
    s.put(data_key("f", "b", "submap", 2), later)
    assert wait(lambda: a.store.seqs("b") == [1, 2])  # sent after the station's: it came first
    assert a.store.seqs("station") == [] and "station" not in a.door.refusals.snapshot()


def test_a_relayed_submap_altered_in_transit_is_refused_and_the_original_taken(
    tmp_path, fleet, frames
):
    a = node(tmp_path, "a", fleet["a"])
    original = seal(load(fleet["b"]).sign, "f", "b", "submap", 0, submap_bytes(frames, "b", 0))
    altered = bytearray(original)
    altered[100] ^= 0x40  # c, in between, changes one bit
    a.fetcher.enqueue_fetched("b", 0, bytes(altered))  # as c's fetch reply would bring it
    assert a.door.refusals.snapshot() == {"b": {"bad_signature": 1}}
    a.fetcher.enqueue_fetched("b", 0, original)
    a.start()
    assert wait(lambda: a.store.seqs("b") == [0]) and a.counts["fetched"] == 1


def test_a_replayed_submap_is_ignored_and_a_revoked_robots_are_refused(tmp_path, fleet, frames):
    sign = load(fleet["b"]).sign
    first = seal(sign, "f", "b", "submap", 0, submap_bytes(frames, "b", 0))
    a = node(tmp_path, "a", fleet["a"])
    a.start()
    for _ in range(3):
        a._receive("b", "submap", 0, first)
    a._receive("b", "submap", 1, first)  # replayed under another number
    assert wait(lambda: a.store.seqs("b") == [0]) and a.drain(5)
    assert a.counts["received"] == 1
    assert a.door.refusals.snapshot() == {"b": {"bad_signature": 1}}
    revoke(tmp_path / "fleet", "b")  # refreshes the revocation list in a's folder too
    later = seal(sign, "f", "b", "submap", 1, submap_bytes(frames, "b", 1))
    time.sleep(CRL_EVERY_S + 0.2)  # a running robot looks at its folder's list that often
    a._receive("b", "submap", 1, later)
    assert a.door.refusals.by_cause() == {"bad_signature": 1, "revoked": 1}
    a.stop()
    a = node(tmp_path, "a", fleet["a"])  # restarted: revoked from the start
    a._receive("b", "submap", 1, later)
    assert a.door.refusals.snapshot() == {"b": {"revoked": 1}}
    assert a.store.seqs("b") == [0]  # what it held stays


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:  # resident pages now (not the peak)
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.parametrize("secured", [True, False])
def test_ten_thousand_junk_messages_leave_the_robot_mapping(tmp_path, fleet, frames, secured):
    folder = fleet["a"] if secured else None
    a = node(tmp_path, "a", folder, rate=50.0, burst=200)
    a.start()
    port = int(a.transport.listen_endpoints[0].rsplit(":", 1)[1])
    s = session(port, load(fleet["b"]) if secured else None)
    assert wait(lambda: linked(s))
    time.sleep(0.5)
    before = _rss_mb()
    mapping = a.start_frames(frames[0:8])
    for i in range(10_000):  # b's own name where access control holds it to that; else any
        name = "b" if secured else f"x{i % 3000}"
        junk = (b"\x01" if i % 2 else b"GMMW") + bytes(range(256)) * (1 + i % 4)
        s.put(data_key("f", name, "submap", i), junk, congestion_control=BLOCK)
    too_big = b"z" * (SecurityOptions().max_bytes + 1)
    s.put(data_key("f", "b", "submap", 10_001), too_big, congestion_control=BLOCK)
    mapping.join()

    def turned_away() -> int:  # refused at the door, or bytes that are no submap
        counts = a.door.refusals.snapshot().values()
        return sum(n for by in counts for n in by.values()) + a.counts["decode_errors"]

    ok = wait(lambda: turned_away() == 10_001, 60)  # all of it, and nothing else
    assert ok, (turned_away(), a.door.refusals.by_cause(), a.counts, a.inbox.qsize())
    assert a.transport.stats()["totals"]["received"]["messages"] == 10_001 and a.drain(20)
    assert a.store.seqs("a") == [0, 1, 2, 3] and set(a.store.robots()) == {"a"}
    refused = a.door.refusals.snapshot()
    assert any("rate" in by for by in refused.values())
    assert _rss_mb() - before < 100
    if secured:
        assert refused["b"]["bad_signature"] + refused["b"].get("unsigned", 0) >= 100
    report = a.report()
    assert report["refused_by_sender"] == refused and report["secure"] is secured
    assert report["refused"]["rate"] == sum(by.get("rate", 0) for by in refused.values())


def test_the_secured_demo_joins_the_maps_and_refuses_nothing(tmp_path):
    from gmmap.cli.demo import run_demo

    config = Config()
    config = replace(config, sim=replace(config.sim, robots=2))
    r = run_demo(config, max_frames=80, out=tmp_path / "demo", log=lambda *_: None, secure=True)
    assert r["secure"] is True and r["refused"] == {"robot_0": {}, "robot_1": {}}
    assert all(n > 0 for n in r["received"].values())
    assert (tmp_path / "demo" / "fleet" / "robot_0" / "key.pem").stat().st_mode & 0o077 == 0
