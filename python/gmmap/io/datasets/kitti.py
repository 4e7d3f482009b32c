"""KITTI odometry sequences: Velodyne scans with the published camera-0 poses.

Sequence folder layout: ``velodyne/NNNNNN.bin`` (float32 x y z intensity per point, LiDAR
frame), ``times.txt`` (one stamp per line, seconds from the sequence start), ``calib.txt``
and ``poses.txt`` (line i: the 3x4 pose of camera 0 at scan i in the first camera frame). The
official layout, ``dataset/poses/NN.txt`` beside ``dataset/sequences/NN/``, is found too.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.io.datasets.base import FrameSequence, crop, drifted
from gmmap.io.datasets.trajectory import read_table
from gmmap.math.drift import Drift
from gmmap.math.geometry import invert

CALIB_FILES = ("calib.txt", "calib_Tr_velo_to_cam.txt")


def read_matrices(path: Path) -> np.ndarray:
    """Rows of 12 numbers (a 3x4 matrix each, row-major) → (M, 4, 4)."""
    rows = read_table(path, 12)
    try:
        data = np.array([[float(v) for v in r[:12]] for r in rows], dtype=np.float64)
    except ValueError as exc:
        raise FileFormatError(f"{path}: non-numeric value ({exc})") from exc
    out = np.tile(np.eye(4), (len(data), 1, 1))
    out[:, :3, :] = data.reshape(-1, 3, 4)
    return out


def read_velo_to_cam(root: Path) -> np.ndarray:
    """The ``Tr:`` (LiDAR → camera 0) line of calib.txt, else of calib_Tr_velo_to_cam.txt."""
    for name in CALIB_FILES:
        path = root / name
        if not path.is_file():
            continue
        for row in read_table(path, 1):
            if row[0] == "Tr:":
                try:
                    values = np.array([float(v) for v in row[1:13]])
                except ValueError as exc:
                    raise FileFormatError(f"{path}: non-numeric Tr ({exc})") from exc
                if values.size != 12:
                    raise FileFormatError(f"{path}: Tr needs 12 numbers, got {values.size}")
                return np.vstack([values.reshape(3, 4), [0.0, 0.0, 0.0, 1.0]])
    raise FileNotFoundError(f"{root / CALIB_FILES[0]}: no 'Tr:' line in {' or '.join(CALIB_FILES)}")


def read_scan(path: Path) -> np.ndarray:
    """A Velodyne .bin file → (N, 3) float32 x y z (intensity dropped)."""
    try:
        raw = np.fromfile(path, dtype=np.float32)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing scan") from None
    if raw.size % 4:
        raise FileFormatError(
            f"{path}: truncated scan ({path.stat().st_size} bytes is not a whole number of "
            "16-byte points)"
        )
    return raw.reshape(-1, 4)[:, :3]


def find_poses_file(root: Path, name: str) -> Path:
    """``root/name``, else the official layout's ``../../poses/<sequence>.txt``."""
    path = root / name
    if path.is_file():
        return path
    official = root.resolve().parent.parent / "poses" / f"{root.resolve().name}.txt"
    if official.is_file():
        return official
    raise FileNotFoundError(f"{path}: missing (nor is there {official})")


class KittiOdometry(FrameSequence):
    """A KITTI odometry sequence as a lazy sequence of Frames (scans read on access).

    Frames are the scans present in ``velodyne/`` (a partial download is fine: poses and stamps
    are looked up by the scan number). A scan's LiDAR→world pose is Tr⁻¹ · P · Tr, with P the
    camera-0 pose and Tr the LiDAR→camera calibration, so the first pose is near identity.
    KITTI has no odometry: ``pose`` is the ground truth unless ``drift`` is set.

    Options:
        poses_file: the file in the sequence folder with the poses (``poses.txt``).
        min_range, max_range: keep points at these distances from the sensor (metres).
        voxel: voxel size (metres) for ``gmmap.voxel_filter`` per scan; None keeps every point.
        drift: a ``Drift`` applied to the poses (simulated odometry); ``gt_pose`` is untouched.
    """

    format = "kitti"

    def __init__(
        self,
        root: str | Path,
        *,
        poses_file: str = "poses.txt",
        min_range: float = 0.0,
        max_range: float = math.inf,
        voxel: float | None = None,
        drift: Drift | None = None,
    ) -> None:
        self.root = Path(root)
        if not (self.root / "velodyne").is_dir():
            raise FileNotFoundError(f"{self.root / 'velodyne'}: no such folder")
        if not 0 <= min_range < max_range:
            raise InvalidInputError(f"need 0 <= min_range < max_range, got {min_range, max_range}")
        self.options = dict(min_range=min_range, max_range=max_range, voxel=voxel)
        self.files, numbers = self._scans()
        self.velo_to_cam = read_velo_to_cam(self.root)
        cam_poses = self._lookup(read_matrices(find_poses_file(self.root, poses_file)), numbers)
        times = np.array([float(r[0]) for r in read_table(self.root / "times.txt", 1)])
        self.stamps = self._lookup(times, numbers, "times.txt")
        self.gt_poses = invert(self.velo_to_cam) @ cam_poses @ self.velo_to_cam
        self.poses = drifted(self.gt_poses, drift)

    def _scans(self) -> tuple[list[Path], np.ndarray]:
        files = sorted(p for p in (self.root / "velodyne").glob("*.bin") if p.stem.isdigit())
        if not files:
            raise FileFormatError(f"{self.root / 'velodyne'}: no NNNNNN.bin scans")
        return files, np.array([int(p.stem) for p in files])

    def _lookup(self, table: np.ndarray, numbers: np.ndarray, name: str = "poses") -> np.ndarray:
        """Rows of a per-scan table for the scans on disk; a scan past its end is an error."""
        if numbers.max() >= len(table):
            missing = self.files[int(np.argmax(numbers >= len(table)))]
            raise FileFormatError(
                f"{missing}: no entry in {name} (it has {len(table)} lines for scans 0.."
                f"{len(table) - 1})"
            )
        return table[numbers]

    def _points(self, i: int) -> np.ndarray:
        return crop(read_scan(self.files[i]), **self.options)
