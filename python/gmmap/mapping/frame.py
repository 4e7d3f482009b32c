"""The record every dataset loader yields."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One sensor frame: points in the sensor frame and the sensor's pose.

    ``pose`` maps sensor coordinates into the robot's map frame (its odometry); ``gt_pose`` is
    the ground-truth pose in the dataset's world frame, when the data has one.
    """

    stamp: float
    points: np.ndarray  # (N, 3) float32, sensor frame
    pose: np.ndarray  # (4, 4) sensor -> map
    gt_pose: np.ndarray | None = None

    def world_points(self) -> np.ndarray:
        """The points in the map frame (float64)."""
        R, t = self.pose[:3, :3], self.pose[:3, 3]
        return self.points.astype(np.float64) @ R.T + t
