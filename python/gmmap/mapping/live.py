"""Live input for a robot node (`gmmap.fleet.node.robot.RobotNode.start_live`): frames and poses
pushed by any driver (a ROS callback, a camera SDK), each frame given its pose at its stamp.

- `LiveInput.push_pose(stamp, pose)`: the robot's base in its map frame (odometry, or TF
  base → odom), 4×4, in any order; the last ``horizon_s`` seconds of them are kept.
- `LiveInput.push_frame(stamp, points)`: points (N, 3) in the sensor frame. The frame's pose
  is the base pose interpolated at its stamp (linear in translation, slerp in rotation,
  `gmmap.math.geometry.interpolate_poses`) times the sensor's mounting (``extrinsic``: sensor
  → base, from TF or the configuration).

A frame waits until poses on both sides of its stamp have arrived, for at most ``wait_s``
seconds after it was pushed; then, or at once where its stamp is older than every pose kept,
it is dropped and counted (``no_pose``): odometry is never extrapolated. Back-pressure: at
most ``max_pending`` frames wait, ready or not. A frame pushed when that many wait makes the
oldest one go (``skipped``): a mapper that cannot keep up maps what the robot sees now, and
memory stays bounded. Iterating yields the ready frames in stamp order and blocks until one
is ready or the input is closed.
"""

from __future__ import annotations

import bisect
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.mapping.frame import Frame
from gmmap.math.geometry import interpolate_poses, matrix_to_quaternion, rigid_matrix


@dataclass
class LiveCounts:
    """What became of the pushed frames and poses."""

    frames: int = 0
    poses: int = 0
    mapped: int = 0  # handed to the node
    no_pose: int = 0  # no pose on both sides of its stamp in time
    skipped: int = 0  # dropped by back-pressure
    rejected: int = 0  # bad input (NaN, wrong shape): never queued


@dataclass
class _Pending:
    stamp: float
    points: np.ndarray
    pushed: float  # clock time


@dataclass
class LiveInput:
    """Frames and poses pushed from any thread; iterate it (one consumer) for `Frame`s."""

    extrinsic: np.ndarray = field(default_factory=lambda: np.eye(4))
    wait_s: float = 1.0
    max_pending: int = 8
    horizon_s: float = 30.0
    clock: Callable[[], float] = time.monotonic

    def __post_init__(self) -> None:
        self.extrinsic = rigid_matrix(np.asarray(self.extrinsic, float), "extrinsic")
        if not (self.wait_s >= 0 and self.horizon_s > 0 and self.max_pending >= 1):
            raise InvalidInputError("wait_s >= 0, horizon_s > 0 and max_pending >= 1")
        self.counts = LiveCounts()
        self._stamps: list[float] = []
        self._poses: list[np.ndarray] = []
        self._pending: list[_Pending] = []  # sorted by stamp
        self._closed = False
        self._cond = threading.Condition()

    def push_pose(self, stamp: float, pose: np.ndarray) -> None:
        """The base pose (4×4, base → map) at ``stamp`` (s); `InvalidInputError` if bad."""
        T = rigid_matrix(np.asarray(pose, float), "pose")
        stamp = _stamp(stamp)
        with self._cond:
            i = bisect.bisect_left(self._stamps, stamp)
            if i < len(self._stamps) and self._stamps[i] == stamp:
                self._poses[i] = T  # the same stamp again: the newer word wins
            else:
                self._stamps.insert(i, stamp)
                self._poses.insert(i, T)
            cut = bisect.bisect_left(self._stamps, self._stamps[-1] - self.horizon_s)
            del self._stamps[:cut], self._poses[:cut]
            self.counts.poses += 1
            self._cond.notify_all()

    def push_frame(self, stamp: float, points: np.ndarray) -> None:
        """Points (N, 3) in the sensor frame at ``stamp``; bad input is counted and dropped."""
        pts = np.asarray(points, dtype=np.float32)
        try:
            stamp = _stamp(stamp)
            ok = pts.ndim == 2 and pts.shape[1] == 3 and bool(np.isfinite(pts).all())
        except (InvalidInputError, TypeError, ValueError):
            ok = False
        with self._cond:
            self.counts.frames += 1
            if not ok:
                self.counts.rejected += 1
                return
            if len(self._pending) >= self.max_pending:
                self._pending.pop(0)
                self.counts.skipped += 1
            bisect.insort(self._pending, _Pending(stamp, pts, self.clock()), key=lambda p: p.stamp)
            self._cond.notify_all()

    def close(self) -> None:
        """No more input: iteration ends once the ready frames are taken."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def __iter__(self) -> Iterator[Frame]:
        while True:
            with self._cond:
                while (frame := self._next()) is None:
                    if self._closed and not self._pending:
                        return
                    if self._closed:  # what still waits has no pose to come
                        self.counts.no_pose += len(self._pending)
                        self._pending.clear()
                        return
                    self._cond.wait(timeout=min(0.1, self.wait_s or 0.1))
                self.counts.mapped += 1
            yield frame

    def _next(self) -> Frame | None:
        """The oldest waiting frame that has its pose (dropping those that cannot get one)."""
        now = self.clock()
        while self._pending:
            p = self._pending[0]
            if self._stamps and self._stamps[0] <= p.stamp <= self._stamps[-1]:
                self._pending.pop(0)
                return Frame(p.stamp, p.points, self._pose_at(p.stamp))
            late = now > p.pushed + self.wait_s
            if late or (self._stamps and p.stamp < self._stamps[0]):
                self._pending.pop(0)
                self.counts.no_pose += 1
                continue
            return None
        return None

    def _pose_at(self, stamp: float) -> np.ndarray:
        """The sensor pose at ``stamp``, within the poses kept, from its two neighbours."""
        hi = min(bisect.bisect_left(self._stamps, stamp), len(self._stamps) - 1)
        lo = max(hi - 1, 0)
        poses = np.asarray(self._poses[lo : hi + 1])
        stamps = np.asarray(self._stamps[lo : hi + 1])
        q = matrix_to_quaternion(poses[:, :3, :3])
        base = interpolate_poses(stamps, poses[:, :3, 3], q, np.array([stamp]))
        return base[0] @ self.extrinsic


def _stamp(stamp: object) -> float:
    value = float(stamp)  # type: ignore[arg-type]
    if not np.isfinite(value):
        raise InvalidInputError(f"a stamp must be finite; got {stamp!r}")
    return value
