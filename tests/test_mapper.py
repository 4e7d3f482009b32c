"""One pipeline: the robot node and the offline merge judge the same pairs and optimise alike."""

import numpy as np
import pytest

from conftest import BUNDLED_TUM_SLICE
from gmmap.config import Config
from gmmap.eval.merge import merge
from gmmap.fleet.node.robot import RobotNode
from gmmap.fleet.storage.store import Store
from gmmap.fleet.wire.codec import decode, encode
from gmmap.io.datasets.tum import TumRgbd
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.submap import build_submaps
from gmmap.options import BackendOptions, BuildOptions, RobotOptions

# The bundled slice's two-frame submaps give one or two matches per robot pair: let one join.
CONFIG = Config(
    build=BuildOptions(frames_per_submap=2, n_components=60),
    backend=BackendOptions(min_matches=1),
)


@pytest.fixture(scope="module")
def recorded():
    """Two robots' submaps as they cross the wire: encoded bytes and their decoded copies."""
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)
    payloads = {
        name: [encode(s) for s in build_submaps(frames[part], name, CONFIG.build)]
        for name, part in (("a", slice(0, 4)), ("b", slice(4, 8)))
    }
    return payloads, {r: [decode(p) for p in ps] for r, ps in payloads.items()}


def judged(mapper: Mapper) -> dict:
    return {
        (m.query, (m.candidate.robot, m.candidate.seq)): (m.accepted, m.registration.transform)
        for m in mapper.matches
    }


def test_robot_node_and_merge_give_the_same_matches_and_poses(tmp_path, recorded):
    payloads, submaps = recorded
    offline, report = merge(submaps, CONFIG)
    assert report["groups"] == [["a", "b"]]
    # A node whose store holds the same submaps (its own a's, b's received) judges them when
    # it starts: the same pairs, the same registrations, the same optimised poses.
    with Store(tmp_path / "a.db") as store:
        for robot, ps in payloads.items():
            for seq, p in enumerate(ps):
                store.put_submap(robot, seq, p, own=robot == "a")
    config = Config(
        build=CONFIG.build,
        place=CONFIG.place,
        backend=CONFIG.backend,
        robot=RobotOptions(name="a", fleet="same", store=str(tmp_path / "a.db")),
    )
    node = RobotNode(config)
    try:
        node.start()
        assert node.drain(30)
        online = node.mapper
        ours, theirs = judged(online), judged(offline)
        assert ours.keys() == theirs.keys() and len(ours) >= 1
        for pair, (accepted, transform) in theirs.items():
            assert ours[pair][0] == accepted
            np.testing.assert_allclose(ours[pair][1], transform, atol=1e-12)
        assert sorted(online.result.accepted) == sorted(offline.result.accepted)
        assert online.frames.groups() == offline.frames.groups()
        for key, pose in offline.result.poses.items():
            np.testing.assert_allclose(online.result.poses[key], pose, atol=1e-6)
        assert len(node.store.edges()) == len(ours)  # every judged pair is stored
    finally:
        node.stop()


def test_a_mapper_judges_each_pair_once(recorded):
    _, submaps = recorded
    mapper = Mapper(CONFIG)
    first = mapper.add(submaps["a"] + submaps["b"])
    assert first and mapper.add(submaps["b"]) == []  # held already: nothing new to judge
    mapper.optimize()
    assert mapper.frames.groups() == [["a", "b"]]
    assert mapper.global_map("b").reference == "a"


def test_a_local_map_holds_the_neighbours_in_the_candidates_frame(recorded):
    from dataclasses import replace

    from gmmap.mapping.submap import local_map

    _, submaps = recorded
    a0, a1 = submaps["a"][:2]
    moved = np.eye(4)
    moved[:3, 3] = [1.0, -2.0, 0.5]
    a1 = replace(a1, anchor=moved)
    local = local_map([a0, a1], frame=a1.anchor)
    assert len(local) == len(a0.gmm) + len(a1.gmm)
    np.testing.assert_allclose(local.weights.sum(), 1.0)
    # a1 sits at its own frame's origin; a0 is where its anchor is, seen from a1's.
    np.testing.assert_allclose(local.means[len(a0.gmm) :], a1.gmm.means, atol=1e-12)
    expected = a0.gmm.transform(np.linalg.inv(moved) @ a0.anchor).means
    np.testing.assert_allclose(local.means[: len(a0.gmm)], expected, atol=1e-12)
    share = a0.n_points / (a0.n_points + a1.n_points)
    np.testing.assert_allclose(local.weights[: len(a0.gmm)].sum(), share, atol=1e-12)


def test_rejudged_gives_the_offline_merge_whatever_the_arrival_order(recorded):
    _, submaps = recorded
    offline, _ = merge(submaps, CONFIG)
    live = Mapper(CONFIG)
    arrivals = [s for pair in zip(submaps["b"][::-1], submaps["a"], strict=False) for s in pair]
    for s in arrivals:  # one at a time, b's newest first: pairs judged against what is held
        live.add([s])
    fresh = live.rejudged()
    assert judged(fresh).keys() == judged(offline).keys()
    for pair, (accepted, transform) in judged(offline).items():
        assert judged(fresh)[pair][0] == accepted
        np.testing.assert_allclose(judged(fresh)[pair][1], transform, atol=1e-12)
    assert fresh.frames.groups() == offline.frames.groups()
