"""Cross-session merging against ground truth (``gmmap eval merge``): did the maps join, how right
are their frames, how good was the verification, and what does the data allow.

Each session (a recording, or a slice of one) is one robot. The sessions are merged with the
library's pipeline (`gmmap.eval.merge.merge`, the defaults unless a configuration says
otherwise), then, from the outside:

- ``joined``: all sessions ended in one group; ``frame_t_error`` / ``frame_r_error_deg``: the
  worst robot pair's map-frame error against the truth (None when not joined);
- ``positives``: the submap pairs of two sessions whose views overlap at the truth
  (`gmmap.eval.place.positives`), and ``positives_by_robots`` per robot pair ("a|b");
- ``precision`` / ``recall`` of the verified (accepted) matches: a match is correct when its
  transform is within 0.2 m and 3° of the truth (a chain's match can be, and its edge is as
  good, where the two submaps themselves overlap too little to be a positive); recall counts
  the correct matches of positive pairs (views overlapping at the truth,
  `gmmap.eval.place.positives`) over every positive pair of the sessions, found by place
  recognition or not; ``kept_precision``: the same over the
  matches the backend kept (those that shape the merged map); ``probability_brier``: the
  mean squared gap between each probability-scored match's `Match.probability` and whether
  it is right (`gmmap.mapping.calibration`; 0 is perfect, None when none was scored);
- ``gicp``: the points + GICP verification (small_gicp, the same yaw starts) on the same
  candidates: how many it registers correctly, and its recall at 100 % precision when its
  inlier fraction is the score;
- ``floor``: GICP on the positive candidates' points started at the truth, and how far it moves
  away: what two sessions' poses and smeared submaps agree to at best;
- ``no_guess``: registration with no initial guess on the positive pairs, beside KISS-Matcher on
  their points (`gmmap.eval.noguess`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from gmmap.config import Config
from gmmap.eval.merge import merge
from gmmap.eval.noguess import no_guess
from gmmap.eval.place import is_correct, positives, pr_curve, truth, verify_gicp
from gmmap.eval.registration import error_summary, pose_errors
from gmmap.mapping.place import Match
from gmmap.mapping.submap import Submap

GICP_VOXEL = 0.2  # the points + GICP verification's, as in `gmmap eval place`


def evaluate_sessions(
    sessions: Mapping[str, Sequence[Submap]],
    config: Config | None = None,
    progress: Callable[[str], None] | None = None,
    gicp: bool = True,
) -> dict:
    """The report described in the module docstring, plus the merge's own report."""
    mapper, report = merge(sessions, config, progress)
    held, pos, index = truth_of(sessions)
    order = list(held)
    pairs = [p for p in report.get("pairs", []) if p["frame_t_error"] is not None]
    joined = len(report["groups"]) == 1
    out = {
        "sessions": {name: len(subs) for name, subs in sessions.items()},
        "joined": joined,
        "frame_t_error": max((p["frame_t_error"] for p in pairs), default=None) if joined else None,
        "frame_r_error_deg": (
            max((p["frame_r_error_deg"] for p in pairs), default=None) if joined else None
        ),
        "positives": int(pos.sum() // 2),
        "positives_by_robots": by_robots(pos, [robot for robot, _ in order]),
        "candidates": len(mapper.matches),
        **verification(mapper.matches, held, pos, index),
        "kept_precision": kept_precision(mapper, held),
        "merge": report,
    }
    if gicp:
        out["gicp"] = gicp_verification(mapper.matches, held, pos, index, out["positives"])
        voxel = (config or Config()).build.voxel_size
        out["floor"] = floor(mapper.matches, held, pos, index, voxel)
        out["no_guess"] = no_guess([held[k] for k in order], pos, mapper)
    return out


def by_robots(pos: np.ndarray, robots: Sequence[str]) -> dict[str, int]:
    """The positive pairs per robot pair, keyed "a|b" (a < b)."""
    out: dict[str, int] = {}
    for i, j in zip(*np.nonzero(np.triu(pos)), strict=True):
        key = "|".join(sorted((robots[i], robots[j])))
        out[key] = out.get(key, 0) + 1
    return out


def _pair(m: Match, held: Mapping) -> tuple[Submap, Submap]:
    return held[m.query], held[(m.candidate.robot, m.candidate.seq)]


def _positive(m: Match, pos: np.ndarray, index: Mapping) -> bool:
    return bool(pos[index[m.query], index[(m.candidate.robot, m.candidate.seq)]])


def truth_of(
    sessions: Mapping[str, Sequence[Submap]],
) -> tuple[dict[tuple[str, int], Submap], np.ndarray, dict[tuple[str, int], int]]:
    """Every submap by (robot, seq), the positive pairs among them in that order
    (`gmmap.eval.place.positives`), and each one's row there."""
    held = {(s.robot, s.seq): s for subs in sessions.values() for s in subs}
    pos = positives(list(held.values()))
    return held, pos, {k: i for i, k in enumerate(held)}


def is_right(m: Match, held: Mapping) -> bool:
    """A pair registered within `is_correct`'s tolerance of the truth."""
    return is_correct(m.registration.transform, *_pair(m, held))


def verification(matches: Sequence[Match], held: Mapping, pos: np.ndarray, index: Mapping) -> dict:
    """Precision and recall of the accepted matches, and how many candidates registered right."""
    right = [is_right(m, held) for m in matches]
    accepted = [m.accepted for m in matches]
    n_positive = int(pos.sum() // 2)
    correct_accepted = sum(r and a for r, a in zip(right, accepted, strict=True))
    recalled = sum(
        r and a and _positive(m, pos, index)
        for m, r, a in zip(matches, right, accepted, strict=True)
    )
    scored = [
        (m.probability, r) for m, r in zip(matches, right, strict=True) if m.probability is not None
    ]
    return {
        "verified": sum(accepted),
        "precision": correct_accepted / sum(accepted) if any(accepted) else None,
        "recall": recalled / n_positive if n_positive else None,
        "candidates_registered_right": sum(right),
        "probability_brier": float(np.mean([(p - r) ** 2 for p, r in scored])) if scored else None,
    }


def kept_precision(mapper, held: Mapping) -> float | None:
    """The share of the backend's kept matches that are correct (None when it kept none)."""
    kept = [mapper.edge_matches[e] for e in (mapper.result.accepted if mapper.result else [])]
    right = [is_right(m, held) for m in kept]
    return sum(right) / len(right) if right else None


def gicp_verification(
    matches: Sequence[Match], held: Mapping, pos: np.ndarray, index: Mapping, n_positive: int
) -> dict:
    """Points + GICP on the same candidates, scored by the inlier fraction."""
    scores, right = [], []
    for m in matches:
        source, target = _pair(m, held)
        score, T = verify_gicp(source, target, GICP_VOXEL)
        scores.append(score)
        right.append(_positive(m, pos, index) and is_correct(T, source, target))
    curve = pr_curve(np.array(scores), np.array(right), max(1, n_positive)) if matches else None
    return {
        "candidates_registered_right": sum(right),
        "recall_at_full_precision": curve["recall_at_full_precision"] if curve else None,
    }


def floor(
    matches: Sequence[Match], held: Mapping, pos: np.ndarray, index: Mapping, voxel: float
) -> dict:
    """GICP on the points (at the submaps' ``voxel``) started at the truth on each positive
    candidate: how far it moves (m, °)."""
    import small_gicp

    moved = []
    for m in (m for m in matches if _positive(m, pos, index)):
        source, target = _pair(m, held)
        tgt, tree = small_gicp.preprocess_points(target.points.astype(float), voxel, 10, 1)
        src, _ = small_gicp.preprocess_points(source.points.astype(float), voxel, 10, 1)
        T = truth(source, target)
        result = small_gicp.align(
            tgt, src, tree, T, registration_type="GICP",
            max_correspondence_distance=2 * voxel, num_threads=1,
        )  # fmt: skip
        moved.append(pose_errors(result.T_target_source, T))
    return error_summary(moved)
