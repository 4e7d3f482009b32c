"""No-guess registration where two robots' submaps overlap, beside a global registration on
their points (KISS-Matcher), on the same pairs.

Place recognition hands registration pairs with no initial guess; this measures that step alone,
on every pair whose views overlap at the truth (`gmmap.eval.place.positives`), found by place
recognition or not. Per method: how many pairs it registers within 0.2 m and 3° of the truth
(`gmmap.eval.place.is_correct`), and its mean time per pair:

- ``gmmap``: `PlaceDatabase.register_pair` on the two mixtures: the registration alone;
- ``gmmap_free_space``: `Mapper.register_pair`, what `Mapper` verifies with: the same on
  the chains it registers a narrow view as (`PlaceOptions.chain`), less the solutions that put
  surfaces where either robot saw free space (the chains' horizons);
- ``from_truth``: the same registration started at the truth, the objective's ceiling: a pair
  it gets wrong is one where the right alignment is no basin of the correlation C (a depth
  camera's view of a wall slides along it), which no search without a guess can find;
- ``kiss_matcher``: KISS-Matcher (FPFH correspondences, graduated non-convexity) on the two
  submaps' points at ``voxel``, refined by small_gicp's GICP, as its authors' pipeline does.
  Skipped, with the reason, where the `kiss-matcher` wheel is not installed (none for Python
  3.13 yet).

Pairs are taken evenly over the list when there are more than ``limit`` (KISS-Matcher takes
0.1-0.5 s per pair on two cores).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from gmmap.eval.place import is_correct, truth
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.place import PlaceDatabase
from gmmap.mapping.submap import Submap
from gmmap.math.register import register

VOXEL = 0.1  # KISS-Matcher's voxel: of 0.1, 0.3 and 0.5 m the best rate on the simulated office


def no_guess(submaps: Sequence[Submap], pos: np.ndarray, mapper: Mapper, limit: int = 60) -> dict:
    """The report described in the module docstring, over the positive pairs ``pos`` (n, n)
    of ``submaps``, all held by ``mapper``."""
    pairs = list(zip(*np.nonzero(np.triu(pos)), strict=True))
    if len(pairs) > limit:
        pairs = [pairs[i] for i in np.linspace(0, len(pairs) - 1, limit).round().astype(int)]
    pairs = [(submaps[i], submaps[j]) for i, j in pairs]
    db = mapper.db
    out = {"pairs": len(pairs), "gmmap": _rate(pairs, lambda s, t: _gmmap(s, t, db))}
    out["gmmap_free_space"] = _rate(
        pairs, lambda s, t: mapper.register_pair(s, (t.robot, t.seq)).transform
    )
    out["from_truth"] = _rate(pairs, lambda s, t: _from_truth(s, t, db))
    try:
        import kiss_matcher  # noqa: F401
    except ImportError as e:
        out["kiss_matcher"] = {"skipped": f"kiss-matcher is not installed ({e})"}
    else:
        out["kiss_matcher"] = _rate(pairs, _kiss_matcher)
    return out


def _rate(pairs: Sequence[tuple[Submap, Submap]], method) -> dict:
    right, seconds = 0, 0.0
    for source, target in pairs:
        start = time.perf_counter()
        T = method(source, target)
        seconds += time.perf_counter() - start
        right += is_correct(T, source, target)
    n = max(1, len(pairs))
    return {"right": right, "rate": right / n if pairs else None, "time_s": seconds / n}


def _gmmap(source: Submap, target: Submap, db: PlaceDatabase) -> np.ndarray:
    return db.register_pair(source.gmm, target.gmm).transform


def _from_truth(source: Submap, target: Submap, db: PlaceDatabase) -> np.ndarray:
    guess = truth(source, target)
    return register(source.gmm, target.gmm, guess, options=db.registration).transform


def _kiss_matcher(source: Submap, target: Submap) -> np.ndarray:
    import kiss_matcher
    import small_gicp

    src = source.points.astype(np.float32)
    tgt = target.points.astype(np.float32)
    solution = kiss_matcher.KISSMatcher(kiss_matcher.KISSMatcherConfig(VOXEL)).estimate(src, tgt)
    T = np.eye(4)
    T[:3, :3] = solution.rotation
    T[:3, 3] = solution.translation
    result = small_gicp.align(
        tgt.astype(float), src.astype(float), T, registration_type="GICP",
        downsampling_resolution=VOXEL, max_correspondence_distance=2 * VOXEL, num_threads=1,
    )  # fmt: skip
    return result.T_target_source
