"""Live input (`gmmap.mapping.live`): frames and poses pushed by a driver, a pose for each frame
at its stamp, late or missing poses, and back-pressure; a robot node mapping it."""

import threading

import numpy as np
import pytest

from conftest import wait
from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.fleet.node.robot import RobotNode
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.mapping.live import LiveInput
from gmmap.options import BuildOptions, RobotOptions

POINTS = np.zeros((10, 3), np.float32)


def pose(x: float, yaw: float = 0.0) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[0, 3] = x
    return T


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def take(live: LiveInput, n: int) -> list:
    out = []
    for frame in live:
        out.append(frame)
        if len(out) == n:
            break
    return out


def test_a_frame_gets_the_pose_interpolated_at_its_stamp_through_the_mounting() -> None:
    mount = pose(0.1)  # the sensor 10 cm ahead of the base
    live = LiveInput(extrinsic=mount)
    live.push_frame(1.5, POINTS)
    live.push_pose(2.0, pose(2.0, np.pi / 2))  # out of order
    live.push_pose(1.0, pose(1.0))
    (frame,) = take(live, 1)
    expected = pose(1.5, np.pi / 4) @ mount
    assert frame.stamp == 1.5 and np.allclose(frame.pose, expected)


def test_frames_wait_for_a_late_pose_and_go_without_one() -> None:
    clock = Clock()
    live = LiveInput(wait_s=1.0, clock=clock)
    live.push_pose(1.0, pose(1.0))
    live.push_frame(0.5, POINTS)  # older than every pose: never gets one
    live.push_frame(2.0, POINTS)  # waits for a pose after it
    live.push_frame(3.0, POINTS)
    live.push_pose(2.5, pose(2.5))  # late, but in time for the frame at 2.0
    clock.t = 2.0  # the frame at 3.0 waited too long
    live.close()
    frames = list(live)
    assert [f.stamp for f in frames] == [2.0]
    assert live.counts.no_pose == 2 and live.counts.mapped == 1


def test_a_burst_faster_than_mapping_keeps_the_newest_frames() -> None:
    live = LiveInput(max_pending=3)
    for k in range(10):
        live.push_frame(float(k), POINTS)
    live.push_pose(0.0, pose(0.0))
    live.push_pose(10.0, pose(10.0))
    live.close()
    assert [f.stamp for f in live] == [7.0, 8.0, 9.0]
    assert live.counts.skipped == 7


def test_bad_input_is_refused_or_counted() -> None:
    live = LiveInput()
    with pytest.raises(InvalidInputError):
        live.push_pose(1.0, np.full((4, 4), np.nan))
    with pytest.raises(InvalidInputError):
        live.push_pose(float("nan"), np.eye(4))
    live.push_frame(1.0, np.full((5, 3), np.nan))
    live.push_frame(1.0, np.zeros((5, 2)))
    assert live.counts.rejected == 2 and live.counts.frames == 2
    with pytest.raises(InvalidInputError):
        LiveInput(max_pending=0)


def test_a_robot_node_maps_what_a_driver_pushes(tmp_path) -> None:
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)
    config = Config(
        robot=RobotOptions(name="a", fleet="f", store=str(tmp_path / "a.db")),
        build=BuildOptions(frames_per_submap=2, covariance="full", n_components=60),
    )
    node = RobotNode(config)
    live = LiveInput(max_pending=100)
    try:
        node.start()
        builder = node.start_frames(live)

        def driver() -> None:  # poses a little after the frames, as odometry often comes
            for f in frames[0:4]:
                live.push_frame(f.stamp, f.points)
            for f in frames[0:4]:
                live.push_pose(f.stamp, f.pose)

        threading.Thread(target=driver).start()
        assert wait(lambda: live.counts.mapped == 4)
        live.close()
        builder.join(timeout=30)
        assert not builder.is_alive() and node.store.seqs("a") == [0, 1]
        assert live.counts.no_pose == 0 and live.counts.skipped == 0
    finally:
        node.stop()
