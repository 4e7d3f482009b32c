"""A folder of PLY or PCD point clouds (one per frame) with a TUM-format poses file.

Layout: ``*.ply`` / ``*.pcd`` files directly in the folder (points in the sensor frame) and
``poses.txt`` (or ``trajectory.txt``, ``groundtruth.txt``, ``odometry.txt``: the first present),
each line ``stamp tx ty tz qx qy qz qw`` giving the sensor→map pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gmmap.datasets.base import FrameSequence, crop
from gmmap.datasets.drift import Drift
from gmmap.datasets.pcd import read_pcd
from gmmap.datasets.ply import read_ply
from gmmap.datasets.tum import associate, read_trajectory
from gmmap.errors import FileFormatError, InvalidInputError

POSES_NAMES = ("poses.txt", "trajectory.txt", "groundtruth.txt", "odometry.txt")
READERS: dict[str, Callable[[Path], np.ndarray]] = {".ply": read_ply, ".pcd": read_pcd}
MATCHES = ("auto", "stamp", "order")


def point_files(root: Path) -> list[Path]:
    """The PLY/PCD files of a folder, by name (by number when every name is a number)."""
    files = [p for p in root.iterdir() if p.is_file() and p.suffix.lower() in READERS]
    if all(_number(p) is not None for p in files):
        return sorted(files, key=lambda p: (_number(p), p.name))
    return sorted(files, key=lambda p: p.name)


def _number(path: Path) -> float | None:
    try:
        value = float(path.stem)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


class PointFiles(FrameSequence):
    """PLY/PCD files as a lazy sequence of Frames (each file read on access).

    Association of files with poses (``match``):
        "stamp": every file name is its stamp in seconds (``1305031102.175.pcd``) and takes the
            pose nearest in time within ``max_dt``; a file with none is an error.
        "order": file i (in sorted order) takes line i of the poses file, and its stamp from
            there; the counts must be equal.
        "auto" (default): "stamp" when every name is a number and every one has a pose within
            ``max_dt``, else "order".

    Options:
        poses: the poses file (a path, or a name in the folder); default the first present of
            poses.txt, trajectory.txt, groundtruth.txt, odometry.txt.
        match, max_dt: as above.
        min_range, max_range: keep points at these distances from the sensor (metres).
        voxel: voxel size (metres) for ``gmmap.voxel_filter`` per frame; None keeps all.
        drift: a ``Drift`` applied to the poses; then ``gt_pose`` is the poses file's pose.
            Without drift, ``gt_pose`` is None (the file may be odometry or ground truth).
    """

    format = "pointfiles"

    def __init__(
        self,
        root: str | Path,
        *,
        poses: str | Path | None = None,
        match: str = "auto",
        max_dt: float = 0.02,
        min_range: float = 0.0,
        max_range: float = math.inf,
        voxel: float | None = None,
        drift: Drift | None = None,
    ) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"{self.root}: no such folder")
        if match not in MATCHES:
            raise InvalidInputError(f"match must be one of {MATCHES}, got {match!r}")
        self.options = dict(min_range=min_range, max_range=max_range, voxel=voxel)
        files = point_files(self.root)
        if not files:
            raise FileFormatError(f"{self.root}: no .ply or .pcd files")
        self.poses_path = self._poses_path(poses)
        self.match = self._resolve_match(match, files, max_dt)
        if self.match == "stamp":
            self.files, self.stamps, true_poses = self._by_stamp(files, max_dt)
        else:
            self.files, self.stamps, true_poses = self._by_order(files)
        self.gt_poses = None if drift is None else true_poses
        self.poses = true_poses if drift is None else drift(true_poses)

    def _poses_path(self, poses: str | Path | None) -> Path:
        if poses is not None:
            path = Path(poses) if Path(poses).is_absolute() else self.root / poses
            if not path.is_file():
                raise FileNotFoundError(f"{path}: missing poses file")
            return path
        for name in POSES_NAMES:
            if (self.root / name).is_file():
                return self.root / name
        raise FileNotFoundError(
            f"{self.root / POSES_NAMES[0]}: missing (nor any of {', '.join(POSES_NAMES[1:])})"
        )

    def _resolve_match(self, match: str, files: list[Path], max_dt: float) -> str:
        if match != "auto":
            return match
        stamps = [_number(p) for p in files]
        if any(s is None for s in stamps):
            return "order"
        pose_stamps, _ = read_trajectory(self.poses_path)
        matched = associate(np.array(stamps, dtype=np.float64), pose_stamps, max_dt) >= 0
        return "stamp" if matched.all() else "order"

    def _by_stamp(
        self, files: list[Path], max_dt: float
    ) -> tuple[list[Path], np.ndarray, np.ndarray]:
        numbers = [_number(p) for p in files]
        if None in numbers:
            bad = files[numbers.index(None)]
            raise FileFormatError(f"{bad}: match='stamp' needs file names that are stamps")
        stamps = np.array(numbers, dtype=np.float64)
        pose_stamps, poses = read_trajectory(self.poses_path)
        idx = associate(stamps, pose_stamps, max_dt)
        if (idx < 0).any():
            lost = [f.name for f, i in zip(files, idx, strict=True) if i < 0]
            raise FileFormatError(
                f"{self.root}: {len(lost)} files have no pose in {self.poses_path.name} within "
                f"max_dt={max_dt} s (first: {', '.join(lost[:3])}; poses span "
                f"{pose_stamps[0]:.3f}..{pose_stamps[-1]:.3f})"
            )
        return files, stamps, poses[idx]

    def _by_order(self, files: list[Path]) -> tuple[list[Path], np.ndarray, np.ndarray]:
        stamps, poses = read_trajectory(self.poses_path, sort=False)
        if len(stamps) != len(files):
            raise FileFormatError(
                f"{self.poses_path}: {len(stamps)} poses for {len(files)} point files in "
                f"{self.root} (match='order' pairs them line by line; match='stamp' needs file "
                "names that are stamps)"
            )
        return files, stamps, poses

    def _points(self, i: int) -> np.ndarray:
        path = self.files[i]
        return crop(READERS[path.suffix.lower()](path), **self.options)
