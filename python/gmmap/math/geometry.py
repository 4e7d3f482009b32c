"""Small rigid-motion helpers shared by the loaders and the pose-graph backend (numpy only:
scipy is not a dependency).

Quaternions are (qx, qy, qz, qw), the order of TUM files and ROS messages. SE(3) tangents are
(ω, v), GTSAM's order.
"""

from __future__ import annotations

import math

import numpy as np

from gmmap.errors import InvalidInputError


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """(M, 4) quaternions as (qx, qy, qz, qw), normalised here, → (M, 3, 3) rotations."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    return np.stack(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    ).transpose(2, 0, 1)


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotations → (M, 4) unit quaternions (qx, qy, qz, qw) with qw ≥ 0.

    Every entry of the outer product 4·q qᵀ is a sum of entries of R; the row of the largest
    diagonal entry is the best-conditioned estimate of q (Shepperd's choice of pivot).
    """
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    d0, d1, d2 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    xx, yy = 1 + d0 - d1 - d2, 1 - d0 + d1 - d2
    zz, ww = 1 - d0 - d1 + d2, 1 + d0 + d1 + d2
    xy, xz, yz = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
    wx, wy, wz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    outer = np.stack(
        [
            np.stack([xx, xy, xz, wx], axis=1),
            np.stack([xy, yy, yz, wy], axis=1),
            np.stack([xz, yz, zz, wz], axis=1),
            np.stack([wx, wy, wz, ww], axis=1),
        ],
        axis=1,
    )
    pivot = np.argmax(np.stack([xx, yy, zz, ww], axis=1), axis=1)
    q = outer[np.arange(len(R)), pivot]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    # q and -q are one rotation: pick qw ≥ 0 so equal rotations give equal quaternions.
    return np.where(q[:, 3:] < 0, -q, q)


def make_poses(translations: np.ndarray, quaternions: np.ndarray) -> np.ndarray:
    """(M, 3) translations and (M, 4) quaternions → (M, 4, 4) rigid transforms."""
    poses = np.tile(np.eye(4), (len(translations), 1, 1))
    poses[:, :3, :3] = quaternion_to_matrix(quaternions)
    poses[:, :3, 3] = translations
    return poses


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid (..., 4, 4) transforms (exact: Rᵀ, not a general inverse)."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    out = np.zeros_like(T)
    out[..., :3, :3] = np.swapaxes(R, -1, -2)
    out[..., :3, 3] = -np.einsum("...ji,...j->...i", R, t)
    out[..., 3, 3] = 1.0
    return out


def so3_exp(w: np.ndarray) -> np.ndarray:
    """(M, 3) rotation vectors (axis × angle) → (M, 3, 3) rotations (Rodrigues)."""
    w = np.asarray(w, dtype=np.float64).reshape(-1, 3)
    theta = np.linalg.norm(w, axis=1)
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K -= K.transpose(0, 2, 1)
    # Taylor series near 0 keeps the coefficients finite for tiny angles.
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24, (1 - np.cos(safe)) / safe**2)
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotations → (M,) rotation angles in [0, π]."""
    trace = np.trace(np.asarray(R).reshape(-1, 3, 3), axis1=1, axis2=2)
    return np.arccos(np.clip((trace - 1) / 2, -1.0, 1.0))


def pose_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """How far apart two 4x4 poses are: translation (m) and rotation (degrees)."""
    translation = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    angle = float(rotation_angle(a[:3, :3].T @ b[:3, :3])[0])
    return translation, math.degrees(angle)


def rigid_matrix(T: np.ndarray, what: str) -> np.ndarray:
    """A finite 4x4 rigid transform, projected onto SE(3); InvalidInputError (naming ``what``)
    for anything else."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidInputError(f"{what} must be a finite 4x4 matrix, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
        raise InvalidInputError(f"{what} is not a rigid transform")
    return project_rigid(T)


def project_rigid(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) with the rotation blocks replaced by their nearest rotations (SVD)."""
    U, _, Vt = np.linalg.svd(T[..., :3, :3])
    out = np.array(T, dtype=np.float64)
    out[..., :3, :3] = U @ Vt
    out[..., 3, :] = (0.0, 0.0, 0.0, 1.0)
    return out


def adjoint(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) → (..., 6, 6) adjoints for (ω, v) tangents: [[R, 0], [[t]×R, R]], so that
    exp(ξ)·T = T·exp(Ad(T)⁻¹ ξ) (GTSAM's Pose3.AdjointMap)."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    out = np.zeros((*T.shape[:-2], 6, 6))
    out[..., :3, :3] = R
    out[..., 3:, 3:] = R
    out[..., 3:, :3] = _hat(t) @ R
    return out


def _hat(v: np.ndarray) -> np.ndarray:
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    return out - np.swapaxes(out, -1, -2)


def right_information(transform: np.ndarray, information_left: np.ndarray) -> np.ndarray:
    """Information of a left perturbation exp(ξ)·T as one of a right perturbation T·exp(ξ')
    (GTSAM's): ξ = Ad_T ξ', so Info_R = Ad_Tᵀ Info_L Ad_T."""
    Ad = adjoint(np.asarray(transform, dtype=np.float64))
    return Ad.T @ np.asarray(information_left, dtype=np.float64) @ Ad


def invert_with_cov(T: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T⁻¹ and its left-perturbation covariance: (exp(ξ)T)⁻¹ = exp(−Ad_{T⁻¹} ξ)·T⁻¹."""
    Ti = invert(T)
    Ad = adjoint(Ti)
    return Ti, Ad @ C @ Ad.T


def se3_log(T: np.ndarray) -> np.ndarray:
    """(..., 4, 4) → (..., 6) SE(3) logarithm (ω, v), finite for any rotation (wrong matches).

    The translation part matters: with (log R, t) instead, loops far from the map origin pick
    up second-order rotation·lever-arm terms and true matches fail the χ² test several times
    more often than the nominal rate."""
    R = T[..., :3, :3]
    theta = rotation_angle(R.reshape(-1, 3, 3)).reshape(R.shape[:-2])
    vee = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    s = np.sin(theta)
    ok = s > 1e-6
    w = np.where(ok, theta / np.where(ok, 2 * s, 1.0), 0.5)[..., None] * vee
    # Near π the skew part vanishes; the axis is then the dominant column of (R + I)/2.
    near_pi = theta > math.pi - 1e-3
    if np.any(near_pi):
        B = 0.5 * (R[near_pi] + np.eye(3))
        k = np.argmax(np.diagonal(B, axis1=1, axis2=2), axis=1)
        col = B[np.arange(len(B)), :, k]
        w[near_pi] = col / np.linalg.norm(col, axis=1, keepdims=True) * theta[near_pi][:, None]
    # v = J⁻¹(ω) t with J⁻¹ = I − W/2 + (1/θ² − (1 + cos θ)/(2θ sin θ)) W²: → 1/12 at 0,
    # → 1/π² at π (the second term vanishes there).
    W = _hat(w)
    small = theta < 1e-6
    th = np.where(small, 1.0, theta)
    second = np.where(ok, (1 + np.cos(th)) / (2 * th * np.where(ok, s, 1.0)), 0.0)
    c = np.where(small, 1 / 12, 1 / th**2 - second)
    J_inv = np.eye(3) - 0.5 * W + c[..., None, None] * (W @ W)
    return np.concatenate([w, np.einsum("...ij,...j->...i", J_inv, T[..., :3, 3])], axis=-1)


def slerp(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Spherical interpolation between (M, 4) unit quaternions at fractions (M,) in [0, 1]."""
    dot = np.sum(q0 * q1, axis=1)
    # q and -q are one rotation: flip to take the short way round.
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    dot = np.abs(dot)
    omega = np.arccos(np.clip(dot, -1.0, 1.0))
    near = omega < 1e-6  # nearly equal: linear interpolation is exact to rounding
    s = np.where(near, 1.0, np.sin(omega))
    w0 = np.where(near, 1 - a, np.sin((1 - a) * omega) / s)
    w1 = np.where(near, a, np.sin(a * omega) / s)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def interpolate_poses(
    stamps: np.ndarray, translations: np.ndarray, quaternions: np.ndarray, query: np.ndarray
) -> np.ndarray:
    """Poses at ``query`` stamps, linear in translation and slerp in rotation.

    ``stamps`` must be sorted; every query must lie within [stamps[0], stamps[-1]] (the caller
    drops the others: extrapolating odometry would invent motion).
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    query = np.asarray(query, dtype=np.float64)
    if len(stamps) == 1:
        return make_poses(
            np.repeat(translations, len(query), 0), np.repeat(quaternions, len(query), 0)
        )
    right = np.clip(np.searchsorted(stamps, query, side="right"), 1, len(stamps) - 1)
    left = right - 1
    span = stamps[right] - stamps[left]
    a = np.clip(np.where(span > 0, (query - stamps[left]) / np.where(span > 0, span, 1), 0), 0, 1)
    t = translations[left] + a[:, None] * (translations[right] - translations[left])
    q0 = quaternions[left] / np.linalg.norm(quaternions[left], axis=1, keepdims=True)
    q1 = quaternions[right] / np.linalg.norm(quaternions[right], axis=1, keepdims=True)
    return make_poses(t, slerp(q0, q1, a))


def path_length(poses: np.ndarray) -> float:
    """Length of the polyline through the poses' positions, in metres."""
    if len(poses) < 2:
        return 0.0
    return float(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum())
