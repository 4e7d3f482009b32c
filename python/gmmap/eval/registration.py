"""The paper's Table I: registration of consecutive submaps against ground truth.

Every method registers the same pairs (submap i onto submap i+1, built from the same groups of
F frames, so they share anchors and ground truth):

- ``points``: Point-to-GMM submaps (one GMM fitted to the buffered points), GMM registration;
- ``gmm-merge``: submaps concatenated from per-frame GMMs, GMM registration;
- ``per-frame``: the GMM of each group's first frame only (no submap), GMM registration;
- ``gicp``: small_gicp's GICP on the Point-to-GMM submaps' buffered points (the baseline).

Normal mode starts every method from the identity (consecutive submaps are close), or from the
odometry's relative pose (``odometry_guess``; for data whose poses are ground truth, open it
with a drift model so the guess is a realistic one). The global
mode moves each source by a random yaw (0–180°) and translation (≤ 1 m) and registers with no
initial guess (GICP gets the identity: it has no global search). The guess mode
(``guess_deg``) starts every method from the truth turned by a random angle in a range of
degrees about a random axis and moved ≤ 5 cm: a guess that far off, as a fast-turning camera's
consecutive submaps or a place recognition's rough yaw give.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from gmmap.errors import InvalidInputError
from gmmap.mapping.submap import BuildOptions, Submap, build_submaps
from gmmap.math.geometry import pose_distance
from gmmap.math.register import register

METHODS = ("points", "gmm-merge", "per-frame", "gicp")
SUCCESS_M, SUCCESS_DEG = 0.05, 2.0


# From odometry (good to about a centimetre) no widened step: widened, the floor filling 83 % of
# a fr3 cabinet keyframe overlaps most where its camera-fixed footprint does, at the identity,
# and pulled each pair 8–11 cm / 3–5° off (3.4 cm / 1.2° mean without).
ODOMETRY_SCALES = (0.0,)


@dataclass
class Pair:
    source: dict  # method -> Submap (gicp uses the points submap)
    target: dict
    truth: np.ndarray  # source anchor -> target anchor
    guess: np.ndarray  # the initial guess: identity, or the odometry's relative pose
    perturbation: np.ndarray  # applied to the source (identity in normal mode)


def pose_errors(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Translation error (m) and rotation error (degrees) of a 4x4 estimate."""
    return pose_distance(estimate, truth)


def error_summary(errors: Sequence[tuple[float, float]]) -> dict:
    """Median, max and the share within 5 cm and 1° of (translation m, rotation °) errors."""
    if not errors:
        return {"n": 0}
    t, r = np.array(errors, dtype=float).T
    return {
        "n": len(errors),
        "t_median": float(np.median(t)),
        "t_max": float(t.max()),
        "r_median_deg": float(np.median(r)),
        "r_max_deg": float(r.max()),
        "within_5cm_1deg": float(np.mean((t <= 0.05) & (r <= 1.0))),
    }


def describe_errors(summary: dict) -> str:
    """One line for an `error_summary`."""
    s = summary
    return (
        f"median {s['t_median'] * 100:.1f} cm / {s['r_median_deg']:.2f}°, max "
        f"{s['t_max'] * 100:.1f} cm / {s['r_max_deg']:.2f}°; {s['within_5cm_1deg']:.0%} within "
        "5 cm and 1°"
    )


def describe_match_errors(errors: dict) -> list[str]:
    """Lines for kept matches against the truth (``match_errors`` of a merge or demo report:
    an `error_summary` with an ``optimised`` one inside); none when nothing was kept."""
    if not errors.get("n"):
        return []
    lines = [f"{errors['n']} kept matches vs truth: {describe_errors(errors)}"]
    if errors["optimised"].get("n"):
        lines.append(f"the same, optimised: {describe_errors(errors['optimised'])}")
    return lines


def random_perturbation(rng: np.random.Generator) -> np.ndarray:
    """A yaw uniform in ±(0–180°) and a translation uniform in the 1 m ball."""
    yaw = rng.uniform(0, math.pi) * rng.choice([-1, 1])
    direction = rng.normal(size=3)
    t = direction / np.linalg.norm(direction) * rng.uniform(0, 1) ** (1 / 3)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = t
    return T


def guess_error(rng: np.random.Generator, degrees: tuple[float, float]) -> np.ndarray:
    """A rotation by an angle uniform in ``degrees`` about a uniform axis, and a translation
    uniform in the 5 cm ball."""
    axis = rng.normal(size=3)
    angle = math.radians(rng.uniform(*degrees))
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
    direction = rng.normal(size=3)
    T[:3, 3] = direction / np.linalg.norm(direction) * 0.05 * rng.uniform(0, 1) ** (1 / 3)
    return T


def build_pairs(
    frames: Sequence,
    frames_per_submap: int,
    methods: Sequence[str],
    options: BuildOptions,
    global_mode: bool,
    seed: int,
    progress: Callable[[str], None] | None = None,
    odometry_guess: bool = False,
    guess_deg: tuple[float, float] | None = None,
) -> list[Pair]:
    """Submaps for every method from the same frame groups, paired (i, i+1); the guess is the
    identity, the relative pose of the frames' odometry (``odometry_guess``) or the truth turned
    by ``guess_deg``; in the global mode the source is perturbed."""
    f = frames_per_submap
    base = replace(options.by_frames(f), min_novelty=0.0)
    submaps: dict[str, list[Submap]] = {}
    for strategy in ("points", "gmm-merge", "per-frame"):
        if strategy not in methods and not (strategy == "points" and "gicp" in methods):
            continue
        if progress:
            progress(f"building {strategy} submaps")
        if strategy == "per-frame":
            firsts = [frames[i] for i in range(0, len(frames) - f + 1, f)]
            opts = BuildOptions(**{**base.__dict__, "strategy": "per-frame"})
            submaps[strategy] = list(build_submaps(firsts, "eval", opts))
        else:
            opts = BuildOptions(**{**base.__dict__, "strategy": strategy})
            complete = [frames[i] for i in range(len(frames) // f * f)]
            submaps[strategy] = list(build_submaps(complete, "eval", opts))
    count = min(len(v) for v in submaps.values())
    rng = np.random.default_rng(seed)
    pairs = []
    for i in range(count - 1):
        src = {m: v[i] for m, v in submaps.items()}
        tgt = {m: v[i + 1] for m, v in submaps.items()}
        a, b = next(iter(src.values())), next(iter(tgt.values()))
        truth = np.linalg.inv(b.gt_anchor) @ a.gt_anchor
        guess = np.linalg.inv(b.anchor) @ a.anchor if odometry_guess else np.eye(4)
        if guess_deg is not None:
            guess = truth @ guess_error(rng, guess_deg)
        perturbation = random_perturbation(rng) if global_mode else np.eye(4)
        pairs.append(Pair(src, tgt, truth, guess, perturbation))
    return pairs


def run_method(
    method: str, pair: Pair, global_mode: bool, voxel: float, scales: tuple[float, ...] | None
) -> tuple[np.ndarray, float, float | None]:
    """One registration: the estimate (perturbed source → target), its time and its confidence
    C (None for GICP)."""
    P = pair.perturbation
    if method == "gicp":
        import small_gicp

        src = pair.source["points"].points @ P[:3, :3].T + P[:3, 3]
        start = time.perf_counter()
        guess = np.eye(4) if global_mode else pair.guess
        result = small_gicp.align(
            pair.target["points"].points,
            src,
            guess,
            registration_type="GICP",
            downsampling_resolution=voxel,
            max_correspondence_distance=5 * voxel,
            num_threads=os.cpu_count() or 1,
        )
        return result.T_target_source, time.perf_counter() - start, None
    source = pair.source[method].gmm.transform(P)
    start = time.perf_counter()
    r = register(
        source, pair.target[method].gmm, None if global_mode else pair.guess, scales=scales
    )
    return r.transform, time.perf_counter() - start, r.confidence


QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)


def summarise(
    errors: list[tuple[float, float]],
    times: list[float],
    confidences: Sequence[float | None] = (),
) -> dict:
    """Error and time figures; for GMM methods also the highest confidence C of a failed
    pair (farther than 5 cm / 2° from the truth) and the lowest of a successful one."""
    e = np.array(errors)
    ok = (e[:, 0] <= SUCCESS_M) & (e[:, 1] <= SUCCESS_DEG)
    out = {
        "t_error_mean": float(e[:, 0].mean()),
        "t_error_median": float(np.median(e[:, 0])),
        "t_rmse": float(np.sqrt((e[:, 0] ** 2).mean())),
        "r_error_mean": float(e[:, 1].mean()),
        "r_error_median": float(np.median(e[:, 1])),
        "r_rmse": float(np.sqrt((e[:, 1] ** 2).mean())),
        "success_rate": float(ok.mean()),
        "time_per_pair_s": float(np.mean(times)),
        # The distributions, for plots: errors at QUANTILES.
        "t_error_quantiles": np.quantile(e[:, 0], QUANTILES).tolist(),
        "r_error_quantiles": np.quantile(e[:, 1], QUANTILES).tolist(),
    }
    if confidences and all(c is not None for c in confidences):
        c = np.array(confidences, dtype=float)
        out["confidence_failed_max"] = float(c[~ok].max()) if (~ok).any() else None
        out["confidence_succeeded_min"] = float(c[ok].min()) if ok.any() else None
    return out


def evaluate_registration(
    frames: Sequence,
    frames_per_submap: int = 5,
    methods: Sequence[str] = METHODS,
    global_mode: bool = False,
    max_pairs: int | None = None,
    options: BuildOptions | None = None,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
    scales: tuple[float, ...] | None = None,
    odometry_guess: bool = False,
    guess_deg: tuple[float, float] | None = None,
    repeats: int = 1,
) -> dict:
    """Table I for ``frames`` (a dataset sequence with ground truth); see the module docs.
    ``scales`` overrides the registration's coarse-to-fine ladder (default: `register`'s, or
    ``ODOMETRY_SCALES`` from odometry);
    ``odometry_guess`` starts every method from the odometry's relative pose (open the data with
    a ``Drift`` to make that guess realistic) instead of the identity; ``guess_deg`` is the guess
    mode of the module docstring. ``repeats`` > 1 builds the pairs that many times, with the
    EM seed and the guesses' seed counted up from ``options.seed`` and ``seed``, and pools
    them: on a short sequence, one EM seed's fits alone move the median by millimetres."""
    if guess_deg is not None and (global_mode or odometry_guess):
        raise InvalidInputError("the guess mode excludes the global mode and the odometry guess")
    if guess_deg is not None and not 0 <= guess_deg[0] <= guess_deg[1] <= 180:
        raise InvalidInputError(f"guess degrees must be 0 <= LOW <= HIGH <= 180, got {guess_deg}")
    options = options or BuildOptions(covariance="full")
    scales = scales or (ODOMETRY_SCALES if odometry_guess else None)
    frames = frames if max_pairs is None else frames[: (max_pairs + 1) * frames_per_submap]
    if frames[0].gt_pose is None:
        raise InvalidInputError("registration evaluation needs ground-truth poses")
    if repeats < 1:
        raise InvalidInputError(f"repeats must be >= 1, got {repeats}")
    pairs = [
        pair
        for r in range(repeats)
        for pair in build_pairs(
            frames,
            frames_per_submap,
            methods,
            replace(options, seed=options.seed + r),
            global_mode,
            seed + r,
            progress,
            odometry_guess,
            guess_deg,
        )
    ]
    if not pairs:
        raise InvalidInputError(
            f"{len(frames)} frames make fewer than two submaps of {frames_per_submap}"
        )
    result: dict = {
        "pairs": len(pairs),
        "repeats": repeats,
        "frames_per_submap": frames_per_submap,
        "global": global_mode,
        "guess_deg": list(guess_deg) if guess_deg is not None else None,
        "methods": {},
    }
    for method in methods:
        if progress:
            progress(f"registering {len(pairs)} pairs with {method}")
        errors, times, confidences = [], [], []
        for pair in pairs:
            estimate, elapsed, c = run_method(method, pair, global_mode, options.voxel_size, scales)
            confidences.append(c)
            errors.append(pose_errors(estimate, pair.truth @ np.linalg.inv(pair.perturbation)))
            times.append(elapsed)
        result["methods"][method] = summarise(errors, times, confidences)
    return result
