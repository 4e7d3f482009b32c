"""The offline multi-robot pipeline: submap folders in, relative frames and a global map out.

What each robot's node does online, run once over whole folders (e.g. from ``gmmap build``):
place recognition between the robots' submaps (descriptors computed here, from the GMMs
only), verification by registration, the robust pose graph, the TF graph, and a global map
per connected group. Where the submaps carry ground truth, the recovered frames and the
optimised trajectories are compared with it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.eval.pairs import match_errors, pair_errors
from gmmap.mapping.backend import BackendOptions, BackendResult, PoseGraph
from gmmap.mapping.globalmap import GlobalMap, build_global_map
from gmmap.mapping.place import Match, PlaceDatabase, PlaceOptions
from gmmap.mapping.submap import Submap
from gmmap.mapping.tfgraph import TfGraph
from gmmap.math.geometry import invert
from gmmap.math.select import SelectOptions

Progress = Callable[[str], None]


@dataclass
class MergeOptions:
    """``wrong_matches``: a robustness test: this fraction of the verified matches has its
    transform replaced by a wrong one (a random yaw of 30-180° and 1-5 m, seeded by ``seed``),
    with its confidence and information kept, before the backend sees them."""

    place: PlaceOptions = field(default_factory=PlaceOptions)
    backend: BackendOptions = field(default_factory=BackendOptions)
    selection: SelectOptions = field(default_factory=SelectOptions)
    wrong_matches: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 <= self.wrong_matches <= 1.0:
            raise InvalidInputError(f"wrong_matches must be in [0, 1], got {self.wrong_matches}")


@dataclass
class MergeResult:
    matches: list[Match]  # every verified candidate, accepted by C_thr or not
    backend: BackendResult
    tf: TfGraph
    maps: dict[str, GlobalMap]  # by reference robot
    edge_ids: dict[int, Match]  # backend edge id → the match it came from
    time_s: float
    injected: list[int] = field(default_factory=list)  # edge ids of injected wrong matches

    def report(self, submaps: Mapping[str, Sequence[Submap]]) -> dict:
        """The JSON report: frames, groups, edges and, with ground truth, the errors."""
        b = self.backend
        reference = min(self.tf.groups()[0]) if self.tf.groups() else min(submaps)
        report: dict = {
            "reference": reference,
            "robots": [
                {
                    "name": r,
                    "reference": b.reference[r],
                    "to_reference": b.to_reference[r].tolist(),
                    "submaps": len(submaps[r]),
                }
                for r in sorted(submaps)
            ],
            "groups": b.groups,
            "candidates": len(self.matches),
            "verified": sum(m.accepted for m in self.matches),
            "accepted_edges": len(b.accepted),
            "rejected_edges": len(b.rejected),
            "rejected_by": {
                why: list(b.rejected.values()).count(why) for why in {*b.rejected.values()}
            },
            "backend_time_s": b.time_s,
            "time_s": self.time_s,
        }
        if self.injected:
            report["injected_wrong"] = {
                "n": len(self.injected),
                "rejected": sum(i in b.rejected for i in self.injected),
            }
        if all(s.gt_anchor is not None for subs in submaps.values() for s in subs):
            report.update(truth_errors(submaps, b))
            report["match_errors"] = self.match_errors(submaps)
        return report

    def match_errors(self, submaps: Mapping[str, Sequence[Submap]]) -> dict:
        """Each match the backend kept against the anchors' ground truth, as registered and as
        optimised (`gmmap.eval.pairs.match_errors`)."""
        truth = {(s.robot, s.seq): s.gt_anchor for subs in submaps.values() for s in subs}
        kept = [self.edge_ids[e] for e in self.backend.accepted]
        registered = [
            ((m.candidate.robot, m.candidate.seq), m.query, m.registration.transform) for m in kept
        ]
        nodes = [(t, s) for t, s, _ in registered]
        return match_errors(registered, nodes, self.backend.poses, truth)


def merge(
    submaps: Mapping[str, Sequence[Submap]],
    options: MergeOptions | None = None,
    progress: Progress | None = None,
) -> MergeResult:
    """Runs the pipeline over ``submaps`` (robot name → its submaps)."""
    options = options or MergeOptions()
    say = progress or (lambda _m: None)
    if len(submaps) < 1 or any(len(s) == 0 for s in submaps.values()):
        raise InvalidInputError("merge needs at least one robot, each with submaps")
    start = time.perf_counter()
    say(f"describing {sum(map(len, submaps.values()))} submaps")
    db = PlaceDatabase(options=options.place)
    for subs in submaps.values():
        for s in subs:
            db.add(s.robot, s.seq, s.gmm)
    matches = find_matches(db, submaps, say)
    wrong = inject_wrong(matches, options.wrong_matches, options.seed)
    graph = PoseGraph(options.backend)
    for subs in submaps.values():
        for s in sorted(subs, key=lambda s: s.seq):
            graph.add_submap(s.robot, s.seq, s.anchor)
    edge_ids, injected = {}, []
    for i, m in enumerate(matches):
        if m.accepted:
            target = (m.candidate.robot, m.candidate.seq)
            r = m.registration
            edge = graph.add_match(target, m.query, r.transform, r.information, r.confidence)
            edge_ids[edge] = m
            if i in wrong:
                injected.append(edge)
    say(f"optimising the pose graph ({len(edge_ids)} inter-robot matches)")
    result = graph.optimize()
    tf = TfGraph.from_result(result)
    everything = [s for subs in submaps.values() for s in subs]
    maps = {}
    for group in result.groups:
        ref = result.reference[group[0]]
        say(f"merging the global map of {', '.join(group)}")
        poses = {k: v for k, v in result.poses.items() if k[0] in group}
        maps[ref] = build_global_map(everything, poses, ref, options.selection)
    elapsed = time.perf_counter() - start
    return MergeResult(matches, result, tf, maps, edge_ids, elapsed, injected)


def inject_wrong(matches: list[Match], fraction: float, seed: int) -> set[int]:
    """Replaces the transform of ``fraction`` of the accepted matches (in place) by a wrong
    one; returns their indices."""
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


def find_matches(
    db: PlaceDatabase, submaps: Mapping[str, Sequence[Submap]], say: Progress
) -> list[Match]:
    """Each submap queries the other robots' submaps; every candidate pair is verified once."""
    seen: set[frozenset] = set()
    matches = []
    queries = [s for subs in submaps.values() for s in subs]
    for i, s in enumerate(queries):
        for c in db.query(s.robot, s.seq, s.gmm, others_only=True):
            pair = frozenset({(s.robot, s.seq), (c.robot, c.seq)})
            if pair in seen:
                continue
            seen.add(pair)
            matches.append(db.verify(s.robot, s.seq, s.gmm, c))
        if (i + 1) % 10 == 0 or i + 1 == len(queries):
            accepted = sum(m.accepted for m in matches)
            say(f"place recognition: {i + 1}/{len(queries)} submaps, {accepted} matches verified")
    return matches


def map_to_world(subs: Sequence[Submap]) -> np.ndarray:
    """A robot's true map frame → world, from its first submap (odometry starts exact)."""
    first = min(subs, key=lambda s: s.seq)
    return first.gt_anchor @ invert(first.anchor)


def truth_errors(submaps: Mapping[str, Sequence[Submap]], b: BackendResult) -> dict:
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
            true.append(invert(frames[b.reference[r]]) @ s.gt_anchor)
    before, after, true = np.array(before), np.array(after), np.array(true)
    return {
        "pairs": pair_errors(b.groups, submaps, b.poses, truth, kept, b.to_reference, frames),
        "ate_before_m": ate(before, true),
        "ate_after_m": ate(after, true),
        "ate_aligned_before_m": ate(before, true, align=True),
        "ate_aligned_after_m": ate(after, true, align=True),
    }


def ate(estimate: np.ndarray, truth: np.ndarray, align: bool = False) -> float:
    """RMSE of anchor positions (evo's APE, translation part). Both are in the reference frame;
    ``align`` first fits the estimate to the truth by one rigid motion (evo's ``--align``), which
    takes out where the reference robot's own drift put the whole map."""
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D

    reference, moved = PosePath3D(poses_se3=list(truth)), PosePath3D(poses_se3=list(estimate))
    if align:
        moved.align(reference)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((reference, moved))
    return float(ape.get_statistic(metrics.StatisticsType.rmse))
