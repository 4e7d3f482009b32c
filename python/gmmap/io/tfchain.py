"""Live base poses from /tf and /tf_static: the chain of transforms from ``tf_parent`` (the odom
or map frame) down to ``tf_child`` (the base or the sensor), as the recorded bags take it
(`gmmap.io.datasets.RosBag`), for the ROS bridges.

TF is a tree: every frame has one parent, and a transform's child replaces its earlier parent.
A pose is given each time the chain's *driver* moves: its first non-static edge from the
parent's side (``odom → base_link`` in the usual ``odom → base_link → camera_link`` with a
static mounting). The other moving edges of the chain are interpolated at the driver's stamp
from their recent transforms, and held at their ends outside them: exact where one edge of the
chain moves, an approximation where two move at different rates. When the chain first closes
(a static mounting arriving after the odometry, or the sensor's frame learnt from the first
cloud), the driver's kept history is given at once, so no early pose is lost.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from gmmap.math.geometry import interpolate_poses, matrix_to_quaternion

HISTORY = 400  # transforms kept per moving edge: 4 s of 100 Hz odometry


@dataclass
class _Edge:
    parent: str
    static: bool
    samples: deque = field(default_factory=lambda: deque(maxlen=HISTORY))  # (stamp, 4×4)

    def at(self, stamp: float) -> np.ndarray:
        if self.static or len(self.samples) == 1:
            return self.samples[-1][1]
        stamps = np.array([s for s, _ in self.samples])
        poses = np.array([T for _, T in self.samples])
        order = np.argsort(stamps, kind="stable")
        stamps, poses = stamps[order], poses[order]
        query = np.clip([stamp], stamps[0], stamps[-1])
        quats = matrix_to_quaternion(poses[:, :3, :3])
        return interpolate_poses(stamps, poses[:, :3, 3], quats, query)[0]


def frame_name(name: str) -> str:
    return name.lstrip("/")  # ROS 1 writes "/odom" where ROS 2 writes "odom"


class TfChain:
    """Poses (``parent`` → ``child``, 4×4) from the transforms of /tf and /tf_static, added
    from any thread. ``child`` None: set it later (`set_child`), from the clouds' frame."""

    def __init__(self, parent: str, child: str | None = None) -> None:
        self.parent = frame_name(parent)
        self.child = None if child is None else frame_name(child)
        self._edges: dict[str, _Edge] = {}  # by child frame
        self._closed = False  # whether the chain was complete at the last add
        self._lock = threading.Lock()

    def set_child(self, child: str) -> list[tuple[float, np.ndarray]]:
        """Sets the chain's lower end; the poses it gives at once (see `add`)."""
        with self._lock:
            self.child = frame_name(child)
            return self._update(None)

    def add(
        self, parent: str, child: str, stamp: float, T: np.ndarray, static: bool = False
    ) -> list[tuple[float, np.ndarray]]:
        """One transform (``child`` in ``parent``); the (stamp, pose) pairs it gives: none, one
        (the driver moved) or the driver's history (the chain just closed)."""
        parent, child = frame_name(parent), frame_name(child)
        with self._lock:
            edge = self._edges.get(child)
            if edge is None or edge.parent != parent or edge.static != static:
                edge = self._edges[child] = _Edge(parent, static)
            edge.samples.append((float(stamp), np.asarray(T, float)))
            return self._update((child, float(stamp)))

    def _update(self, moved: tuple[str, float] | None) -> list[tuple[float, np.ndarray]]:
        chain = self._chain()
        was_closed, self._closed = self._closed, chain is not None
        if chain is None:
            return []
        driver = next((c for c in chain if not self._edges[c].static), None)
        if driver is None:  # all static: one pose, valid at any stamp
            stamp = moved[1] if moved else 0.0
            return [(stamp, self._compose(chain, stamp))]
        if not was_closed:
            stamps = sorted({s for s, _ in self._edges[driver].samples})
            return [(s, self._compose(chain, s)) for s in stamps]
        if moved is not None and moved[0] == driver:
            return [(moved[1], self._compose(chain, moved[1]))]
        return []

    def _chain(self) -> list[str] | None:
        """The child frames of the chain's edges, parent side first; None while it is open."""
        if self.child is None:
            return None
        chain, frame = [], self.child
        while frame != self.parent:
            if frame not in self._edges or len(chain) > len(self._edges):  # open, or a loop
                return None
            chain.append(frame)
            frame = self._edges[frame].parent
        return chain[::-1]

    def _compose(self, chain: list[str], stamp: float) -> np.ndarray:
        pose = np.eye(4)
        for frame in chain:
            pose = pose @ self._edges[frame].at(stamp)
        return pose
