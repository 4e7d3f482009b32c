"""Point arrays: validation shared by every stage, and the voxel filter."""

from __future__ import annotations

import numpy as np

from gmmap import _core
from gmmap.errors import InvalidInputError


def as_points(points: object, name: str = "points", allow_empty: bool = False) -> np.ndarray:
    """Returns ``points`` as a C-contiguous (N, 3) float64 array, or raises InvalidInputError."""
    try:
        arr = np.ascontiguousarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be numeric (N, 3) coordinates: {exc}") from exc
    if arr.ndim == 1 and arr.shape == (3,):
        arr = arr.reshape(1, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InvalidInputError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not allow_empty and arr.shape[0] == 0:
        raise InvalidInputError(f"{name} is empty")
    finite = np.isfinite(arr).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        raise InvalidInputError(
            f"{name} contain NaN or infinite values ({int((~finite).sum())} rows, first at row "
            f"{row}: {arr[row].tolist()})"
        )
    return arr


def voxel_filter(points: object, voxel_size: float) -> np.ndarray:
    """One point per occupied voxel of edge ``voxel_size``: the centroid of the points inside.

    Voxels are returned in the order their first point appears. Runs in the Rust core in
    O(N) time and O(voxels) memory.
    """
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise InvalidInputError(f"voxel_size must be positive and finite, got {voxel_size}")
    pts = as_points(points, allow_empty=True)
    try:
        return _core.voxel_filter(pts, float(voxel_size))
    except ValueError as exc:
        raise InvalidInputError(str(exc)) from exc
