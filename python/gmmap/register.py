"""GMM-to-GMM registration with geometric confidence (paper V-B, after DESIGN.md).

`register` finds the rigid transform T (source → target) maximising the normalised L2
correlation C(T) = ∫ T(f) g / sqrt(∫f² ∫g²) of two mixtures, in the Rust core: analytic
gradient (the rotation of the source covariances included), Levenberg-Marquardt steps on the
Gauss-Newton metric, coarse to fine by adding s² to every covariance for each s in ``scales``.
C at the solution is the geometric confidence (1: the mixtures coincide; independent of the
component counts). Without ``init`` the search starts from ``yaw_starts`` rotations about +z
(robots share gravity, not heading) with the centroids aligned, or near ``yaw_hint``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gmmap import _core
from gmmap.errors import InvalidInputError
from gmmap.gmm import Gmm, _rigid

DEFAULT_SCALES = (0.5, 0.2, 0.08, 0.0)


@dataclass(frozen=True)
class Registration:
    """The result of `register`.

    ``information`` is the 6x6 information of a left perturbation exp(ξ)·T, ξ = (ω, v) with the
    rotation first: the Gauss-Newton curvature of −log ∫T(f)g at the solution, times
    ``information_scale`` (default: the smaller component count, each component counted as one
    independent measurement).
    """

    transform: np.ndarray
    confidence: float
    information: np.ndarray
    iterations: int
    time_s: float


def register(
    source: Gmm,
    target: Gmm,
    init: np.ndarray | None = None,
    *,
    yaw_hint: float | None = None,
    dof: int = 6,
    scales: tuple[float, ...] = DEFAULT_SCALES,
    max_iter: int = 30,
    yaw_starts: int = 12,
    information_scale: float | None = None,
) -> Registration:
    """Registers ``source`` onto ``target``; see the module docstring.

    Args:
        init: a 4x4 initial guess (source → target); None searches over yaw.
        yaw_hint: with ``init`` None, start near this yaw (radians, e.g. from place recognition).
        dof: 6, or 4 for ground robots (x, y, z, yaw; roll and pitch as given by ``init``).
        scales: standard deviations added to all covariances, coarse to fine; end with 0.
    """
    if not isinstance(source, Gmm) or not isinstance(target, Gmm):
        raise InvalidInputError("source and target must be gmmap.Gmm mixtures")
    if dof not in (4, 6):
        raise InvalidInputError(f"dof must be 4 or 6, got {dof}")
    if init is not None:
        R, t = _rigid(init)
        init = np.eye(4)
        init[:3, :3], init[:3, 3] = R, t
    if yaw_hint is not None and not np.isfinite(yaw_hint):
        raise InvalidInputError(f"yaw_hint must be finite, got {yaw_hint}")
    scale = float(information_scale or min(len(source), len(target)))
    start = time.perf_counter()
    T, confidence, info, iterations = _core.register_gmm(
        (source.weights, source.means, source.covariances),
        (target.weights, target.means, target.covariances),
        init,
        yaw_hint,
        [float(s) for s in scales],
        int(max_iter),
        dof == 4,
        int(yaw_starts),
        scale,
    )
    return Registration(T, float(confidence), info, int(iterations), time.perf_counter() - start)
