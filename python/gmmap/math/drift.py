"""Simulated odometry drift: noisy relative motions chained from the first true pose.

Noise model (per frame i ≥ 1, the usual wheel/visual-odometry error model): let
Δᵢ = Tᵢ₋₁⁻¹ Tᵢ be the true motion between consecutive poses, dᵢ its translation length (m) and
θᵢ its rotation angle (rad). The odometry measures Δ̃ᵢ = Δᵢ · Eᵢ, where Eᵢ is a small random
rigid motion in the frame of pose i with independent Gaussian components

    translation, each axis:  σₜ = translation · dᵢ + translation_floor              (m)
    rotation vector, each axis: σᵣ = rotation_per_rad · θᵢ + rotation_per_m · dᵢ + rotation_floor

and the drifted trajectory is D₀ = T₀, Dᵢ = Dᵢ₋₁ Δ̃ᵢ. The error is a random walk: it grows with
the distance travelled and the angle turned (and, with the floors, with the frame count), and
a robot that stands still does not drift unless a floor is set.

With ``up`` set (a direction in the poses' frame), the odometry is gravity-referenced: the
rotation noise turns about ``up`` only (its size is σᵣ of the z component above) and roll and
pitch never drift, as on a ground robot whose IMU sees gravity or under visual-inertial
odometry (the paper's RealSense T265), whose drift lies in position and heading only.

All normal draws are made up front, 6 per frame, from one generator, so a seed gives the same
trajectory on any machine and the error scales linearly with the parameters for a fixed seed.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.math.geometry import invert, rotation_angle, so3_exp
from gmmap.options import drift_overrides


@dataclass(frozen=True)
class Drift:
    """Parameters of the drift model above (standard deviations; all ≥ 0) and its seed.

    Defaults are a mediocre wheel odometry: 2 % of the distance per axis, 0.02 rad per radian
    turned and 0.005 rad (0.3°) per metre, about every axis (``up`` None) or about ``up`` only.
    A ``Drift`` is callable as ``drift(poses, rng)``, the odometry-model signature the
    simulator takes.
    """

    translation: float = 0.02
    translation_floor: float = 0.0
    rotation_per_rad: float = 0.02
    rotation_per_m: float = 0.005
    rotation_floor: float = 0.0
    seed: int = 0
    up: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if name in ("seed", "up"):
                continue
            if not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"Drift.{name} must be finite and >= 0, got {value}")
        if self.up is not None:
            u = np.asarray(self.up, dtype=float)
            if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
                raise InvalidInputError(f"Drift.up must be a non-zero 3-vector, got {self.up}")

    @classmethod
    def per_metre(
        cls, drift: float, seed: int = 0, up: tuple[float, float, float] | None = None
    ) -> Drift:
        """The defaults' shape scaled by one figure: ``drift`` of the distance per axis and rad
        per radian turned, a quarter of it in rad per metre (0.02 gives the defaults)."""
        return cls(**drift_overrides(drift), seed=seed, up=up)

    def __call__(self, poses: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        return apply_drift(poses, self, rng)


def apply_drift(
    poses: np.ndarray, drift: Drift | None = None, rng: np.random.Generator | None = None
) -> np.ndarray:
    """(M, 4, 4) true poses → (M, 4, 4) drifted poses; the first pose is returned unchanged.

    ``rng`` overrides ``drift.seed`` (the simulator seeds one generator per robot).
    """
    drift = drift or Drift()
    T = np.asarray(poses, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise InvalidInputError(f"poses must have shape (M, 4, 4), got {T.shape}")
    out = T.copy()
    if len(T) < 2:
        return out
    rng = rng if rng is not None else np.random.default_rng(drift.seed)
    steps = invert(T[:-1]) @ T[1:]
    noisy = steps @ _noise(steps, drift, rng.standard_normal((len(steps), 6)), T[1:, :3, :3])
    for i, step in enumerate(noisy, 1):
        out[i] = out[i - 1] @ step
    return out


def _noise(steps: np.ndarray, drift: Drift, z: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """(M, 4, 4) error motions Eᵢ for the true steps, from standard normals z (M, 6);
    ``rotations`` (M, 3, 3) are the true poses' at the end of each step (Eᵢ's frame)."""
    dist = np.linalg.norm(steps[:, :3, 3], axis=1)
    angle = rotation_angle(steps[:, :3, :3])
    sigma_t = drift.translation * dist + drift.translation_floor
    sigma_r = drift.rotation_per_rad * angle + drift.rotation_per_m * dist + drift.rotation_floor
    E = np.tile(np.eye(4), (len(steps), 1, 1))
    if drift.up is None:
        E[:, :3, :3] = so3_exp(z[:, 3:] * sigma_r[:, None])
    else:  # about ``up``, seen from each pose's own frame
        up = np.asarray(drift.up, dtype=float) / np.linalg.norm(drift.up)
        axis = np.einsum("mji,j->mi", rotations, up)
        E[:, :3, :3] = so3_exp(axis * (z[:, 5] * sigma_r)[:, None])
    E[:, :3, 3] = z[:, :3] * sigma_t[:, None]
    return E
