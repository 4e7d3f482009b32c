"""TUM-format trajectory files (``stamp tx ty tz qx qy qz qw``) and rotation conversions."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotations → (M, 4) unit quaternions (qx, qy, qz, qw) with qw ≥ 0."""
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    # Shepperd's method: pivot on the largest of the four squared components.
    t = np.stack(
        [
            1 + R[:, 0, 0] - R[:, 1, 1] - R[:, 2, 2],
            1 - R[:, 0, 0] + R[:, 1, 1] - R[:, 2, 2],
            1 - R[:, 0, 0] - R[:, 1, 1] + R[:, 2, 2],
            1 + R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2],
        ],
        axis=1,
    )
    q = np.empty((len(R), 4))
    for n, k in enumerate(np.argmax(t, axis=1)):
        r, s = R[n], 0.5 / np.sqrt(t[n, k])
        if k == 0:
            q[n] = [
                t[n, 0] * s,
                (r[0, 1] + r[1, 0]) * s,
                (r[0, 2] + r[2, 0]) * s,
                (r[2, 1] - r[1, 2]) * s,
            ]
        elif k == 1:
            q[n] = [
                (r[0, 1] + r[1, 0]) * s,
                t[n, 1] * s,
                (r[1, 2] + r[2, 1]) * s,
                (r[0, 2] - r[2, 0]) * s,
            ]
        elif k == 2:
            q[n] = [
                (r[0, 2] + r[2, 0]) * s,
                (r[1, 2] + r[2, 1]) * s,
                t[n, 2] * s,
                (r[1, 0] - r[0, 1]) * s,
            ]
        else:
            q[n] = [
                (r[2, 1] - r[1, 2]) * s,
                (r[0, 2] - r[2, 0]) * s,
                (r[1, 0] - r[0, 1]) * s,
                t[n, 3] * s,
            ]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def write_trajectory(
    path: str | Path,
    stamps: np.ndarray,
    poses: np.ndarray,
    header: str = "timestamp tx ty tz qx qy qz qw",
) -> None:
    """Writes (M,) stamps and (M, 4, 4) poses in TUM format (9 decimals: sub-nanometre)."""
    q = matrix_to_quaternion(poses[:, :3, :3])
    rows = np.column_stack([stamps, poses[:, :3, 3], q])
    np.savetxt(path, rows, fmt=["%.6f"] + ["%.9f"] * 7, header=header)
