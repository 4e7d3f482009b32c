"""The pose-graph backend's solve (`gmmap.mapping.backend`): Levenberg-Marquardt, or GNC
(graduated non-convexity, truncated least squares) with a shortcut when last time's inlier set
is still a fixed point, the comparison of two solutions, and the search that places robots'
map frames for the warm start.
"""

from __future__ import annotations

import heapq
from typing import TYPE_CHECKING

import gtsam
import numpy as np

from gmmap.mapping.consistency import chi2_quantile
from gmmap.options import BackendOptions

if TYPE_CHECKING:
    from gmmap.mapping.backend import Match


def solve(
    graph: gtsam.NonlinearFactorGraph,
    initial: gtsam.Values,
    n_known: int,
    matches: list[Match],
    options: BackendOptions,
    outliers: set[int],
) -> tuple[gtsam.Values, np.ndarray, str, set[int]]:
    """Solves; returns the values, each match's weight (1 inlier, 0 outlier), how: "lm" (no
    robust stage), "verified" or "gnc", and the match ids GNC rejected (``outliers``, last
    time's, unless GNC ran). The graph's first ``n_known`` factors are known inliers, then one
    factor per match in ``matches`` order.

    GNC runs its whole schedule (several Levenberg-Marquardt solves) whenever any match is
    an outlier, i.e. at nearly every update once a wrong match PCM cannot see (a single
    match between two robots) is in the graph. So first one solve with last time's inlier
    set: when the truncated-least-squares weights it implies are the same set (every
    included match under the threshold, every excluded one over it), that is a fixed point
    of GNC and it is kept; otherwise GNC decides from scratch.
    """
    o = options
    lm = gtsam.LevenbergMarquardtParams()
    lm.setMaxIterations(o.max_iterations)
    if not (o.gnc and matches):
        values = gtsam.LevenbergMarquardtOptimizer(graph, initial, lm).optimize()
        return values, np.ones(len(matches)), "lm", outliers
    factors = [graph.at(n_known + k) for k in range(len(matches))]
    threshold = 0.5 * chi2_quantile(o.gnc_probability, 6)  # GTSAM's factor error is ½‖r‖²
    inlier = np.array([m.id not in outliers for m in matches])
    trial = gtsam.NonlinearFactorGraph()
    for k in range(n_known):
        trial.add(graph.at(k))
    for f, keep in zip(factors, inlier, strict=True):
        if keep:
            trial.add(f)
    values = gtsam.LevenbergMarquardtOptimizer(trial, initial, lm).optimize()
    if np.array_equal(np.array([f.error(values) < threshold for f in factors]), inlier):
        return values, inlier.astype(float), "verified", outliers
    params = gtsam.GncLMParams(lm)
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(list(range(n_known)))
    gnc = gtsam.GncLMOptimizer(graph, initial, params)
    gnc.setInlierCostThresholdsAtProbability(o.gnc_probability)
    values = gnc.optimize()
    weights = np.asarray(gnc.getWeights())[n_known:]
    rejected = {m.id for m, w in zip(matches, weights, strict=True) if w <= 0.5}
    return values, weights, "gnc", rejected


def better(
    graph_a: gtsam.NonlinearFactorGraph,
    values_a: gtsam.Values,
    weights_a: np.ndarray,
    graph_b: gtsam.NonlinearFactorGraph,
    values_b: gtsam.Values,
    weights_b: np.ndarray,
    n_known: int,
) -> bool:
    """Whether solution a beats b: more matches kept as inliers, then a lower cost of the
    odometry, priors and kept matches."""

    def score(graph, values, weights) -> tuple[int, float]:
        kept = [*range(n_known), *(n_known + i for i, w in enumerate(weights) if w > 0.5)]
        return -len(kept), sum(graph.at(k).error(values) for k in kept)

    return score(graph_a, values_a, weights_a) < score(graph_b, values_b, weights_b)


def shortest_path_frames(
    robots: list[str],
    links: dict[str, list[tuple[int, str, np.ndarray]]],
    reference: dict[str, str],
) -> dict[str, np.ndarray]:
    """Each robot's frame (its map frame into its group's reference frame) by a shortest-path
    search from each reference robot over ``links``: robot → (cost, neighbour, transform from
    the neighbour's map frame into the robot's). Among equal paths the link listed first wins.
    """
    frames: dict[str, np.ndarray] = {}
    for robot in robots:
        if reference[robot] != robot:
            continue
        heap: list[tuple[int, int, str, np.ndarray]] = [(0, 0, robot, np.eye(4))]
        tie = 1
        while heap:
            dist, _, r, T = heapq.heappop(heap)
            if r in frames:
                continue
            frames[r] = T
            for cost, nxt, T_rn in links[r]:
                if nxt not in frames and reference[nxt] == robot:
                    heapq.heappush(heap, (dist + cost, tie, nxt, T @ T_rn))
                    tie += 1
    return frames
