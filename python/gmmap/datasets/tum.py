"""TUM RGB-D folders: depth PNGs associated with motion-capture ground truth.

Folder layout (as published): ``depth.txt`` (``stamp path`` per line), ``depth/*.png`` (uint16,
metres = value / depth_factor, 0 = no reading) and ``groundtruth.txt`` (``stamp tx ty tz qx qy
qz qw``). The data has no odometry, so a frame's ``pose`` is its ground truth.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from gmmap.datasets.frame import Frame
from gmmap.errors import FileFormatError, InvalidInputError


@dataclass(frozen=True)
class Intrinsics:
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
        f"{root}: cannot tell fr1/fr2/fr3 from the folder name; pass intrinsics explicitly"
    )


def read_table(path: Path, columns: int) -> list[list[str]]:
    """Rows of a whitespace-separated text file, comments skipped, with at least ``columns``."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing")
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        if len(fields) < columns:
            raise FileFormatError(f"{path}:{n}: expected {columns} fields, got {len(fields)}")
        rows.append(fields)
    return rows


def read_trajectory(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """TUM trajectory file → (stamps (M,), poses (M, 4, 4)), sorted by time."""
    rows = read_table(path, 8)
    try:
        data = np.array([[float(v) for v in r[:8]] for r in rows])
    except ValueError as exc:
        raise FileFormatError(f"{path}: non-numeric value ({exc})") from exc
    if len(data) == 0:
        raise FileFormatError(f"{path}: no poses")
    data = data[np.argsort(data[:, 0], kind="stable")]
    poses = np.tile(np.eye(4), (len(data), 1, 1))
    poses[:, :3, :3] = quaternion_to_matrix(data[:, 4:8])
    poses[:, :3, 3] = data[:, 1:4]
    return data[:, 0], poses


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """(M, 4) quaternions as (qx, qy, qz, qw), normalised here, → (M, 3, 3) rotations."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    ).transpose(2, 0, 1)


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
    """Back-projects a depth image into (N, 3) float32 camera-frame points (z forward)."""
    d = depth[::stride, ::stride].astype(np.float32) / np.float32(depth_factor)
    v, u = np.mgrid[0 : depth.shape[0] : stride, 0 : depth.shape[1] : stride]
    keep = (d > min_range) & (d < max_range)
    z = d[keep]
    x = (u[keep] - intrinsics.cx) * z / intrinsics.fx
    y = (v[keep] - intrinsics.cy) * z / intrinsics.fy
    return np.stack([x, y, z], axis=1).astype(np.float32)


class TumRgbd(Sequence):
    """A TUM RGB-D folder as a lazy sequence of Frames (depth frames with ground truth).

    Depth frames with no ground-truth pose within ``max_dt`` seconds are left out.
    """

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
    ) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"{self.root}: no such folder")
        self.intrinsics = intrinsics or intrinsics_for(self.root)
        self.options = dict(
            depth_factor=depth_factor, stride=stride, min_range=min_range, max_range=max_range
        )
        rows = read_table(self.root / "depth.txt", 2)
        stamps = np.array([float(r[0]) for r in rows])
        gt_stamps, gt_poses = read_trajectory(self.root / "groundtruth.txt")
        match = associate(stamps, gt_stamps, max_dt)
        keep = match >= 0
        if not keep.any():
            raise FileFormatError(
                f"{self.root}: no depth frame has a ground-truth pose within {max_dt} s"
            )
        self.stamps = stamps[keep]
        self.files = [self.root / r[1] for r, k in zip(rows, keep, strict=True) if k]
        self.gt_poses = gt_poses[match[keep]]

    def __len__(self) -> int:
        return len(self.stamps)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        points = depth_to_points(read_depth(self.files[i]), self.intrinsics, **self.options)
        pose = self.gt_poses[i]
        return Frame(float(self.stamps[i]), points, pose.copy(), pose.copy())
