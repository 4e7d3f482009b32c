"""TUM-format trajectory files: one pose per line, ``stamp tx ty tz qx qy qz qw`` (sensor→map),
``#`` comments; read, written, and matched to frame stamps. Every loader and the simulator use
these (the quaternion conversions live in ``geometry``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gmmap.errors import FileFormatError
from gmmap.math.geometry import make_poses, matrix_to_quaternion

__all__ = ["associate", "read_table", "read_trajectory", "write_trajectory"]

HEADER = "timestamp tx ty tz qx qy qz qw"


def read_table(path: Path, columns: int) -> list[list[str]]:
    """Rows of a whitespace- (or comma-) separated text file, comments skipped, each with at
    least ``columns`` fields."""
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


def write_trajectory(
    path: str | Path, stamps: np.ndarray, poses: np.ndarray, header: str = HEADER
) -> None:
    """Writes (M,) stamps and (M, 4, 4) poses in TUM format: stamps to the microsecond, the
    rest to 9 decimals (sub-nanometre, and rotations good to about 1e-9)."""
    q = matrix_to_quaternion(poses[:, :3, :3])
    rows = np.column_stack([stamps, poses[:, :3, 3], q])
    np.savetxt(path, rows, fmt=["%.6f"] + ["%.9f"] * 7, header=header)


def associate(query: np.ndarray, reference: np.ndarray, max_dt: float) -> np.ndarray:
    """For each query stamp, the index of the nearest (sorted) reference stamp, or -1 when none
    lies within ``max_dt`` seconds."""
    right = np.clip(np.searchsorted(reference, query), 1, len(reference) - 1)
    left = right - 1
    nearest = np.where(
        np.abs(reference[left] - query) <= np.abs(reference[right] - query), left, right
    )
    if len(reference) == 1:
        nearest = np.zeros_like(query, dtype=int)
    return np.where(np.abs(reference[nearest] - query) <= max_dt, nearest, -1)
