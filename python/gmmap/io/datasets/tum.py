"""TUM RGB-D folders: depth PNGs with poses from a TUM-format trajectory.

Folder layout (as published): ``depth.txt`` (``stamp path`` per line), ``depth/*.png`` (uint16,
metres = value / depth_factor, 0 = no reading) and ``groundtruth.txt`` (``stamp tx ty tz qx qy
qz qw``). Folders written by gmmap's simulator add ``odometry.txt`` (same format, the robot's
own map frame) and ``intrinsics.txt`` (one line ``fx fy cx cy``).

Keyframe exports (such as ``tum_fr3_cabinet_keyframes``) number their frames 0, 1, … in
``depth.txt`` and keep the ground truth in ``truth_cam_poses.txt`` (TUM format, line i = frame
i); their ``depth.txt`` may name a folder other than the one shipped (``depth_imgs/`` for
``depth/``), so a listed image that is missing is looked for by name in ``depth/``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.io.datasets.base import FrameSequence, drifted
from gmmap.io.datasets.trajectory import associate, read_table, read_trajectory
from gmmap.math.drift import Drift
from gmmap.math.geometry import interpolate_poses, matrix_to_quaternion, quaternion_to_matrix

# Trajectories matched to depth frames by time, and the keyframe ground truth matched by line.
TIMED_POSES = ("groundtruth.txt", "odometry.txt")
KEYFRAME_POSES = "truth_cam_poses.txt"

# associate, read_table, read_trajectory (trajectory.py) and quaternion_to_matrix (geometry.py)
# are re-exported: callers have long imported them from here.
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


def read_intrinsics(path: Path) -> Intrinsics:
    """``intrinsics.txt``: one line ``fx fy cx cy`` (pixels)."""
    row = read_table(path, 4)
    try:
        fx, fy, cx, cy = (float(v) for v in row[0][:4])
    except (IndexError, ValueError) as exc:
        raise FileFormatError(f"{path}: expected one line 'fx fy cx cy' ({exc})") from exc
    return Intrinsics(fx, fy, cx, cy)


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


def at_stamps(
    times: np.ndarray, poses: np.ndarray, query: np.ndarray, nearest: np.ndarray, max_dt: float
) -> np.ndarray:
    """Poses at the query stamps: interpolated between the two samples around each stamp when
    both lie within ``max_dt`` of it (the camera moves between 100 Hz mocap samples: at fr1's
    speeds the nearest sample alone can be 0.3° off), else the nearest sample."""
    right = np.clip(np.searchsorted(times, query), 1, len(times) - 1)
    left = right - 1
    inside = (times[left] <= query) & (query <= times[right])
    close = (query - times[left] <= max_dt) & (times[right] - query <= max_dt)
    out = poses[nearest].copy()
    use = inside & close
    if use.any():
        quats = matrix_to_quaternion(poses[:, :3, :3])
        out[use] = interpolate_poses(times, poses[:, :3, 3], quats, query[use])
    return out


class TumRgbd(FrameSequence):
    """A TUM RGB-D folder as a lazy sequence of Frames (depth back-projected on access).

    Poses: with ``odometry.txt`` in the folder, ``pose`` is the odometry and ``gt_pose`` the
    ground truth (``groundtruth.txt``, optional then); without it, both are the ground truth.
    Each depth frame takes the pose nearest in time within ``max_dt`` seconds from each file;
    frames lacking one are left out (TUM's motion capture starts after the camera), and a
    folder where no frame has one raises FileFormatError. ``match`` is then "stamp".

    A keyframe folder, with ``truth_cam_poses.txt`` and neither of the files above, pairs frame
    i with line i (the counts must agree) and takes its stamps from there; ``match`` is
    "order" and both poses are that ground truth.

    Options:
        stride: take every ``stride``-th pixel in both directions (1 = all 307,200).
        min_range, max_range: keep depths in this interval (metres).
        max_dt: association tolerance between depth and pose stamps (seconds).
        depth_factor: PNG value per metre (5000 for TUM and the simulator).
        intrinsics: the camera; default ``intrinsics.txt`` if present, else the fr1/fr2/fr3
            calibration named by the folder (``..._freiburg1_...``, ``tum_fr3_...``).
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
        timed = any((self.root / name).is_file() for name in TIMED_POSES)
        if timed or not (self.root / KEYFRAME_POSES).is_file():
            self.match = "stamp"
            self.stamps, self.files, gt, odom = self._by_stamp(stamps, files, max_dt)
        else:
            self.match = "order"
            self.stamps, self.files, gt, odom = self._by_order(files)
        self.gt_poses = gt
        self.poses = drifted(gt if odom is None else odom, drift)

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
        return stamps, [self._locate(r[1]) for r in rows]

    def _locate(self, listed: str) -> Path:
        """The depth image depth.txt names, or one of that name in depth/ when only that exists
        (a missing image stays as listed: reading it then names the file depth.txt gave)."""
        path = self.root / listed
        if path.is_file():
            return path
        moved = self.root / "depth" / path.name
        return moved if moved.is_file() else path

    def _by_stamp(
        self, stamps: np.ndarray, files: list[Path], max_dt: float
    ) -> tuple[np.ndarray, list[Path], np.ndarray | None, np.ndarray | None]:
        """Frames with a pose within max_dt in every timed trajectory present: (stamps, files,
        ground truth or None, odometry or None)."""
        sources = self._timed_pose_files()
        matches = {name: associate(stamps, read[0], max_dt) for name, read in sources.items()}
        keep = np.logical_and.reduce([m >= 0 for m in matches.values()])
        if not keep.any():
            raise FileFormatError(
                f"{self.root}: no frame of depth.txt has a pose in {' and '.join(sources)} "
                f"within max_dt={max_dt} s (depth stamps {stamps.min():.3f}..{stamps.max():.3f})"
            )
        picked = {
            name: at_stamps(*sources[name], stamps[keep], m[keep], max_dt)
            for name, m in matches.items()
        }
        kept = [f for f, k in zip(files, keep, strict=True) if k]
        return stamps[keep], kept, picked.get("groundtruth.txt"), picked.get("odometry.txt")

    def _by_order(self, files: list[Path]) -> tuple[np.ndarray, list[Path], np.ndarray, None]:
        """Frame i with line i of the keyframe ground truth, whose stamps replace depth.txt's
        (keyframe exports number their frames there)."""
        path = self.root / KEYFRAME_POSES
        stamps, poses = read_trajectory(path, sort=False)
        if len(stamps) != len(files):
            raise FileFormatError(
                f"{path}: {len(stamps)} poses for {len(files)} frames in depth.txt (line i is "
                "frame i's pose: the counts must agree)"
            )
        return stamps, files, poses, None

    def _timed_pose_files(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The trajectories present: ground truth and/or odometry (at least one)."""
        found = {
            name: read_trajectory(self.root / name)
            for name in TIMED_POSES
            if (self.root / name).is_file()
        }
        if not found:
            raise FileNotFoundError(
                f"{self.root / TIMED_POSES[0]}: missing (nor odometry.txt or {KEYFRAME_POSES}: "
                "no poses)"
            )
        return found

    def _points(self, i: int) -> np.ndarray:
        return depth_to_points(read_depth(self.files[i]), self.intrinsics, **self.options)
