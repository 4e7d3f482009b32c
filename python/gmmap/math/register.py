"""GMM-to-GMM registration with geometric confidence (paper V-B, after DESIGN.md).

`register` finds the rigid transform T (source → target) maximising the normalised L2
correlation C(T) = ∫ T(f) g / sqrt(∫f² ∫g²) of two mixtures, in the Rust core: analytic
gradient (the rotation of the source covariances included), Levenberg-Marquardt steps on a
Newton metric (Gauss-Newton plus the gradients' covariance term), coarse to fine by adding s²
to every covariance for each s in ``scales``. From a guess, the scales of 10 cm and more but
the last run on the mixtures merged in cells of ``coarse_cell``·s (`Gmm.coarsened`): a
fraction of the components and the same end point (benchmarks/registration.py,
``tum_fr1_xyz_guess_10_20``: the same errors to 0.01 mm in under half the time).
C at the solution, measured with ``confidence_scale`` (5 cm) added to every covariance so it
reflects the shared geometry rather than how sharply each side was fitted, is the geometric
confidence (1: the mixtures coincide; nearly independent of the component counts). Without
``init`` the search covers ``yaw_starts`` rotations about +z (robots share gravity, not
heading): for each, every pair of components votes for the translation that lays one on the
other, on a grid of ``search_cell``, and the votes' ``search_starts`` best maxima over all yaws
are optimised at the coarsest scale (`gmmap_core::search`; near ``yaw_hint``, or with
``search_cell`` 0, the yaws start with the centroids aligned instead). The best
``refine_starts`` distinct coarse solutions are refined; every distinct one comes back in
``basins``, the best first (the next one's C is the ``alternative_confidence``).

Level planes (floors, ceilings, table tops: flat components facing up or down) line up under
any yaw and horizontal shift, so over the whole mixtures a wrong alignment that lays more
floor on floor outscores the right one: two simulated office submaps 4-8 m apart along a
corridor align best shifted or turned 180°. Without ``init`` (and unless
``level_planes``), the search runs twice, on the whole mixtures and on their upright parts
(the rest), every solution is refined on the whole mixtures, and the solutions are ranked by
C on the upright parts. Both frames' +z is up (the search turns about it), so a solution
tilted more than `MAX_TILT_DEG` is not ranked while any other is found: walls alone, with no
ceiling, line up as well upside down. The best one reports its C on the whole mixtures; the
others, in ``basins`` and ``alternative_confidence``, their upright C relative to its. On the
simulated office's overlapping pairs (`benchmarks/sensors.py`, seed 0) the best solution is
right for 71 of 120 16-beam LiDAR pairs instead of 62, for 158 of 274 360° LiDAR (2 Hz) pairs
instead of 100, and for 17 of 44 depth-camera chains instead of 8; TUM fr1_xyz's
cross-session pairs stay 12 of 12. Both searches cost about 1.8 times one. Every
registration also reports its C on the upright parts (`Registration.upright_confidence`), in
which verification compares a match with its lookalikes and its half-turned twin.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gmmap import _core
from gmmap.errors import InvalidInputError
from gmmap.math.geometry import pose_distance
from gmmap.math.gmm import Gmm, _rigid
from gmmap.options import RegisterOptions

# Scales from this standard deviation (m) up are registered on coarsened mixtures from a guess
# (`RegisterOptions.coarse_cell`; at 5 cm the merge saves nothing more).
COARSE_SCALE = 0.1
# A level plane: its least variance under FLAT_RATIO of the middle one, its normal within
# LEVEL_TILT_DEG of +z. A search keeps at least MIN_UPRIGHT components.
FLAT_RATIO = 0.1
LEVEL_TILT_DEG = 25.0
MIN_UPRIGHT = 3
# Both frames' +z is up within LEVEL_TILT_DEG: a solution tilting one onto the other by more
# than twice that (walls laid on walls upside down) is not ranked.
MAX_TILT_DEG = 2 * LEVEL_TILT_DEG


@dataclass(frozen=True)
class Registration:
    """The result of `register`.

    ``information`` is the 6x6 information of a left perturbation exp(ξ)·T, ξ = (ω, v) with the
    rotation first: the Gauss-Newton curvature of −log ∫T(f)g at the solution, times
    ``RegisterOptions.information_scale``.
    """

    transform: np.ndarray
    confidence: float
    information: np.ndarray
    iterations: int
    time_s: float
    # Without ``init``: the confidence of the best solution in another basin (30° or 0.5 m
    # away), 0 if none. Close to ``confidence``: ambiguous geometry (a corridor end for end).
    alternative_confidence: float = 0.0
    # Without ``init``: every distinct solution found, (transform, confidence), best first
    # (this one leads); with ``init`` just this one.
    basins: tuple[tuple[np.ndarray, float], ...] = ()
    # C on the mixtures' upright parts (without level planes), where whether one alignment
    # beats another is told; ``confidence`` where ``level_planes`` or too few are upright.
    upright_confidence: float | None = None

    @property
    def upright(self) -> float:
        """``upright_confidence``, or ``confidence`` where it was not measured."""
        return self.confidence if self.upright_confidence is None else self.upright_confidence

    @property
    def conditioning(self) -> float:
        """The smallest eigenvalue of the translation block of ``information`` over its
        largest: near 0 where the alignment could slide along some direction unseen (a plain
        corridor's length), near 1 where every direction is pinned alike."""
        eig = np.linalg.eigvalsh(self.information[3:, 3:])
        return float(max(eig[0], 0.0) / eig[-1]) if eig[-1] > 0 else 0.0


def register(
    source: Gmm,
    target: Gmm,
    init: np.ndarray | None = None,
    *,
    yaw_hint: float | None = None,
    scales: tuple[float, ...] | None = None,
    options: RegisterOptions | None = None,
    **settings: Any,
) -> Registration:
    """Registers ``source`` onto ``target``; see the module docstring.

    Args:
        init: a 4x4 initial guess (source → target); None searches over yaw.
        yaw_hint: with ``init`` None, start near this yaw (radians, e.g. from place recognition).
        scales: standard deviations added to all covariances, coarse to fine, ending at 0
            or near it.
            Default: ``options.local_scales`` with ``init``, ``options.global_scales`` without.
        options: the ``register`` section of the configuration (`RegisterOptions`);
            ``settings`` replace single fields of it (``dof=4``, ``max_iter=20``, …).
    """
    if not isinstance(source, Gmm) or not isinstance(target, Gmm):
        raise InvalidInputError("source and target must be gmmap.Gmm mixtures")
    try:
        o = replace(options or RegisterOptions(), **settings)
    except TypeError as err:
        raise InvalidInputError(f"register: {err}") from None
    if init is not None:
        R, t = _rigid(init)
        init = np.eye(4)
        init[:3, :3], init[:3, 3] = R, t
    if scales is None:
        scales = o.local_scales if init is not None else o.global_scales
    if not scales or not all(np.isfinite(s) and s >= 0 for s in scales):
        raise InvalidInputError("scales must be finite and >= 0")
    if yaw_hint is not None and not np.isfinite(yaw_hint):
        raise InvalidInputError(f"yaw_hint must be finite, got {yaw_hint}")
    upright = None if o.level_planes else _upright_parts(source, target)
    if upright is None:
        r = _solve(source, target, init, yaw_hint, scales, o)
        return replace(r, upright_confidence=r.confidence)
    if init is not None:
        r = _solve(source, target, init, yaw_hint, scales, o)
        c = confidence(*upright, r.transform, o.confidence_scale)
        return replace(r, upright_confidence=c)
    start = time.perf_counter()
    # The whole mixtures find some places the upright parts miss (a desk seen from above: its
    # top's edges); both searches' solutions are refined on the whole mixtures.
    found = [_solve(*pair, None, yaw_hint, scales, o) for pair in ((source, target), upright)]
    starts = [T for r in found for T, _ in r.basins or ((r.transform, 0.0),)]
    results = [_solve(source, target, T, None, scales[-2:], o) for T in starts]
    return replace(
        _ranked_upright(upright, results, o),
        iterations=sum(r.iterations for r in found + results),
        time_s=time.perf_counter() - start,
    )


def _solve(
    source: Gmm,
    target: Gmm,
    init: np.ndarray | None,
    yaw_hint: float | None,
    scales: tuple[float, ...],
    o: RegisterOptions,
) -> Registration:
    """The Rust core's registration (`register` after its checks)."""
    scale = float(o.information_scale or min(len(source), len(target)))
    start = time.perf_counter()
    T, confidence, info, iterations, alternative, basins = _core.register_gmm(
        (source.weights, source.means, source.covariances),
        (target.weights, target.means, target.covariances),
        init,
        yaw_hint,
        [float(s) for s in scales],
        int(o.max_iter),
        o.dof == 4,
        int(o.yaw_starts),
        float(o.search_cell),
        int(o.search_starts),
        int(o.refine_starts),
        scale,
        float(o.confidence_scale),
        float(o.tol),
        float(o.cutoff),
        float(o.coarse_cell),
        COARSE_SCALE,
    )
    elapsed = time.perf_counter() - start
    basins = tuple((B, float(c)) for B, c in basins)
    return Registration(
        T, float(confidence), info, int(iterations), elapsed, float(alternative), basins
    )


def _upright_parts(source: Gmm, target: Gmm) -> tuple[Gmm, Gmm] | None:
    """Both mixtures `_without_level_planes`; None when either keeps too few components."""
    parts = _without_level_planes(source), _without_level_planes(target)
    return None if parts[0] is None or parts[1] is None else (parts[0], parts[1])


def _without_level_planes(gmm: Gmm) -> Gmm | None:
    """``gmm`` without its level planes (flat components whose normal is within
    `LEVEL_TILT_DEG` of +z: floor, ceiling, table tops), reweighted; None when fewer than
    `MIN_UPRIGHT` components would be left."""
    values, vectors = np.linalg.eigh(gmm.covariances)
    flat = values[:, 0] < FLAT_RATIO * values[:, 1]
    level = flat & (np.abs(vectors[:, 2, 0]) > np.cos(np.radians(LEVEL_TILT_DEG)))
    if np.count_nonzero(~level) < MIN_UPRIGHT:
        return None
    weights = gmm.weights[~level]
    return Gmm(weights / weights.sum(), gmm.means[~level], gmm.covariances[~level])


def _ranked_upright(
    upright: tuple[Gmm, Gmm], results: list[Registration], o: RegisterOptions
) -> Registration:
    """The best of ``results`` by C on the ``upright`` parts of the mixtures, with its own C on
    the whole ones; the other distinct ones (`apart`) in ``basins`` and
    ``alternative_confidence``, at their upright C relative to its. Solutions tilted more than
    `MAX_TILT_DEG` are left out while any other is found."""
    level = [r for r in results if r.transform[2, 2] >= np.cos(np.radians(MAX_TILT_DEG))]
    scored = sorted(
        ((confidence(*upright, r.transform, o.confidence_scale), r) for r in level or results),
        key=lambda cr: -cr[0],
    )
    distinct: list[tuple[float, Registration]] = []
    for c, r in scored:
        if all(apart(r.transform, d.transform) for _, d in distinct):
            distinct.append((c, r))
    top, best = distinct[0]
    scale = best.confidence / top if top > 0 else 0.0
    return replace(
        best,
        upright_confidence=top,
        alternative_confidence=distinct[1][0] * scale if len(distinct) > 1 else 0.0,
        basins=tuple((r.transform, c * scale) for c, r in distinct),
    )


def apart(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two solutions lie in different basins: 0.5 m or 30° apart, as the Rust core
    tells them (`distinct` in crates/gmmap-core/src/register.rs)."""
    t, angle = pose_distance(a, b)
    return t > 0.5 or angle > 30.0


def confidence(
    source: Gmm,
    target: Gmm,
    transform: np.ndarray | None = None,
    scale: float = RegisterOptions.confidence_scale,
) -> float:
    """The geometric confidence C of ``transform`` (source → target; identity if None): the
    normalised L2 correlation of the two mixtures, both widened by ``scale``."""
    s2 = scale * scale * np.eye(3)
    f = Gmm(source.weights, source.means, source.covariances + s2)
    g = Gmm(target.weights, target.means, target.covariances + s2)
    moved = f if transform is None else f.transform(transform)
    return float(moved.l2_correlation(g))
