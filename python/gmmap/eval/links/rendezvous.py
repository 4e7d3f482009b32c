"""Rendezvous links: which robots are in reach of each other, from where each is (`Rendezvous`);
a relay's gate (`gmmap.eval.links.relay.Relay`) opens only while its two robots are."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np

Sight = Callable[[np.ndarray, np.ndarray], bool]


class Rendezvous:
    """Which robots are in reach of each other, from where each is: within ``range_m`` (None:
    any distance) and, where ``sight`` is given, in its line of sight (``sight(a, b)``: no
    obstacle between positions a and b).

    ``tracks[i]`` holds robot i's positions (N, 3), one per frame; frame k is where the robots
    are ``k / fps`` s after ``start`` on ``clock`` (the robots' frames paced so, `SimOptions.pace`),
    and after its last frame a robot stays where it ended. `gate` is a `Relay`'s gate.
    """

    def __init__(
        self,
        tracks: list[np.ndarray],
        range_m: float | None,
        sight: Sight | None = None,
        start: float = 0.0,
        fps: float = 1.0,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._tracks = [np.asarray(t, float).reshape(-1, 3) for t in tracks]
        self._range, self._sight = range_m, sight
        self._start, self._fps, self._clock = start, fps, clock
        self._lock = threading.Lock()
        self._memo: dict[tuple, bool] = {}

    @property
    def frames(self) -> int:
        """Frames until the last robot's last: the links stay as they are from then on."""
        return max(len(t) for t in self._tracks)

    def frame(self, at: float | None = None) -> int:
        """The frame the robots are at ``at`` (a time on the clock; None: now)."""
        return max(0, int(((self._clock() if at is None else at) - self._start) * self._fps))

    def up(self, i: int, j: int, frame: int | None = None) -> bool:
        """Whether robots i and j are in reach at ``frame`` (None: now)."""
        k = self.frame() if frame is None else frame
        ki, kj = (min(k, len(self._tracks[r]) - 1) for r in (i, j))
        key = (i, ki, j, kj)
        with self._lock:
            if key not in self._memo:
                a, b = self._tracks[i][ki], self._tracks[j][kj]
                near = self._range is None or float(np.linalg.norm(a - b)) <= self._range
                self._memo[key] = near and (self._sight is None or self._sight(a, b))
            return self._memo[key]

    def gate(self, i: int, j: int) -> Callable[[], bool]:
        return lambda: self.up(i, j)
