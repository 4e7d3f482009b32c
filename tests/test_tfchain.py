"""Live base poses from TF chains (`gmmap.io.tfchain`)."""

import numpy as np

from gmmap.io.tfchain import TfChain
from gmmap.math.geometry import make_poses


def pose(x: float, yaw: float = 0.0) -> np.ndarray:
    q = np.array([[0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)]])
    return make_poses(np.array([[x, 0.5 * x, 0.0]]), q)[0]


MOUNT = pose(0.2, np.pi / 2)


def test_a_moving_base_and_a_static_mounting_give_the_sensor_at_every_odometry_stamp():
    chain = TfChain("/odom", "camera")
    assert chain.add("base_link", "camera", 0.0, MOUNT, static=True) == []  # odom not yet known
    for t in (1.0, 2.0):
        [(stamp, got)] = chain.add("odom", "/base_link", t, pose(t, 0.1 * t))
        assert stamp == t and np.allclose(got, pose(t, 0.1 * t) @ MOUNT)


def test_a_mounting_that_arrives_late_gives_the_odometry_kept_until_then():
    chain = TfChain("odom", "camera")
    for t in (1.0, 2.0, 3.0):
        assert chain.add("odom", "base_link", t, pose(t)) == []
    given = chain.add("base_link", "camera", 0.0, MOUNT, static=True)
    assert [s for s, _ in given] == [1.0, 2.0, 3.0]
    assert np.allclose(given[2][1], pose(3.0) @ MOUNT)


def test_the_lower_end_learnt_from_the_first_cloud_gives_the_history_at_once():
    chain = TfChain("odom")
    chain.add("odom", "base_link", 1.0, pose(1.0))
    chain.add("odom", "base_link", 2.0, pose(2.0))
    assert [s for s, _ in chain.set_child("base_link")] == [1.0, 2.0]
    assert len(chain.add("odom", "base_link", 3.0, pose(3.0))) == 1


def test_a_second_moving_edge_is_interpolated_at_the_drivers_stamps():
    chain = TfChain("map", "base")
    chain.add("odom", "base", 1.0, pose(0.0))
    chain.add("odom", "base", 3.0, pose(2.0))
    chain.add("map", "odom", 0.0, pose(0.0))  # closes: the driver's (map → odom) one stamp
    [(stamp, got)] = chain.add("map", "odom", 2.0, pose(0.0))
    assert stamp == 2.0 and np.allclose(got, pose(1.0))  # odom → base halfway at t = 2


def test_other_edges_give_nothing_and_a_new_parent_replaces_the_old():
    chain = TfChain("odom", "camera")
    chain.add("base_link", "camera", 0.0, MOUNT, static=True)
    assert chain.add("odom", "wheel", 1.0, pose(1.0)) == []
    assert chain.add("world", "base_link", 1.0, pose(1.0)) == []  # not below odom
    assert len(chain.add("odom", "base_link", 2.0, pose(2.0))) == 1  # reparented


def test_a_loop_in_the_transforms_closes_nothing():
    chain = TfChain("odom", "a")
    chain.add("b", "a", 1.0, pose(1.0))
    assert chain.add("a", "b", 1.0, pose(1.0)) == []
