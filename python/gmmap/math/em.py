"""EM fitting of 3-D Gaussian mixtures (the arithmetic runs in the Rust core)."""

from __future__ import annotations

import math
import operator
import time

from gmmap import _core
from gmmap.errors import InvalidInputError
from gmmap.math.gmm import FitInfo, Gmm
from gmmap.math.points import as_points

COVARIANCES = ("diag", "full")
INITS = ("kmeans++", "random")


def fit_gmm(
    points: object,
    n_components: int = 100,
    covariance: str = "diag",
    max_iter: int = 100,
    tol: float = 1e-3,
    seed: int = 0,
    init: str | Gmm = "kmeans++",
    *,
    reg_covar: float = 1e-6,
    truncation: float = 5.0,
) -> Gmm:
    """Fits a Gaussian mixture to (N, 3) points by expectation-maximisation.

    Args:
        points: (N, 3) coordinates; NaN or inf raises InvalidInputError.
        n_components: components requested. The result has fewer when the data cannot support
            them: fewer distinct points than components, or a component that loses all its points.
        covariance: "diag" (axis-aligned, the paper's choice) or "full".
        max_iter: EM iterations at most (0 returns the k-means++ initialisation).
        tol: stop when the mean log-likelihood per point changes by less than this (0: never).
        seed: seeds the initialisation; the same seed gives the identical fit on any thread count.
        init: "kmeans++" (greedy, as scikit-learn), "random" (distinct random points), or a
            Gmm to continue EM from (its size replaces ``n_components``; ``seed`` is unused).
        reg_covar: added to every variance after each M-step: the variance floor (squared units,
            m² for metric data), so flat or duplicate points never make a covariance singular.
        truncation: a component is not evaluated for points beyond this many standard deviations
            (Mahalanobis) from it; its responsibility there is below exp(-t²/2). ``math.inf``
            gives exact EM. The default, 5, changes the log-likelihood by well under 1e-3.

    Returns:
        The fitted Gmm; ``gmm.fit_info`` tells iterations, convergence, log-likelihood, time.
    """
    pts = as_points(points)
    _check_arguments(n_components, covariance, max_iter, tol, seed, init, reg_covar, truncation)
    start = time.perf_counter()
    full, numbers = covariance == "full", (float(reg_covar), float(truncation))
    if isinstance(init, Gmm):
        (weights, means, covs), n_iter, converged, ll = _core.refine_em(
            pts,
            init.weights,
            init.means,
            init.covariances,
            full,
            int(max_iter),
            float(tol),
            *numbers,
        )
    else:
        (weights, means, covs), n_iter, converged, ll = _core.fit_em(
            pts, int(n_components), full, int(max_iter), float(tol), int(seed), init, *numbers
        )
    info = FitInfo(int(n_iter), bool(converged), float(ll), time.perf_counter() - start)
    return Gmm(weights, means, covs, fit_info=info)


def _check_arguments(
    n_components: int,
    covariance: str,
    max_iter: int,
    tol: float,
    seed: int,
    init: str | Gmm,
    reg_covar: float,
    truncation: float,
) -> None:
    _check_int("n_components", n_components, 1)
    _check_int("max_iter", max_iter, 0)
    _check_int("seed", seed, 0)
    if covariance not in COVARIANCES:
        raise InvalidInputError(f"covariance must be one of {COVARIANCES}, got {covariance!r}")
    if not isinstance(init, Gmm) and init not in INITS:
        raise InvalidInputError(f"init must be one of {INITS} or a Gmm, got {init!r}")
    if not (math.isfinite(tol) and tol >= 0):
        raise InvalidInputError(f"tol must be finite and >= 0, got {tol}")
    if not (math.isfinite(reg_covar) and reg_covar > 0):
        raise InvalidInputError(f"reg_covar must be finite and > 0, got {reg_covar}")
    if not truncation > 0:
        raise InvalidInputError(f"truncation must be > 0, got {truncation}")


def _check_int(name: str, value: object, minimum: int) -> None:
    try:
        ok = not isinstance(value, bool) and operator.index(value) >= minimum
    except TypeError:
        ok = False
    if not ok:
        raise InvalidInputError(f"{name} must be an integer >= {minimum}, got {value!r}")
