"""TUM RGB-D folders: depth PNGs with poses from a TUM-format trajectory.

Folder layout (as published): ``depth.txt`` (``stamp path`` per line), ``depth/*.png`` (uint16,
metres = value / depth_factor, 0 = no reading) and ``groundtruth.txt`` (``stamp tx ty tz qx qy
qz qw``). Folders written by gmmap's simulator add ``odometry.txt`` (same format, the robot's
own map frame) and ``intrinsics.txt`` (one line ``fx fy cx cy``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from gmmap.datasets.base import FrameSequence, drifted
from gmmap.datasets.drift import Drift
from gmmap.datasets.geometry import make_poses, quaternion_to_matrix
from gmmap.errors import FileFormatError, InvalidInputError

__all__ = [
    "INTRINSICS",
    "Intrinsics",
    "TumRgbd",
    "associate",
    "depth_to_points",
    "intrinsics_for",
    "quaternion_to_matrix",
    "read_depth",
    "read_intrinsics",
    "read_table",
    "read_trajectory",
]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels."""

    fx: float
    fy: float
    cx: float
    cy: float


# The calibrations TUM publishes for its three Kinects.
INTRINSICS = {
    "fr1": Intrinsics(517.3, 516.5, 318.6, 255.3),
    "fr2": Intrinsics(520.9, 521.0, 325.1, 249.7),
    "fr3": Intrinsics(535.4, 539.2, 320.1, 247.6),
}


def intrinsics_for(root: Path) -> Intrinsics:
    """The fr1/fr2/fr3 calibration named by a folder such as ``rgbd_dataset_freiburg1_xyz``."""
    name = root.resolve().name.lower()
    for key in INTRINSICS:
        if key in name or f"freiburg{key[-1]}" in name:
            return INTRINSICS[key]
    raise InvalidInputError(
        f"{root}: cannot tell fr1/fr2/fr3 from the folder name; pass intrinsics= or write "
        "intrinsics.txt ('fx fy cx cy')"
    )


def read_table(path: Path, columns: int) -> list[list[str]]:
    """Rows of a whitespace-separated text file, comments skipped, with at least ``columns``."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing")
    try:
        text = path.read_text()
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: not a text file ({exc})") from exc
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        if len(fields) < columns:
            raise FileFormatError(f"{path}:{n}: expected {columns} fields, got {len(fields)}")
        rows.append(fields)
    return rows


def read_trajectory(path: Path, sort: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """TUM trajectory file → (stamps (M,), poses (M, 4, 4)), sorted by time unless ``sort`` is
    False (then in line order, for files whose line i belongs to frame i)."""
    rows = read_table(path, 8)
    try:
        data = np.array([[float(v) for v in r[:8]] for r in rows])
    except ValueError as exc:
        raise FileFormatError(f"{path}: non-numeric value ({exc})") from exc
    if len(data) == 0:
        raise FileFormatError(f"{path}: no poses")
    if not np.isfinite(data).all():
        raise FileFormatError(f"{path}: NaN or infinite values")
    if sort:
        data = data[np.argsort(data[:, 0], kind="stable")]
    return data[:, 0], make_poses(data[:, 1:4], data[:, 4:8])


def read_intrinsics(path: Path) -> Intrinsics:
    """``intrinsics.txt``: one line ``fx fy cx cy`` (pixels)."""
    row = read_table(path, 4)
    try:
        fx, fy, cx, cy = (float(v) for v in row[0][:4])
    except (IndexError, ValueError) as exc:
        raise FileFormatError(f"{path}: expected one line 'fx fy cx cy' ({exc})") from exc
    return Intrinsics(fx, fy, cx, cy)


def associate(query: np.ndarray, reference: np.ndarray, max_dt: float) -> np.ndarray:
    """For each query stamp, the index of the nearest reference stamp, or -1 beyond ``max_dt``."""
    right = np.clip(np.searchsorted(reference, query), 1, len(reference) - 1)
    left = right - 1
    nearest = np.where(
        np.abs(reference[left] - query) <= np.abs(reference[right] - query), left, right
    )
    if len(reference) == 1:
        nearest = np.zeros_like(query, dtype=int)
    return np.where(np.abs(reference[nearest] - query) <= max_dt, nearest, -1)


def read_depth(path: Path) -> np.ndarray:
    """A 16-bit depth PNG as a (H, W) uint16 array; errors name the file."""
    try:
        with Image.open(path) as img:
            img.load()
            depth = np.array(img)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing depth image") from None
    except (UnidentifiedImageError, OSError, SyntaxError) as exc:
        raise FileFormatError(f"{path}: unreadable depth image ({exc})") from exc
    if depth.ndim != 2 or depth.dtype not in (np.uint16, np.int32):
        raise FileFormatError(f"{path}: expected a 16-bit single-channel depth image")
    return depth.astype(np.uint16, copy=False)


def depth_to_points(
    depth: np.ndarray,
    intrinsics: Intrinsics,
    depth_factor: float = 5000.0,
    stride: int = 1,
    min_range: float = 0.1,
    max_range: float = 5.0,
) -> np.ndarray:
    """Back-projects a depth image into (N, 3) float32 camera-frame points (z forward).

    Keeps pixels with min_range < depth < max_range (metres), in row-major order.
    """
    d = depth[::stride, ::stride]
    if d.dtype == np.uint16:
        # Per-value tables: one gather instead of converting and comparing every pixel.
        metres, valid = _depth_tables(float(depth_factor), float(min_range), float(max_range))
        keep = valid[d]
        z = metres[d[keep]]
    else:
        m = d.astype(np.float32) / np.float32(depth_factor)
        keep = (m > min_range) & (m < max_range)
        z = m[keep]
    rx, ry = _pixel_rays(depth.shape, stride, intrinsics)
    out = np.empty((len(z), 3), dtype=np.float32)
    np.multiply(rx[keep], z, out=out[:, 0])
    np.multiply(ry[keep], z, out=out[:, 1])
    out[:, 2] = z
    return out


@lru_cache(maxsize=8)
def _depth_tables(factor: float, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """Metres and the range test for each of the 65,536 uint16 depth values."""
    metres = np.arange(1 << 16, dtype=np.float32) / np.float32(factor)
    return metres, (metres > lo) & (metres < hi)


@lru_cache(maxsize=8)
def _pixel_rays(
    shape: tuple[int, ...], stride: int, k: Intrinsics
) -> tuple[np.ndarray, np.ndarray]:
    """x/z and y/z of every sampled pixel (float32 grids), computed once per camera."""
    u = (np.arange(0, shape[1], stride) - k.cx) / k.fx
    v = (np.arange(0, shape[0], stride) - k.cy) / k.fy
    rx = np.broadcast_to(u.astype(np.float32), (len(v), len(u))).copy()
    ry = np.broadcast_to(v.astype(np.float32)[:, None], (len(v), len(u))).copy()
    return rx, ry


class TumRgbd(FrameSequence):
    """A TUM RGB-D folder as a lazy sequence of Frames (depth back-projected on access).

    Poses: with ``odometry.txt`` in the folder, ``pose`` is the odometry and ``gt_pose`` the
    ground truth (``groundtruth.txt``, optional then); without it, both are the ground truth.
    Each depth frame takes the pose nearest in time within ``max_dt`` seconds from each file;
    frames lacking one are left out (TUM's motion capture starts after the camera), and a
    folder where no frame has one raises FileFormatError.

    Options:
        stride: take every ``stride``-th pixel in both directions (1 = all 307,200).
        min_range, max_range: keep depths in this interval (metres).
        max_dt: association tolerance between depth and pose stamps (seconds).
        depth_factor: PNG value per metre (5000 for TUM and the simulator).
        intrinsics: the camera; default ``intrinsics.txt`` if present, else the fr1/fr2/fr3
            calibration named by the folder (``..._freiburg1_...``).
        drift: a ``Drift`` applied to the poses (simulated odometry); ``gt_pose`` is untouched.
    """

    format = "tum"

    def __init__(
        self,
        root: str | Path,
        *,
        stride: int = 1,
        min_range: float = 0.1,
        max_range: float = 5.0,
        max_dt: float = 0.02,
        depth_factor: float = 5000.0,
        intrinsics: Intrinsics | None = None,
        drift: Drift | None = None,
    ) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"{self.root}: no such folder")
        if int(stride) < 1:
            raise InvalidInputError(f"stride must be >= 1, got {stride}")
        self.intrinsics = intrinsics or self._default_intrinsics()
        self.options = dict(
            depth_factor=depth_factor, stride=int(stride), min_range=min_range, max_range=max_range
        )
        stamps, files = self._depth_list()
        sources = self._pose_files()
        matches = {name: associate(stamps, read[0], max_dt) for name, read in sources.items()}
        keep = np.logical_and.reduce([m >= 0 for m in matches.values()])
        if not keep.any():
            raise FileFormatError(
                f"{self.root}: no frame of depth.txt has a pose in {' and '.join(sources)} "
                f"within max_dt={max_dt} s (depth stamps {stamps.min():.3f}..{stamps.max():.3f})"
            )
        self.stamps = stamps[keep]
        self.files = [f for f, k in zip(files, keep, strict=True) if k]
        picked = {name: sources[name][1][m[keep]] for name, m in matches.items()}
        self.gt_poses = picked.get("groundtruth.txt")
        self.poses = drifted(picked.get("odometry.txt", self.gt_poses), drift)

    def _default_intrinsics(self) -> Intrinsics:
        path = self.root / "intrinsics.txt"
        return read_intrinsics(path) if path.is_file() else intrinsics_for(self.root)

    def _depth_list(self) -> tuple[np.ndarray, list[Path]]:
        path = self.root / "depth.txt"
        rows = read_table(path, 2)
        if not rows:
            raise FileFormatError(f"{path}: no frames listed")
        try:
            stamps = np.array([float(r[0]) for r in rows])
        except ValueError as exc:
            raise FileFormatError(f"{path}: non-numeric stamp ({exc})") from exc
        return stamps, [self.root / r[1] for r in rows]

    def _pose_files(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The trajectories present: ground truth and/or odometry (at least one)."""
        found = {
            name: read_trajectory(self.root / name)
            for name in ("groundtruth.txt", "odometry.txt")
            if (self.root / name).is_file()
        }
        if not found:
            raise FileNotFoundError(f"{self.root / 'groundtruth.txt'}: missing (no poses)")
        return found

    def _points(self, i: int) -> np.ndarray:
        return depth_to_points(read_depth(self.files[i]), self.intrinsics, **self.options)
