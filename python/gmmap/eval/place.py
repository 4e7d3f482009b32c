"""Place recognition against ground truth (paper Fig. 7 and 8).

Submaps come from several robots (the simulator's, or one recording split into a first and a
second half). A pair of submaps from different robots is a *positive* when their ground-truth
centres lie within ``max_centre_distance`` and they share at least ``min_overlap`` of the
smaller one's occupied world voxels (overlapping views, not just nearby positions).
Every submap with a positive is a query against the other robots' submaps:

- recall@N (N = 1…25) and recall@top-1 % (N = 1 % of the database, at least 1), the
  PointNetVLAD protocol, for the descriptor on resampled GMMs (``gmm``) and the same descriptor
  on the raw buffered points (``points``);
- precision–recall of the top candidate by descriptor distance, and after verification: the
  top-k candidates registered with no initial guess, the most confident kept, swept over C_thr.
  A verified match counts as correct only when the place is a positive *and* the estimated pose
  is within 0.2 m and 3° of the truth. The point-cloud counterpart verifies its candidates with
  small_gicp's GICP from the same yaw starts, scored by the inlier fraction.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.eval.registration import pose_errors
from gmmap.mapping.place import PlaceDatabase, PlaceOptions, descriptor_for
from gmmap.mapping.submap import BuildOptions, Submap, build_submaps
from gmmap.math.geometry import invert
from gmmap.options import SimOptions

CORRECT_M, CORRECT_DEG = 0.2, 3.0
RECALL_N = 25
Progress = Callable[[str], None]


@dataclass
class PlaceSet:
    submaps: list[Submap]
    positives: np.ndarray  # (n, n) bool, cross-robot pairs only

    @property
    def queries(self) -> np.ndarray:
        return np.flatnonzero(self.positives.any(axis=1))


def world_points(s: Submap) -> np.ndarray:
    return s.points @ s.gt_anchor[:3, :3].T + s.gt_anchor[:3, 3]


def positives(
    submaps: Sequence[Submap],
    voxel: float = 0.25,
    min_overlap: float = 0.3,
    max_centre_distance: float = 5.0,
) -> np.ndarray:
    """Cross-robot pairs whose views overlap (see the module docs)."""
    if any(s.gt_anchor is None or s.points is None for s in submaps):
        raise InvalidInputError("place evaluation needs ground-truth poses and the submaps' points")
    clouds = [world_points(s) for s in submaps]
    voxels = [set(map(tuple, np.floor(c / voxel).astype(np.int64))) for c in clouds]
    centres = np.array([c.mean(axis=0) for c in clouds])
    robots = np.array([s.robot for s in submaps])
    n = len(submaps)
    result = np.zeros((n, n), dtype=bool)
    for i in range(n):
        for j in range(i + 1, n):
            if robots[i] == robots[j]:
                continue
            near = np.linalg.norm(centres[i] - centres[j]) <= max_centre_distance
            shared = len(voxels[i] & voxels[j]) / max(1, min(len(voxels[i]), len(voxels[j])))
            result[i, j] = result[j, i] = near and shared >= min_overlap
    return result


def similarity(vectors: np.ndarray, robots: np.ndarray) -> np.ndarray:
    """Cosine similarity between submaps of different robots (−inf within a robot)."""
    unit = vectors / np.maximum(np.linalg.norm(vectors, axis=1, keepdims=True), 1e-300)
    s = unit @ unit.T
    s[robots[:, None] == robots[None, :]] = -np.inf
    return s


def recall_curve(sim: np.ndarray, pos: np.ndarray, queries: np.ndarray) -> list[float]:
    order = np.argsort(-sim[queries], axis=1, kind="stable")
    hits = np.take_along_axis(pos[queries], order, axis=1)
    first = np.where(hits.any(axis=1), hits.argmax(axis=1), np.iinfo(np.int64).max)
    return [float((first < n).mean()) for n in range(1, RECALL_N + 1)]


def pr_curve(scores: np.ndarray, correct: np.ndarray, n_queries: int) -> dict:
    """Precision and recall as the acceptance threshold falls through ``scores`` (one per
    query: its best candidate's score), and the recall reached at 100 % precision."""
    order = np.argsort(-scores, kind="stable")
    tp = np.cumsum(correct[order])
    accepted = np.arange(1, len(order) + 1)
    precision = tp / accepted
    recall = tp / max(1, n_queries)
    perfect = precision >= 1.0 - 1e-12
    at_full = float(recall[perfect].max()) if perfect.any() and perfect[0] else 0.0
    return {
        "thresholds": scores[order].tolist(),
        "precision": precision.tolist(),
        "recall": recall.tolist(),
        "recall_at_full_precision": at_full,
    }


def truth(source: Submap, target: Submap) -> np.ndarray:
    """Ground-truth transform of the source anchor frame into the target's."""
    return invert(target.gt_anchor) @ source.gt_anchor


def is_correct(estimate: np.ndarray, source: Submap, target: Submap) -> bool:
    t, r = pose_errors(estimate, truth(source, target))
    return t <= CORRECT_M and r <= CORRECT_DEG


def verify_gmm(source: Submap, target: Submap, db: PlaceDatabase) -> tuple[float, np.ndarray]:
    r = db.register_pair(source.gmm, target.gmm)
    return db.score(r), r.transform


def verify_gicp(source: Submap, target: Submap, voxel: float, yaw_starts: int = 12):
    """GICP from ``yaw_starts`` yaws about +z with the centroids aligned (points have no
    translation votes); the best inlier fraction is the confidence."""
    import small_gicp

    threads = os.cpu_count() or 1
    tgt, tree = small_gicp.preprocess_points(target.points.astype(float), voxel, 10, threads)
    src, _ = small_gicp.preprocess_points(source.points.astype(float), voxel, 10, threads)
    ms, mt = source.points.mean(axis=0), target.points.mean(axis=0)
    best = (-1.0, np.eye(4))
    for k in range(yaw_starts):
        yaw = 2 * math.pi * k / yaw_starts
        T = np.eye(4)
        T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        T[:3, 3] = mt - T[:3, :3] @ ms
        result = small_gicp.align(
            tgt, src, tree, T, registration_type="GICP",
            max_correspondence_distance=2 * voxel, num_threads=threads,
        )  # fmt: skip
        score = result.num_inliers / max(1, src.size())
        if score > best[0]:
            best = (score, result.T_target_source)
    return best


def verified_curve(
    submaps: Sequence[Submap],
    sim: np.ndarray,
    pos: np.ndarray,
    queries: np.ndarray,
    top_k: int,
    verify: Callable[[Submap, Submap], tuple[float, np.ndarray]],
) -> dict:
    """Verifies each query's ``top_k`` candidates and keeps the most confident."""
    scores, correct = [], []
    for q in queries:
        best = (-1.0, False)
        for c in np.argsort(-sim[q], kind="stable")[:top_k]:
            score, T = verify(submaps[q], submaps[c])
            if score > best[0]:
                best = (score, bool(pos[q, c]) and is_correct(T, submaps[q], submaps[c]))
        scores.append(best[0])
        correct.append(best[1])
    return pr_curve(np.array(scores), np.array(correct), len(queries))


def query_times(vectors: np.ndarray, sizes: Sequence[int] = (1000, 10000), seed: int = 0) -> dict:
    """Seconds per query against databases of ``sizes`` submaps (real descriptors, repeated
    with noise), the search only: describing a received submap happens once, on arrival."""
    rng = np.random.default_rng(seed)
    out = {}
    for n in sizes:
        db = PlaceDatabase()
        rows = np.abs(vectors[rng.integers(len(vectors), size=n)] + rng.normal(0, 0.01, (n, 1)))
        for i, row in enumerate(rows):
            db.add("r", i, None, row)
        db.search(vectors[0])  # builds the matrix once, as a live database keeps it
        start = time.perf_counter()
        for _ in range(20):
            db.search(vectors[0])
        out[str(n)] = (time.perf_counter() - start) / 20
    return out


def evaluate_place(
    place_set: PlaceSet,
    options: PlaceOptions | None = None,
    gicp_voxel: float = 0.2,
    progress: Progress | None = None,
    gicp: bool = True,
) -> dict:
    """Recall, precision–recall and query times for ``place_set`` (see the module docs)."""
    options = options or PlaceOptions()
    submaps, pos = place_set.submaps, place_set.positives
    queries = place_set.queries
    if len(queries) == 0:
        raise InvalidInputError("no submap overlaps another robot's: nothing to recognise")
    robots = np.array([s.robot for s in submaps])
    db = PlaceDatabase(descriptor_for(options), options)
    say = progress or (lambda _m: None)
    say(f"describing {len(submaps)} submaps")
    start = time.perf_counter()
    gmm_vectors = np.array([db.describe(s.gmm) for s in submaps])
    describe_s = (time.perf_counter() - start) / len(submaps)
    point_vectors = np.array([db.descriptor.describe_points(s.points) for s in submaps])
    sims = {"gmm": similarity(gmm_vectors, robots), "points": similarity(point_vectors, robots)}
    db_size = min(int((robots != robots[q]).sum()) for q in queries)
    top1pct = max(1, round(db_size / 100))
    result: dict = {
        "descriptor": options.descriptor,
        "queries": len(queries),
        "submaps": len(submaps),
        "robots": len(set(robots)),
    }
    for name, sim in sims.items():
        curve = recall_curve(sim, pos, queries)
        top1 = sim[queries].max(axis=1)
        first = sim[queries].argmax(axis=1)
        result[name] = {
            "recall_at_1pct": curve[top1pct - 1],
            "recall_at_n": curve,
            "pr": pr_curve(top1, pos[queries, first], len(queries)),
        }
    say(f"verifying the top {options.top_k} candidates of {len(queries)} queries by registration")
    verified = verified_curve(
        submaps, sims["gmm"], pos, queries, options.top_k, lambda a, b: verify_gmm(a, b, db)
    )
    result["verified"] = {
        "gmm_recall_at_full_precision": verified["recall_at_full_precision"],
        "gmm_pr": verified,
    }
    if gicp:
        say("verifying the point-cloud candidates with GICP")
        v = verified_curve(
            submaps, sims["points"], pos, queries, options.top_k,
            lambda a, b: verify_gicp(a, b, gicp_voxel),
        )  # fmt: skip
        result["verified"]["points_gicp_recall_at_full_precision"] = v["recall_at_full_precision"]
        result["verified"]["points_gicp_pr"] = v
    result["describe_time_s"] = describe_s
    result["query_time_s"] = query_times(gmm_vectors)
    return result


def sim_place_set(
    world: str = "office",
    robots: int = 3,
    seed: int = 0,
    frames_per_submap: int = 20,
    progress: Progress | None = None,
    sensor: str = "lidar",
    covariance: str = "full",
    sim: SimOptions | None = None,
) -> PlaceSet:
    """Simulated robots with drifting odometry, their submaps and the positives; ``sensor``
    "lidar" (the default 360° LiDAR) or "depth" (the default depth camera). ``sim``: the
    LiDAR's beams and field, the rate, speed and sway (its world, robots, seed and sensor are
    the arguments'; the depth camera is always the harness's 640 px one)."""
    from gmmap.io.sim import UP, Motion, get_world, sim_sensor, simulate
    from gmmap.math.drift import Drift

    o = replace(sim or SimOptions(), sensor=sensor, width=640)  # the harness's 640 px camera
    motion = Motion(speed=o.speed, rate=o.rate, sway=o.sway)
    run = simulate(get_world(world), robots, seed, sim_sensor(o), motion, Drift(seed=seed, up=UP))
    submaps = []
    for r in run:
        if progress:
            progress(f"building {r.name}'s submaps ({len(r)} frames)")
        options = BuildOptions(seed=seed, covariance=covariance).by_frames(frames_per_submap)
        submaps += build_submaps(r, r.name, options)
    return PlaceSet(submaps, positives(submaps))


def split_place_set(
    frames: Sequence,
    frames_per_submap: int = 20,
    progress: Progress | None = None,
    covariance: str = "full",
) -> PlaceSet:
    """One recording as two robots: its first and second half."""
    half = len(frames) // 2
    options = BuildOptions(covariance=covariance).by_frames(frames_per_submap)
    submaps = []
    for name, part in (("first", frames[:half]), ("second", frames[half:])):
        if progress:
            progress(f"building the {name} half's submaps ({len(part)} frames)")
        submaps += build_submaps(part, name, options)
    return PlaceSet(submaps, positives(submaps))


def plot(result: dict, folder: str | os.PathLike) -> list[str]:
    """recall@N and precision–recall PNGs of an `evaluate_place` result."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    os.makedirs(folder, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5, 4))
    n = np.arange(1, RECALL_N + 1)
    for name in ("gmm", "points"):
        ax.plot(n, result[name]["recall_at_n"], marker=".", label=name)
    ax.set(xlabel="N", ylabel="recall@N", ylim=(0, 1.02), title="Place recognition")
    ax.legend()
    recall_png = os.path.join(folder, "place_recall.png")
    fig.savefig(recall_png, dpi=120, bbox_inches="tight")
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5, 4))
    curves = {
        "gmm descriptor": result["gmm"]["pr"],
        "points descriptor": result["points"]["pr"],
        "gmm + registration": result["verified"]["gmm_pr"],
    }
    if "points_gicp_pr" in result["verified"]:
        curves["points + GICP"] = result["verified"]["points_gicp_pr"]
    for label, c in curves.items():
        ax.plot(c["recall"], c["precision"], marker=".", label=label)
    ax.set(xlabel="recall", ylabel="precision", xlim=(0, 1.02), ylim=(0, 1.02))
    ax.legend()
    pr_png = os.path.join(folder, "place_pr.png")
    fig.savefig(pr_png, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return [recall_png, pr_png]
