"""A merge against ground truth, from the outside: the `Mapper` never sees it.

`merge` runs the offline pipeline over submap folders (``gmmap merge``, benchmarks/merge.py)
and, where the submaps carry their anchors' ground truth, `truth_report` adds every robot
pair's relative pose errors (`gmmap.eval.pairs`), the kept matches as registered and optimised,
and the ATE of the anchors. `inject_wrong` is the robustness test: it replaces a fraction of
the verified matches by wrong ones before the backend sees them.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.pairs import match_errors, pair_errors
from gmmap.mapping.backend import BackendResult
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.place import Match
from gmmap.mapping.submap import Submap
from gmmap.math.geometry import invert

Submaps = Mapping[str, Sequence[Submap]]


def merge(
    submaps: Submaps,
    config: Config | None = None,
    progress: Callable[[str], None] | None = None,
    wrong_matches: float = 0.0,
    seed: int = 0,
) -> tuple[Mapper, dict]:
    """The pipeline over ``submaps`` (robot → its submaps), ``wrong_matches`` of the verified
    matches replaced by wrong ones (seeded); returns the optimised mapper and its report, with
    the errors against ground truth where every submap has it."""
    if not 0.0 <= wrong_matches <= 1.0:
        raise InvalidInputError(f"wrong_matches must be in [0, 1], got {wrong_matches}")
    if not submaps or any(len(s) == 0 for s in submaps.values()):
        raise InvalidInputError("merge needs at least one robot, each with submaps")
    say = progress or (lambda _m: None)
    start = time.perf_counter()
    mapper = Mapper(config)
    everything = [s for subs in submaps.values() for s in subs]
    say(f"describing {len(everything)} submaps")
    matches = mapper.verify(mapper.hold(everything), say)
    wrong = inject_wrong(matches, wrong_matches, seed)
    edges = {i: mapper.add_match(m) for i, m in enumerate(matches)}
    say(f"optimising the pose graph ({len(mapper.edge_matches)} inter-robot matches)")
    mapper.optimize()
    report = {**mapper.report(), "time_s": time.perf_counter() - start}
    if wrong:
        injected = [edges[i] for i in wrong]
        rejected = mapper.result.rejected if mapper.result else {}
        report["injected_wrong"] = {
            "n": len(injected),
            "rejected": sum(e in rejected for e in injected),
        }
    report.update(truth_report(mapper, submaps))
    return mapper, report


def inject_wrong(matches: list[Match], fraction: float, seed: int) -> set[int]:
    """Replaces the transform of ``fraction`` of the accepted matches (in place) by a wrong
    one (a random yaw of 30-180° and 1-5 m), confidence and information kept; returns their
    indices."""
    accepted = [i for i, m in enumerate(matches) if m.accepted]
    n = round(fraction * len(accepted))
    if n == 0:
        return set()
    rng = np.random.default_rng(seed)
    chosen = rng.choice(accepted, size=n, replace=False)
    for i in chosen:
        yaw = rng.uniform(np.pi / 6, np.pi) * rng.choice([-1, 1])
        direction = rng.normal(size=2)
        offset = np.eye(4)
        offset[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
        offset[:2, 3] = rng.uniform(1, 5) * direction / np.linalg.norm(direction)
        r = matches[i].registration
        matches[i] = replace(matches[i], registration=replace(r, transform=offset @ r.transform))
    return {int(i) for i in chosen}


def truth_report(mapper: Mapper, submaps: Submaps) -> dict:
    """The errors against ground truth, or nothing when a submap lacks it."""
    if mapper.result is None or any(s.gt_anchor is None for subs in submaps.values() for s in subs):
        return {}
    report = truth_errors(submaps, mapper.result)
    truth = {(s.robot, s.seq): s.gt_anchor for subs in submaps.values() for s in subs}
    kept = [mapper.edge_matches[e] for e in mapper.result.accepted]
    registered = [
        ((m.candidate.robot, m.candidate.seq), m.query, m.registration.transform) for m in kept
    ]
    nodes = [(t, s) for t, s, _ in registered]
    report["match_errors"] = match_errors(registered, nodes, mapper.result.poses, truth)
    return report


def map_to_world(subs: Sequence[Submap]) -> np.ndarray:
    """A robot's true map frame → world, from its first submap (odometry starts exact)."""
    first = min(subs, key=lambda s: s.seq)
    return first.gt_anchor @ invert(first.anchor)


def truth_in_reference(subs: Sequence[Submap], reference: Sequence[Submap]) -> np.ndarray:
    """The true anchors of ``subs`` in the true map frame of the robot whose submaps are
    ``reference``: the frame its optimised poses are in."""
    to_reference = invert(map_to_world(reference))
    return np.array([to_reference @ s.gt_anchor for s in subs])


def truth_errors(submaps: Submaps, b: BackendResult) -> dict:
    """Every robot pair's relative pose errors (`gmmap.eval.pairs`: where they met, and their
    map frames), and the ATE (evo) of the anchors in the reference frame, as they are and
    rigidly aligned, before (odometry placed by the recovered frames) and after optimisation."""
    frames = {r: map_to_world(subs) for r, subs in submaps.items()}
    truth = {(r, s.seq): s.gt_anchor for r, subs in submaps.items() for s in subs}
    kept = [b.edges[e] for e in b.accepted]
    before, after, true = [], [], []
    for r, subs in sorted(submaps.items()):
        for s in subs:
            before.append(b.to_reference[r] @ s.anchor)
            after.append(b.poses[(r, s.seq)])
        true.extend(truth_in_reference(subs, submaps[b.reference[r]]))
    before, after, true = np.array(before), np.array(after), np.array(true)
    return {
        "pairs": pair_errors(b.groups, submaps, b.poses, truth, kept, b.to_reference, frames),
        "ate_before_m": ate(before, true),
        "ate_after_m": ate(after, true),
        "ate_aligned_before_m": ate(before, true, align=True),
        "ate_aligned_after_m": ate(after, true, align=True),
    }


def ate(estimate: np.ndarray, truth: np.ndarray, align: bool = False) -> float | None:
    """RMSE of anchor positions (evo's APE, translation part). Both are in the reference frame;
    ``align`` first fits the estimate to the truth by one rigid motion (evo's ``--align``), which
    takes out where the reference robot's own drift put the whole map; None when the anchors
    are too few or too nearly in line for that fit (a short recording's few submaps)."""
    from evo.core import metrics
    from evo.core.geometry import GeometryException
    from evo.core.trajectory import PosePath3D

    reference, moved = PosePath3D(poses_se3=list(truth)), PosePath3D(poses_se3=list(estimate))
    if align:
        try:
            moved.align(reference)
        except GeometryException:
            return None
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((reference, moved))
    return float(ape.get_statistic(metrics.StatisticsType.rmse))
