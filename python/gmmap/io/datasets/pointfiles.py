"""A folder of PLY or PCD point clouds (one per frame) with a TUM-format poses file.

Layout: ``*.ply`` / ``*.pcd`` files directly in the folder (points in the sensor frame) and
``poses.txt`` (or ``trajectory.txt``, ``groundtruth.txt``, ``odometry.txt``: the first present),
each line ``stamp tx ty tz qx qy qz qw`` giving the sensor→map pose. A ``groundtruth.txt`` beside
another poses file is the ground truth (``gmmap sim --sensor lidar`` writes such folders: the
robot's odometry in ``poses.txt``, the true poses in ``groundtruth.txt``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.io.datasets.base import FrameSequence, crop
from gmmap.io.datasets.pcd import read_pcd
from gmmap.io.datasets.ply import read_ply
from gmmap.io.datasets.trajectory import associate, read_trajectory
from gmmap.math.drift import Drift

POSES_NAMES = ("poses.txt", "trajectory.txt", "groundtruth.txt", "odometry.txt")
GROUNDTRUTH_NAME = "groundtruth.txt"
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
    A ground-truth file is matched to the files the same way.

    Options:
        poses: the poses file (a path, or a name in the folder); default the first present of
            poses.txt, trajectory.txt, groundtruth.txt, odometry.txt.
        groundtruth: the ground-truth file (a path, or a name in the folder); default
            groundtruth.txt when present and not the poses file. It gives ``gt_pose``.
        match, max_dt: as above.
        min_range, max_range: keep points at these distances from the sensor (metres).
        voxel: voxel size (metres) for ``gmmap.voxel_filter`` per frame; None keeps all.
        drift: a ``Drift`` applied to the poses; without a ground-truth file, ``gt_pose`` is
            then the poses file's pose.
    Without a ground-truth file or drift, ``gt_pose`` is None (the poses file may be odometry
    or ground truth).
    """

    format = "pointfiles"

    def __init__(
        self,
        root: str | Path,
        *,
        poses: str | Path | None = None,
        groundtruth: str | Path | None = None,
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
        self.files = point_files(self.root)
        if not self.files:
            raise FileFormatError(f"{self.root}: no .ply or .pcd files")
        self.poses_path = self._poses_path(poses)
        self.gt_path = self._groundtruth_path(groundtruth)
        self.match = self._resolve_match(match, max_dt)
        self.stamps, file_poses = self._matched(self.poses_path, max_dt)
        if self.gt_path is not None:
            self.gt_poses = self._matched(self.gt_path, max_dt)[1]
        else:
            self.gt_poses = None if drift is None else file_poses
        self.poses = file_poses if drift is None else drift(file_poses)

    def _in_folder(self, name: str | Path) -> Path:
        return Path(name) if Path(name).is_absolute() else self.root / name

    def _poses_path(self, poses: str | Path | None) -> Path:
        if poses is not None:
            path = self._in_folder(poses)
            if not path.is_file():
                raise FileNotFoundError(f"{path}: missing poses file")
            return path
        for name in POSES_NAMES:
            if (self.root / name).is_file():
                return self.root / name
        raise FileNotFoundError(
            f"{self.root / POSES_NAMES[0]}: missing (nor any of {', '.join(POSES_NAMES[1:])})"
        )

    def _groundtruth_path(self, groundtruth: str | Path | None) -> Path | None:
        if groundtruth is not None:
            path = self._in_folder(groundtruth)
            if not path.is_file():
                raise FileNotFoundError(f"{path}: missing ground-truth file")
            return path
        path = self.root / GROUNDTRUTH_NAME
        # The default poses file may itself be groundtruth.txt: then there is no second one.
        return path if path.is_file() and path != self.poses_path else None

    def _resolve_match(self, match: str, max_dt: float) -> str:
        if match != "auto":
            return match
        stamps = [_number(p) for p in self.files]
        if any(s is None for s in stamps):
            return "order"
        pose_stamps, _ = read_trajectory(self.poses_path)
        matched = associate(np.array(stamps, dtype=np.float64), pose_stamps, max_dt) >= 0
        return "stamp" if matched.all() else "order"

    def _matched(self, path: Path, max_dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(stamps, poses) of the files from a trajectory file, by ``self.match``."""
        if self.match == "stamp":
            return self._by_stamp(path, max_dt)
        return self._by_order(path)

    def _by_stamp(self, path: Path, max_dt: float) -> tuple[np.ndarray, np.ndarray]:
        numbers = [_number(p) for p in self.files]
        if None in numbers:
            bad = self.files[numbers.index(None)]
            raise FileFormatError(f"{bad}: match='stamp' needs file names that are stamps")
        stamps = np.array(numbers, dtype=np.float64)
        pose_stamps, poses = read_trajectory(path)
        idx = associate(stamps, pose_stamps, max_dt)
        if (idx < 0).any():
            lost = [f.name for f, i in zip(self.files, idx, strict=True) if i < 0]
            raise FileFormatError(
                f"{self.root}: {len(lost)} files have no pose in {path.name} within "
                f"max_dt={max_dt} s (first: {', '.join(lost[:3])}; poses span "
                f"{pose_stamps[0]:.3f}..{pose_stamps[-1]:.3f})"
            )
        return stamps, poses[idx]

    def _by_order(self, path: Path) -> tuple[np.ndarray, np.ndarray]:
        stamps, poses = read_trajectory(path, sort=False)
        if len(stamps) != len(self.files):
            raise FileFormatError(
                f"{path}: {len(stamps)} poses for {len(self.files)} point files in "
                f"{self.root} (match='order' pairs them line by line; match='stamp' needs file "
                "names that are stamps)"
            )
        return stamps, poses

    def _points(self, i: int) -> np.ndarray:
        path = self.files[i]
        return crop(READERS[path.suffix.lower()](path), **self.options)
