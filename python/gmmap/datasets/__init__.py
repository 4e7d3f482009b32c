"""Dataset loaders: each yields `Frame`s (points in the sensor frame plus poses)."""

from pathlib import Path

from gmmap.datasets.frame import Frame
from gmmap.datasets.tum import TumRgbd

BUNDLED_TUM_SLICE = Path(__file__).resolve().parent.parent / "data" / "tum_fr1_xyz_slice"

__all__ = ["BUNDLED_TUM_SLICE", "Frame", "TumRgbd"]
