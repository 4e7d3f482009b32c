"""What every loader shares: the lazy frame sequence, point cropping, and a dataset summary."""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import ClassVar, overload

import numpy as np

from gmmap.mapping.frame import Frame
from gmmap.math.drift import Drift
from gmmap.math.geometry import path_length


class FrameSequence(Sequence[Frame]):
    """A lazy, sized sequence of Frames: poses are read up front, points only on access.

    Subclasses set ``format``, ``stamps`` (M,), ``poses`` (M, 4, 4) sensor→map,
    ``gt_poses`` (M, 4, 4) or None, and implement ``_points(i)``. Indexing accepts negative
    indices; a slice returns a list of Frames.
    """

    format: ClassVar[str]
    stamps: np.ndarray
    poses: np.ndarray
    gt_poses: np.ndarray | None

    @abstractmethod
    def _points(self, i: int) -> np.ndarray:
        """Frame i's (N, 3) float32 points in the sensor frame."""

    def __len__(self) -> int:
        return len(self.stamps)

    @overload
    def __getitem__(self, i: int) -> Frame: ...

    @overload
    def __getitem__(self, i: slice) -> list[Frame]: ...

    def __getitem__(self, i: int | slice) -> Frame | list[Frame]:
        if isinstance(i, slice):
            return [self._frame(j) for j in range(*i.indices(len(self)))]
        # range() does the bounds check, negative indices and the int-like type check for us.
        return self._frame(range(len(self))[i])

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self._frame(i)

    def _frame(self, i: int) -> Frame:
        gt = None if self.gt_poses is None else self.gt_poses[i].copy()
        return Frame(float(self.stamps[i]), self._points(i), self.poses[i].copy(), gt)

    def __repr__(self) -> str:
        where = getattr(self, "root", None) or getattr(self, "path", "")
        return f"{type(self).__name__}({str(where)!r}, frames={len(self)})"


def read_point_file(path: Path) -> bytes:
    """A point file's bytes; a missing one raises FileNotFoundError naming it."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing point file") from None


def drifted(poses: np.ndarray, drift: Drift | None) -> np.ndarray:
    """The poses with simulated odometry drift when ``drift`` is set, else a copy."""
    return drift(poses) if drift is not None else poses.copy()


def crop(points: np.ndarray, min_range: float, max_range: float, voxel: float | None) -> np.ndarray:
    """Keeps points with min_range ≤ |p| ≤ max_range, then (optionally) voxelises them."""
    if min_range > 0 or math.isfinite(max_range):
        r = np.linalg.norm(points, axis=1)
        points = points[(r >= min_range) & (r <= max_range)]
    if voxel:
        from gmmap.math.points import voxel_filter  # the Rust core: imported only when asked for

        points = voxel_filter(points, voxel)
    return np.ascontiguousarray(points, dtype=np.float32)


def sample_indices(n: int, limit: int) -> np.ndarray:
    """Up to ``limit`` frame indices spread evenly over 0..n-1 (all of them if n ≤ limit)."""
    if n <= limit:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, limit).round().astype(int))


def describe(seq: FrameSequence, max_frames: int = 50) -> dict:
    """Summary of a loaded dataset: format, frames, duration, path length, points per frame.

    ``path_length_m`` follows ``poses`` (what the loader yields); ``gt_path_length_m`` is added
    when ground truth exists. Points per frame is a mean over up to ``max_frames`` frames spread
    evenly; when that is fewer than all, ``points_per_frame_sampled`` says how many were read.
    """
    n = len(seq)
    idx = sample_indices(n, max_frames)
    counts = [len(seq[int(i)].points) for i in idx]
    info = {
        "format": seq.format,
        "frames": n,
        "duration_s": float(seq.stamps[-1] - seq.stamps[0]) if n else 0.0,
        "path_length_m": path_length(seq.poses),
        "points_per_frame": float(np.mean(counts)) if counts else 0.0,
    }
    if len(idx) < n:
        info["points_per_frame_sampled"] = len(idx)
    if seq.gt_poses is not None:
        info["gt_path_length_m"] = path_length(seq.gt_poses)
    return info
