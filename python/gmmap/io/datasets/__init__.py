"""Dataset loaders: each is a lazy, sized sequence of `Frame`s (points in the sensor frame plus
poses). `open(path)` picks the loader from what the path holds.

| format | loader | what `open` looks for |
|---|---|---|
| "tum" | `TumRgbd` | a folder with depth.txt |
| "kitti" | `KittiOdometry` | a folder with velodyne/ |
| "pointfiles" | `PointFiles` | a folder of .ply / .pcd files (with a TUM-format poses file) |
| "rosbag" | `RosBag` | a .bag file; a ROS 2 bag folder (metadata.yaml, .db3, .mcap) or file |

`gmmap sim` writes one folder per robot that `open` reads back: a TUM folder for depth cameras
(odometry.txt and groundtruth.txt), a point-file folder for LiDARs (poses.txt, the odometry, and
groundtruth.txt); either way ``Frame.pose`` is the odometry and ``Frame.gt_pose`` the truth.
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path
from typing import Any

from gmmap.errors import InvalidInputError, UnknownFormatError
from gmmap.io.datasets.base import FrameSequence, describe
from gmmap.io.datasets.kitti import KittiOdometry
from gmmap.io.datasets.pointfiles import READERS, PointFiles
from gmmap.io.datasets.tum import TumRgbd
from gmmap.mapping.frame import Frame
from gmmap.math.drift import Drift, apply_drift

BUNDLED_TUM_SLICE = Path(__file__).resolve().parents[2] / "data" / "tum_fr1_xyz_slice"

# Loader classes by format name; "module:Class" entries are imported on first use (rosbags
# takes a quarter of a second to import and most runs never read a bag).
LOADERS: dict[str, Any] = {
    "tum": TumRgbd,
    "kitti": KittiOdometry,
    "pointfiles": PointFiles,
    "rosbag": "gmmap.io.datasets.rosbag:RosBag",
}
SUPPORTED = (
    "tum (a TUM RGB-D folder: depth.txt, depth/, groundtruth.txt or odometry.txt, or a keyframe "
    "export's truth_cam_poses.txt), "
    "kitti (a KITTI odometry sequence folder: velodyne/*.bin, poses.txt, times.txt, calib), "
    "pointfiles (a folder of .ply/.pcd files with a TUM-format poses.txt, and optionally "
    "groundtruth.txt), "
    "rosbag (a ROS 1 .bag file, or a ROS 2 bag folder with metadata.yaml or a .db3/.mcap file)"
)
BAG_SUFFIXES = (".bag", ".db3", ".mcap")

__all__ = [
    "BUNDLED_TUM_SLICE",
    "LOADERS",
    "Drift",
    "Frame",
    "FrameSequence",
    "KittiOdometry",
    "PointFiles",
    "RosBag",
    "TumRgbd",
    "apply_drift",
    "describe",
    "detect_format",
    "loader_class",
    "open",
]


def __getattr__(name: str) -> Any:
    if name == "RosBag":
        return loader_class("rosbag")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def loader_class(fmt: str) -> type[FrameSequence]:
    """The loader class of a format name."""
    if fmt not in LOADERS:
        raise InvalidInputError(f"unknown format {fmt!r}; one of {', '.join(LOADERS)}")
    entry = LOADERS[fmt]
    if isinstance(entry, str):
        module, name = entry.split(":")
        entry = LOADERS[fmt] = getattr(importlib.import_module(module), name)
    return entry


def detect_format(path: str | Path) -> str:
    """The format name of a dataset path (see the module docstring), or UnknownFormatError."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file or folder")
    if path.is_file():
        if path.suffix in BAG_SUFFIXES:
            return "rosbag"
    elif (path / "metadata.yaml").is_file() or any(
        p.suffix in BAG_SUFFIXES[1:] for p in path.iterdir()
    ):
        return "rosbag"
    elif (path / "depth.txt").is_file():
        return "tum"
    elif (path / "velodyne").is_dir():
        return "kitti"
    elif any(p.suffix.lower() in READERS for p in path.iterdir()):
        return "pointfiles"
    raise UnknownFormatError(f"{path}: not a dataset gmmap can read. Supported: {SUPPORTED}")


def open(path: str | Path, format: str | None = None, **options: Any) -> FrameSequence:
    """Opens a dataset as a lazy sequence of Frames, detecting its format unless ``format`` is
    given; ``options`` go to the loader (see each loader's docstring)."""
    cls = loader_class(format or detect_format(path))
    accepted = [
        p.name
        for p in inspect.signature(cls).parameters.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY
    ]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise InvalidInputError(
            f"{cls.__name__} ({cls.format}) takes no option {', '.join(unknown)}; "
            f"its options: {', '.join(accepted)}"
        )
    return cls(path, **options)
