"""The robot node: submap exchange between processes over loopback Zenoh, restart, fleets."""

import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from conftest import wait
from gmmap.config import Config, load_config
from gmmap.eval.links import ZENOH_NO_GOSSIP
from gmmap.eval.registration import pose_errors
from gmmap.fleet.net.keys import listen_port
from gmmap.fleet.node.robot import RobotNode
from gmmap.fleet.storage.store import Store
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.options import BackendOptions, BuildOptions, RobotOptions, TransportOptions

SLICE_BUILD = BuildOptions(frames_per_submap=2, covariance="full", n_components=60)
# The bundled slice's two-frame submaps give one or two matches per robot pair: let one join.
SLICE_BACKEND = BackendOptions(min_matches=1)


def robot_cmd(name, fleet, port, peers, store, report, frames, *extra):
    cmd = [
        sys.executable, "-c", "from gmmap.cli import main; main()", "robot",
        "--id", name, "--fleet", fleet, "--data", str(BUNDLED_TUM_SLICE), "--stride", "2",
        "--frames", frames, "--frames-per-submap", "2", "--covariance", "full",
        "--components", "60", "--port", str(port), "--store", str(store),
        "--report", str(report), "--linger", "1.5", "--min-matches", "1", "--json",
        *extra,
    ]  # fmt: skip
    for p in peers:
        cmd += ["--peer", f"tcp/127.0.0.1:{p}"]
    return cmd


def test_two_robot_processes_share_submaps_and_agree_on_the_identity(tmp_path):
    """The bundled slice split in two robots (frames 0-3 and 4-7: the same desk, one mocap
    frame, so the true relative frame is the identity), each a process."""
    pa, pb = listen_port(), listen_port()
    fleet = f"t{os.getpid()}"
    procs = [
        subprocess.Popen(
            robot_cmd(
                n,
                fleet,
                port,
                [other],
                tmp_path / f"{n}.db",
                tmp_path / f"{n}.json",
                frames,
                "--wait-for",
                peer,
            ),
            stdout=subprocess.PIPE,
            text=True,
        )
        for n, port, other, peer, frames in (("a", pa, pb, "b", "0:4"), ("b", pb, pa, "a", "4:8"))
    ]
    outs = [p.communicate(timeout=60)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0]
    lines = [json.loads(x) for out in outs for x in out.splitlines()]
    assert {(x["robot"], x["seq"]) for x in lines} == {("a", 0), ("a", 1), ("b", 0), ("b", 1)}
    assert all(0 < x["bytes"] <= 1024 for x in lines)
    for name, other in (("a", "b"), ("b", "a")):
        with Store(tmp_path / f"{name}.db") as store:
            assert store.seqs(other) == [0, 1] and store.seqs(name) == [0, 1]
        r = json.loads((tmp_path / f"{name}.json").read_text())
        assert r["submaps_built"] == 2 and r["held"] == {"a": 2, "b": 2}
        assert r["groups"] == [["a", "b"]] and r["matches_accepted"] >= 1
        t, deg = pose_errors(np.array(r["to_reference"]["b"]), np.eye(4))
        assert t < 0.05 and deg < 2.0
        for robot in ("a", "b"):  # every held robot's anchors, in the reference frame
            traj = tmp_path / f"{name}.trajectory_{robot}.txt"
            assert r["trajectories"] and len(traj.read_text().splitlines()) == 1 + 2
        stats = r["bytes"]["by_robot_and_kind"]
        sent = stats["sent"][name]["submap"]  # published, plus fetch replies served
        published = sent["payload_bytes"] - sent["fetch_payload_bytes"]
        assert published == sum(s["wire"] for s in r["submaps"])
        assert stats["received"][other]["submap"]["messages"] >= 2


@pytest.fixture(scope="module")
def frames():
    return TumRgbd(BUNDLED_TUM_SLICE, stride=2)


_OPEN: list[RobotNode] = []


@pytest.fixture(autouse=True)
def _close_nodes():
    """Every node a test opened is closed, even when the test fails half-way (an open Zenoh
    session would outlive the test and keep the interpreter from exiting)."""
    yield
    while _OPEN:
        _OPEN.pop().stop()


def node(tmp_path, name, port, peers=(), fleet="f", zenoh=None):
    config = Config(
        # Each submap at once: these tests are about what arrives, not when.
        robot=RobotOptions(name=name, fleet=fleet, store=str(tmp_path / f"{name}.db"), bundle=1),
        transport=TransportOptions(
            port=port, connect=[f"tcp/127.0.0.1:{p}" for p in peers], zenoh_options=zenoh or {}
        ),
        build=SLICE_BUILD,
        backend=SLICE_BACKEND,
    )
    _OPEN.append(RobotNode(config))
    return _OPEN[-1]


def test_restarted_robot_reloads_its_store_and_fetches_what_it_missed(tmp_path, frames):
    pa, pb = listen_port(), listen_port()
    b = node(tmp_path, "b", pb)
    b.start()
    try:
        a = node(tmp_path, "a", pa, [pb])
        a.start()
        a.start_frames(frames[0:2]).join()  # a's submap 0, then a dies
        assert wait(lambda: b.store.seqs("a") == [0])
        a.stop()
        assert a.store is not None
        b.start_frames(frames[4:8]).join()  # b maps while a is away
        assert wait(lambda: b.drain(5))
        # a restarts on its store: resumes after frame 2 and seq 0, fetches b's submaps
        a = node(tmp_path, "a", pa, [pb])
        assert a.reloaded == 1 and a.frames_consumed == 2
        a.start()
        assert wait(lambda: a.store.seqs("b") == [0, 1])
        a.start_frames(frames[0:4]).join()  # the same input: only frames 2-3 are new
        assert wait(lambda: a.drain(5))
        assert a.store.seqs("a") == [0, 1] and a.frames_consumed == 4
        assert wait(lambda: b.store.seqs("a") == [0, 1])
        assert wait(lambda: a.mapper.result is not None and a.groups() == [["a", "b"]])
        before = len(a.store.edges())
        a.stop()
        a = node(tmp_path, "a", pa, [pb])  # a second restart re-judges nothing
        a.start()
        assert a.drain(10) and len(a.store.edges()) == before
        a.stop()
    finally:
        b.stop()


def test_the_owner_answers_fetches_a_holder_when_it_is_away_even_to_a_newcomer(tmp_path, frames):
    pa, pb = listen_port(), listen_port()
    b = node(tmp_path, "b", pb)
    b.start()
    try:
        a = node(tmp_path, "a", pa, [pb])
        a.start()
        a.start_frames(frames[0:2]).join()
        assert wait(lambda: b.store.seqs("a") == [0])
        assert wait(lambda: "a" in b.transport.peers())
        a.stop()
        assert wait(lambda: "a" not in b.transport.peers())
        c = node(tmp_path, "c", listen_port(), [pb])  # joins after a left: b hands a's submap on
        c.start()
        try:
            assert wait(lambda: c.store.seqs("a") == [0])
        finally:
            c.stop()
    finally:
        b.stop()


def test_the_end_of_a_chain_waits_for_the_last_submaps_of_the_other_end(tmp_path, frames):
    """a - b - c, and a never hears c: c maps on after a and b are done. a ends only once c's
    last submap has reached it through b, though a and b hold the same all along."""
    pa, pb, pc = listen_port(), listen_port(), listen_port()
    b = node(tmp_path, "b", pb, zenoh=ZENOH_NO_GOSSIP)
    a = node(tmp_path, "a", pa, [pb], zenoh=ZENOH_NO_GOSSIP)
    c = node(tmp_path, "c", pc, [pb], zenoh=ZENOH_NO_GOSSIP)
    for n in (b, a, c):
        n.start()
    assert wait(lambda: b.transport.peers() == ["a", "c"])
    a.start_frames(frames[0:2]).join()
    b.start_frames(frames[2:4]).join()
    ended = {}
    lingering = [
        threading.Thread(target=lambda n=n: ended.setdefault(n.robot, n.linger(0.5)))
        for n in (a, b)
    ]
    for th in lingering:
        th.start()
    time.sleep(3.0)  # a and b hold each other's submap: enough to end, were c done
    assert "a" not in ended and a.store.seqs("c") == []
    c.start_frames(frames[4:8]).join()
    assert c.linger(0.5)
    for th in lingering:
        th.join(timeout=60)
    assert ended == {"a": True, "b": True}
    assert a.store.seqs("c") == [0, 1] and "c" not in a.transport.peers()


def test_a_peer_that_joins_is_told_what_we_hold_and_the_others_are_not(tmp_path, frames):
    """a, b and d met holding nothing, then a and b mapped; c joins them: a and b each tell c
    alone what they hold (a put would reach the two others too), and c fetches from each."""
    pa, pb, pd = listen_port(), listen_port(), listen_port()
    a, b = node(tmp_path, "a", pa), node(tmp_path, "b", pb, [pa])
    d = node(tmp_path, "d", pd, [pa, pb])
    for n in (a, b, d):
        n.start()
    assert wait(lambda: a.transport.peers() == ["b", "d"] and b.transport.peers() == ["a", "d"])
    a.start_frames(frames[0:2]).join()
    b.start_frames(frames[2:4]).join()
    assert wait(lambda: a.store.seqs("b") == [0] and b.store.seqs("a") == [0])
    c = node(tmp_path, "c", listen_port(), [pa, pb, pd])
    c.start()
    assert wait(lambda: c.store.seqs("a") == [0] and c.store.seqs("b") == [0])
    received = c.transport.stats()["received"]
    assert received["a"]["have"]["messages"] == received["b"]["have"]["messages"] == 1
    for n, other in ((a, "b"), (b, "a"), (d, "a"), (d, "b")):
        assert "have" not in n.transport.stats()["received"].get(other, {}), (n.robot, other)


def test_a_robot_of_another_fleet_is_ignored(tmp_path, frames):
    pa, pb = listen_port(), listen_port()
    a = node(tmp_path, "a", pa, fleet="one")
    b = node(tmp_path, "b", pb, [pa], fleet="two")
    a.start()
    b.start()
    try:
        b.start_frames(frames[0:2]).join()
        time.sleep(1.0)
        assert b.transport.fetch("a", "submap", 0) == []
        assert a.drain(5) and b.drain(5)
        assert a.store.robots() == [] and a.counts["received"] == 0
        assert b.store.robots() == ["b"] and b.transport.peers() == []
    finally:
        a.stop()
        b.stop()


def test_a_fetch_asks_only_for_what_an_advert_shows_and_has_not_arrived(tmp_path):
    from gmmap.fleet.sharing import holdings

    b = node(tmp_path, "b", listen_port())
    asked = []
    b.transport.fetch = lambda robot, kind, since, **_: asked.append((robot, since)) or []
    b.holdings.update("c", holdings.encode({"a": 2, "c": 3}, holdings.LINGER))
    b.arrivals.add("a", 0)
    b.arrivals.add("a", 1)  # queued, not stored yet: the advert's count, not news
    b.arrivals.add("c", 0)
    b.fetcher.fetch({"a", "c"})
    assert asked == [("c", 1)]


def test_demo_runs_two_robot_processes(tmp_path):
    out = subprocess.run(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "demo", "--robots", "2",
         "--linger", "1.5", "--out", str(tmp_path), "--json", "--min-matches", "1"],
        capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    # The effective tree beside the results; each robot was started with its own file.
    assert load_config(tmp_path / "config.yaml").robot.linger == 1.5
    own = load_config(tmp_path / "robot_1.yaml")
    assert own.robot.name == "robot_1" and own.robot.wait_for == ("robot_0",)
    assert own.backend.translation == 0.02  # follows the simulated drift
    for key in ("robots", "groups", "bytes_per_submap", "reduction_vs_points", "pairs", "wall_s"):
        assert key in r
    assert r["robots"] == 2 and len(r["pairs"]) == 1
    assert set(r["bytes_per_submap"]) >= {"wire", "points_float32", "gmm_float32_plus_descriptor"}
    assert 0 < r["bytes_per_submap"]["wire"] <= 1024 and r["reduction_vs_points"] > 1
    assert {"a", "b", "t_error", "r_error_deg"} <= set(r["pairs"][0])
    # The robots meet in room B (once: in some arrival orders fewer consistent matches than
    # the default join rule asks for, so the test lets one join): one group, and their
    # relative pose there is right. The map
    # frames' error also holds the odometry drift between the starts and the meeting place.
    assert r["groups"] == [["robot_0", "robot_1"]]
    m = r["match_errors"]
    assert m["n"] >= 3 and m["t_median"] < 0.05 and m["r_median_deg"] < 1.0
    (pair,) = r["pairs"]
    assert pair["matches"] >= 3 and pair["t_error"] < 0.05 and pair["r_error_deg"] < 1.0
    assert pair["frame_t_error"] < 1.0 and pair["frame_r_error_deg"] < 5.0
