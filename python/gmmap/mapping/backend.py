"""Multi-robot pose-graph backend (paper IV-A, after DESIGN.md): GTSAM Pose3 over submap anchors.

Nodes are submap anchors (robot, seq). Factors:

* odometry: a BetweenFactor between consecutive submaps of a robot (by seq; a gap is bridged
  by the longer motion), measured from the anchors, with the drift model of
  `gmmap.math.drift.Drift` applied to the relative motion: per axis
  σₜ = translation·d + translation_floor, σᵣ = rotation_per_rad·θ + rotation_per_m·d +
  rotation_floor (d, θ: its length and angle). That model is per step; odometry integrated over F
  frames per submap has σ ≈ (model)/√F, so the defaults are conservative for real submaps.
* matches: BetweenFactor(target, source, transform) from registration (transform maps source
  anchor coordinates into the target anchor frame, i.e. the measurement pose_t⁻¹·pose_s). The
  registration's information is for a left perturbation exp(ξ)·T, GTSAM's error is a right one,
  T·exp(ξ'), with ξ' = Ad_T⁻¹ ξ, so Info_R = Ad_Tᵀ Info_L Ad_T (both tangents (ω, v)).
* one prior per connected group of robots, on the first submap of its reference robot (the
  lowest name) at its odometry anchor: the group's frame IS that robot's map frame.

Robustness, in two stages. PCM (pairwise consistency maximisation) before optimising: every
match k between robots a and b gives an estimate Fₖ = anchor_a(iₖ)·Zₖ·anchor_b(jₖ)⁻¹ of the
transform from b's map frame into a's; two true matches agree up to the match noise and the
odometry drift between their anchors on either robot, so Fₖ·Fₗ⁻¹ must pass a χ² test (6 dof)
with that propagated covariance (first order, exact SE(3) logarithm; drift covariances from
prefix sums, so each pair costs O(1)). The largest set of pairwise-consistent matches
(maximum clique: branch and bound, exact unless its node budget runs out, then the best
heuristic clique) is kept per robot pair. Then GNC (graduated non-convexity, truncated least
squares; odometry and priors known inliers) in the optimisation.

Limits: PCM needs two matches between the same robots (a single one only GNC can reject), so
no robot pair joins on fewer than three (``min_matches``). Wrong matches consistent with each
other (robots passing a symmetric corridor both ways agree on one 180° flip) can win the
clique; only a third robot that met both can refuse them (`consistency.contradicted`), and
with two robots nothing does. Loop closures within one robot go
through the same test with both odometry legs taken as independent, which they are not where
they overlap (approximate there).

Incremental use: add submaps and matches as they arrive and call `optimize` again. The graph
is re-solved in batch (GNC needs the whole graph; factors are built once), warm-started from
the last estimate, and GNC's schedule only runs when last time's inlier set is no longer a
fixed point (see `gmmap.mapping.solver.solve`). ISAM2 solves an update faster
(benchmarks/backend.py), but it cannot run GNC or drop a rejected factor cheaply, so it is
not used.
"""

from __future__ import annotations

import bisect
import itertools
import math
import time
from dataclasses import dataclass, field

import gtsam
import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.mapping.consistency import (
    by_robot_pair,
    chi2_quantile,
    components,
    contradicted,
    drift_prefix,
    independent,
    max_clique,
    pairwise_mahalanobis,
)
from gmmap.mapping.solver import better, shortest_path_frames, solve
from gmmap.math.geometry import (
    invert,
    project_rigid,
    right_information,
    rigid_matrix,
    rotation_angle,
)
from gmmap.options import BackendOptions

Node = tuple[str, int]


@dataclass(frozen=True)
class Match:
    """An inter-robot (or loop-closure) measurement as given to `PoseGraph.add_match`.

    ``covariance`` is the regularised left-perturbation covariance (ω, v) of ``transform``.
    """

    id: int
    target: Node
    source: Node
    transform: np.ndarray
    covariance: np.ndarray
    confidence: float | None


@dataclass
class BackendResult:
    """What `PoseGraph.optimize` returns.

    ``poses``: optimised anchor poses, each in its group's reference frame (= the reference
    robot's map frame). ``to_reference[r]`` maps robot r's map frame into its reference's
    (identity for a reference robot; see `PoseGraph` for the estimator). ``rejected`` maps an
    edge id to why: "pcm", "pending" (too few between its robots: ``min_matches``),
    "ambiguous" (the consistent set under ``min_consistent_share`` of their verified matches),
    "contradicted" (by a path through a third robot: ``path_distance``) or "gnc". ``edges``
    maps every edge id to its (target, source) nodes.
    """

    poses: dict[Node, np.ndarray]
    to_reference: dict[str, np.ndarray]
    reference: dict[str, str]
    groups: list[list[str]]
    accepted: list[int]
    rejected: dict[int, str]
    edges: dict[int, tuple[Node, Node]]
    time_s: float
    stats: dict = field(default_factory=dict)


class PoseGraph:
    """The joint pose graph of all robots' submaps; see the module docstring.

    ``to_reference`` of a robot r is where its map frame sits in the reference frame, taken at
    r's first submap: T = P(r, first)·anchor(r, first)⁻¹. A map frame is where odometry
    started, and the reference frame is pinned the same way (its robot's first anchor), so
    this is the consistent definition; the anchor there has no drift, and P(r, first) is the
    graph's estimate from every match of every robot through r's optimised odometry, so the
    optimisation already does the averaging. Each later submap gives its own
    P(r,i)·anchor(r,i)⁻¹, off by the drift accumulated since the start (a random walk, so
    weighting by its covariance does not average it out): on benchmarks/backend.py the
    drift-weighted mean of all of them was no better (translation equal within 1 cm, rotation
    up to 0.7° worse) and the plain mean 12-17 times worse in translation.
    """

    def __init__(self, options: BackendOptions | None = None) -> None:
        self.options = options or BackendOptions()
        self._anchors: dict[Node, np.ndarray] = {}
        self._seqs: dict[str, list[int]] = {}
        self._matches: list[Match] = []
        # Warm start: drift-corrected poses in each robot's own map frame, and the frame
        # transform of the last solution (P = frame · local).
        self._local: dict[Node, np.ndarray] = {}
        self._frame: dict[str, np.ndarray] = {}
        self._reference: dict[str, str] = {}
        self._gnc_outliers: set[int] = set()  # match ids GNC rejected last time it ran
        # PCM per robot pair, reused while its matches and the odometry under them are the
        # same: appending submaps leaves earlier drift sums alone, inserting one does not.
        self._pcm_cache: dict[tuple[str, str], tuple[tuple[int, ...], int, set[int], bool]] = {}
        self._odometry_version = 0
        self._prefix: dict[str, np.ndarray] = {}
        # GTSAM keys are fixed when a submap arrives, so factors are built once and reused.
        self._key: dict[Node, int] = {}
        self._odometry_factors: dict[tuple[str, int, int], gtsam.BetweenFactorPose3] = {}
        self._match_factors: dict[int, gtsam.BetweenFactorPose3] = {}

    # ----------------------------------------------------------------------------- input
    @property
    def robots(self) -> list[str]:
        return sorted(self._seqs)

    @property
    def n_submaps(self) -> int:
        return len(self._anchors)

    def has_submap(self, node: Node) -> bool:
        return (str(node[0]), int(node[1])) in self._anchors

    @property
    def matches(self) -> list[Match]:
        return list(self._matches)

    def add_submap(self, robot: str, seq: int, anchor: np.ndarray) -> None:
        """Adds a submap anchor (4x4, in the robot's map frame); odometry links it to the
        robot's neighbouring submaps by seq."""
        node = (str(robot), int(seq))
        if node in self._anchors:
            raise InvalidInputError(f"submap {node} was already added")
        self._anchors[node] = rigid_matrix(anchor, f"anchor of {node}")
        self._key[node] = len(self._key)
        seqs = self._seqs.setdefault(node[0], [])
        if seqs and node[1] < seqs[-1]:
            self._odometry_version += 1
        bisect.insort(seqs, node[1])
        self._prefix.pop(node[0], None)

    def add_match(
        self,
        target: Node,
        source: Node,
        transform: np.ndarray,
        information: np.ndarray | None = None,
        confidence: float | None = None,
    ) -> int:
        """Adds a registration result: ``transform`` maps the source submap's anchor frame into
        the target's; ``information`` (6x6, left perturbation, (ω, v)) or None for the default
        sigmas. Returns the edge id (0, 1, … in order)."""
        target, source = (str(target[0]), int(target[1])), (str(source[0]), int(source[1]))
        for node in (target, source):
            if node not in self._anchors:
                raise InvalidInputError(f"match refers to unknown submap {node}")
        if target == source:
            raise InvalidInputError(f"match from {target} to itself")
        T = rigid_matrix(transform, "match transform")
        cov = self._match_covariance(information)
        if confidence is not None and not math.isfinite(confidence):
            raise InvalidInputError(f"confidence must be finite, got {confidence}")
        match = Match(len(self._matches), target, source, T, cov, confidence)
        self._matches.append(match)
        info = right_information(T, np.linalg.inv(cov))
        noise = gtsam.noiseModel.Gaussian.Information(0.5 * (info + info.T))
        k_t, k_s = self._key[target], self._key[source]
        self._match_factors[match.id] = gtsam.BetweenFactorPose3(k_t, k_s, gtsam.Pose3(T), noise)
        return match.id

    def _match_covariance(self, information: np.ndarray | None) -> np.ndarray:
        o = self.options
        floor = np.diag([o.match_floor_rotation**2] * 3 + [o.match_floor_translation**2] * 3)
        if information is None:
            s = [o.match_sigma_rotation**2] * 3 + [o.match_sigma_translation**2] * 3
            return np.diag(s) + floor
        info = np.asarray(information, dtype=np.float64)
        if info.shape != (6, 6) or not np.all(np.isfinite(info)):
            raise InvalidInputError(f"information must be a finite 6x6 matrix, got {info.shape}")
        # Eigenvalues clipped at 1e-4 (σ ≤ 100): a direction registration could not observe
        # (a corridor's axis) becomes a weak constraint, not a singular one.
        w, V = np.linalg.eigh(0.5 * (info + info.T))
        return (V / np.maximum(w, 1e-4)) @ V.T + floor

    # -------------------------------------------------------------------------- optimise
    def optimize(self) -> BackendResult:
        """Selects consistent matches (PCM), solves (GNC or LM) from the last
        estimate and returns poses, frames and the accepted/rejected edges."""
        start = time.perf_counter()
        t_pcm = time.perf_counter()
        candidates, rejected, exact = self._select()
        t_pcm = time.perf_counter() - t_pcm

        t_opt = time.perf_counter()
        groups = components(self.robots, candidates)
        reference = {r: g[0] for g in groups for r in g}
        graph, initial, n_known = self._build(candidates, reference)
        o, outliers = self.options, self._gnc_outliers
        values, weights, solver, self._gnc_outliers = solve(
            graph, initial, n_known, candidates, o, outliers
        )
        if solver == "gnc":
            # The inlier set changed: last time's estimate may sit in a basin the new set
            # does not support. Solve again from today's matches alone; keep the better.
            cold = self._build(candidates, reference, fresh=True)
            warm_outliers = self._gnc_outliers
            c_values, c_weights, _, self._gnc_outliers = solve(*cold, candidates, o, warm_outliers)
            if better(cold[0], c_values, c_weights, graph, values, weights, n_known):
                graph, values, weights = cold[0], c_values, c_weights
            else:
                self._gnc_outliers = warm_outliers
        accepted = []
        for m, w in zip(candidates, weights, strict=True):
            if w > 0.5:
                accepted.append(m)
            else:
                rejected[m.id] = "gnc"
        t_opt = time.perf_counter() - t_opt

        result = self._finish(values, accepted, rejected)
        result.time_s = time.perf_counter() - start
        result.stats = dict(
            pcm_s=t_pcm,
            optimize_s=t_opt,
            pcm_exact=exact,
            solver=solver,
            factors=graph.size(),
            submaps=self.n_submaps,
            matches=len(self._matches),
        )
        return result

    def _select(self) -> tuple[list[Match], dict[int, str], bool]:
        """The matches left for the solve after PCM (per robot pair, cached while its matches
        and the odometry under them are unchanged) and ``min_matches``, the rejected ones with
        why, and whether every clique search was exact."""
        o = self.options
        rejected: dict[int, str] = {}
        candidates = list(self._matches)
        exact = True
        if o.pcm:
            kept: list[Match] = []
            for key, pair in by_robot_pair(candidates).items():
                ids = tuple(m.id for m in pair)
                cached = self._pcm_cache.get(key)
                if cached and cached[:2] == (ids, self._odometry_version):
                    inliers, pair_exact = cached[2], cached[3]
                else:
                    inliers, pair_exact = self._pcm(pair)
                    self._pcm_cache[key] = (ids, self._odometry_version, inliers, pair_exact)
                exact &= pair_exact
                kept += [pair[k] for k in inliers]
                rejected.update({pair[k].id: "pcm" for k in set(range(len(pair))) - inliers})
            candidates = sorted(kept, key=lambda m: m.id)
        verified = {key: len(pair) for key, pair in by_robot_pair(list(self._matches)).items()}
        consistent, joining = by_robot_pair(candidates), {}
        for (a, b), pair in consistent.items():
            if a == b:
                continue
            if not self._enough(pair):
                rejected.update({m.id: "pending" for m in pair})
            elif len(pair) < o.min_consistent_share * verified[(a, b)]:
                rejected.update({m.id: "ambiguous" for m in pair})
            else:
                joining[(a, b)] = pair
        paths = (o.path_distance, o.path_angle_deg, o.strong_confidence)
        for key in contradicted(joining, consistent, self._anchors, *paths):
            rejected.update({m.id: "contradicted" for m in joining[key]})
        candidates = [m for m in candidates if m.id not in rejected]
        return candidates, rejected, exact

    def _enough(self, pair: list[Match]) -> bool:
        """Whether a robot pair's consistent matches may join their maps: ``min_matches`` of
        them, or ``min_strong_matches`` strong ones, resting on at least ``min_submaps``
        submaps of each robot (`independent`; never more than either count asks for)."""
        o = self.options
        strong = sum(m.confidence is None or m.confidence >= o.strong_confidence for m in pair)
        enough = len(pair) >= o.min_matches or strong >= o.min_strong_matches
        least = min(o.min_submaps, o.min_matches, o.min_strong_matches)
        return enough and independent(pair) >= least

    def _pcm(self, pair: list[Match]) -> tuple[set[int], bool]:
        """Indices (into ``pair``) of the largest pairwise-consistent subset."""
        if len(pair) < 2:
            return set(range(len(pair))), True
        d2 = self._pairwise_mahalanobis(pair)
        adjacent = d2 < chi2_quantile(self.options.pcm_probability, 6)
        np.fill_diagonal(adjacent, False)
        # Order by confidence so that among equal cliques the more confident one is found first.
        order = sorted(range(len(pair)), key=lambda k: -(pair[k].confidence or 0.0))
        clique, exact = max_clique(adjacent, self.options.pcm_exact_budget, order)
        return set(clique), exact

    def _pairwise_mahalanobis(self, pair: list[Match]) -> np.ndarray:
        """(m, m) squared Mahalanobis distances of Fₖ·Fₗ⁻¹ from identity (module docstring;
        `gmmap.mapping.consistency.pairwise_mahalanobis`)."""
        return pairwise_mahalanobis(pair, self._anchors, self._seqs, self._drift_prefix)

    def _drift_prefix(self, robot: str) -> np.ndarray:
        """(n, 6, 6) Sᵢ = Σ_{s≤i} Ad(anchor_s) Σ_s Ad(anchor_s)ᵀ over the robot's submaps: the
        covariance of anchor j relative to anchor i, as a left perturbation in the map frame,
        is Sⱼ − Sᵢ (independent steps)."""
        if robot in self._prefix:
            return self._prefix[robot]
        anchors = np.array([self._anchors[(robot, s)] for s in self._seqs[robot]])
        S = drift_prefix(anchors, self._odometry_sigmas)
        self._prefix[robot] = S
        return S

    def _odometry_sigmas(self, steps: np.ndarray) -> np.ndarray:
        """(M, 6) sigmas (ω, v) of the drift model for (M, 4, 4) relative motions."""
        o = self.options
        d = np.linalg.norm(steps[:, :3, 3], axis=1)
        theta = rotation_angle(steps[:, :3, :3])
        st = o.translation * d + o.translation_floor
        sr = o.rotation_per_rad * theta + o.rotation_per_m * d + o.rotation_floor
        return np.stack([sr, sr, sr, st, st, st], axis=1)

    def _build(
        self, matches: list[Match], reference: dict[str, str], fresh: bool = False
    ) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values, int]:
        """The factor graph (priors and odometry first, matches last, in ``matches`` order),
        the initial values (``fresh``: from odometry and matches alone, not the last
        estimate) and the number of leading known-inlier factors."""
        keys = self._key
        graph = gtsam.NonlinearFactorGraph()
        initial = gtsam.Values()
        frames, local = self._initial_frames(matches, reference, fresh)
        nodes = list(keys)
        # Projected onto SO(3): GTSAM keeps a slightly skewed rotation as given, and the
        # warm-start loop (solution → frames → initial values) would amplify it each update.
        start = project_rigid(np.array([frames[n[0]] @ local[n] for n in nodes]))
        for node, T in zip(nodes, start, strict=True):
            initial.insert(keys[node], gtsam.Pose3(T))
        o = self.options
        strong = gtsam.noiseModel.Isotropic.Sigma(6, o.prior_sigma)
        # A weak prior on every other robot's first submap, at its initial value: it pins a
        # robot whose every match GNC turns off (no gauge otherwise), and is 1e-12 as stiff as
        # a match, so it pulls nothing.
        weak = gtsam.noiseModel.Isotropic.Sigma(6, 1e3)
        for robot, seqs in self._seqs.items():
            first = (robot, seqs[0])
            if reference[robot] == robot:
                pose, noise = gtsam.Pose3(self._anchors[first]), strong
            else:
                pose, noise = initial.atPose3(keys[first]), weak
            graph.add(gtsam.PriorFactorPose3(keys[first], pose, noise))
        for robot, seqs in self._seqs.items():
            for factor in self._odometry(robot, seqs):
                graph.add(factor)
        n_known = graph.size()
        for m in matches:
            graph.add(self._match_factors[m.id])
        return graph, initial, n_known

    def _odometry(self, robot: str, seqs: list[int]) -> list[gtsam.BetweenFactorPose3]:
        """The robot's odometry factors between consecutive seqs (cached; new ones built)."""
        pairs = list(itertools.pairwise(seqs))
        missing = [(a, b) for a, b in pairs if (robot, a, b) not in self._odometry_factors]
        if missing:
            A = np.array([self._anchors[(robot, a)] for a, _ in missing])
            B = np.array([self._anchors[(robot, b)] for _, b in missing])
            steps = invert(A) @ B
            for (a, b), step, sig in zip(missing, steps, self._odometry_sigmas(steps), strict=True):
                noise = gtsam.noiseModel.Diagonal.Sigmas(sig)
                k0, k1 = self._key[(robot, a)], self._key[(robot, b)]
                factor = gtsam.BetweenFactorPose3(k0, k1, gtsam.Pose3(step), noise)
                self._odometry_factors[(robot, a, b)] = factor
        return [self._odometry_factors[(robot, a, b)] for a, b in pairs]

    def _initial_frames(
        self, matches: list[Match], reference: dict[str, str], fresh: bool = False
    ) -> tuple[dict[str, np.ndarray], dict[Node, np.ndarray]]:
        """Warm start: per robot a frame (its map frame into its group's reference) and per
        node a pose in the robot's own map frame, P = frame · local."""
        local: dict[Node, np.ndarray] = {}
        for robot, seqs in self._seqs.items():
            known = [s for s in seqs if (robot, s) in self._local]
            for s in seqs:
                node = (robot, s)
                if fresh:
                    local[node] = self._anchors[node]
                    continue
                if node in self._local:
                    local[node] = self._local[node]
                    continue
                # Nearest earlier estimated submap (else the nearest later), moved by odometry.
                i = bisect.bisect_left(known, s)
                base = known[i - 1] if i > 0 else (known[0] if known else None)
                if base is None:
                    local[node] = self._anchors[node]
                else:
                    b = (robot, base)
                    local[node] = self._local[b] @ invert(self._anchors[b]) @ self._anchors[node]
        # Robots' frames by a shortest-path search from each reference: links between robots
        # that shared a group last time (their relative frame is optimised, cost 0) are
        # preferred to links through a single match (cost 1).
        # One match link per robot pair is enough: the most confident (then the oldest).
        links: dict[str, list[tuple[int, str, np.ndarray]]] = {r: [] for r in self._seqs}
        chosen: dict[tuple[str, str], Match] = {}
        for m in sorted(matches, key=lambda m: (-(m.confidence or 0.0), m.id)):
            chosen.setdefault((m.target[0], m.source[0]), m)
        for (a, b), m in chosen.items():
            if a != b:
                T_ab = local[m.target] @ m.transform @ invert(local[m.source])
                links[a].append((1, b, T_ab))
                links[b].append((1, a, invert(T_ab)))
        robots = sorted(self._seqs)
        for a in [] if fresh else robots:
            for b in robots:
                known = a != b and a in self._frame and b in self._frame
                if known and self._reference[a] == self._reference[b]:
                    links[a].append((0, b, invert(self._frame[a]) @ self._frame[b]))
        return shortest_path_frames(robots, links, reference), local

    def _finish(
        self, values: gtsam.Values, accepted: list[Match], rejected: dict[int, str]
    ) -> BackendResult:
        """Final groups from the accepted matches, poses re-anchored to each group's reference
        (exact where GNC split a group), frames and the warm-start state."""
        groups = components(self.robots, accepted)
        reference = {r: g[0] for g in groups for r in g}
        nodes = list(self._key)
        mats = project_rigid(np.array([values.atPose3(self._key[n]).matrix() for n in nodes]))
        raw = dict(zip(nodes, mats, strict=True))
        poses: dict[Node, np.ndarray] = {}
        for g in groups:
            first = (g[0], self._seqs[g[0]][0])
            fix = self._anchors[first] @ invert(raw[first])
            for r in g:
                for s in self._seqs[r]:
                    poses[(r, s)] = fix @ raw[(r, s)]
        to_reference = {r: self._to_reference(r, poses, reference[r]) for r in self.robots}
        self._frame = to_reference
        self._reference = reference
        self._local = {n: invert(to_reference[n[0]]) @ P for n, P in poses.items()}
        return BackendResult(
            poses=poses,
            to_reference=to_reference,
            reference=reference,
            groups=groups,
            accepted=[m.id for m in accepted],
            rejected=dict(sorted(rejected.items())),
            edges={m.id: (m.target, m.source) for m in self._matches},
            time_s=0.0,
        )

    def _to_reference(self, robot: str, poses: dict[Node, np.ndarray], reference: str):
        """Robot's map frame → its reference's, at its first submap (class docstring)."""
        if robot == reference:
            return np.eye(4)
        first = (robot, self._seqs[robot][0])
        return project_rigid(poses[first] @ invert(self._anchors[first]))

    # ----------------------------------------------------------------------- estimates
    def estimate(self) -> dict[Node, np.ndarray]:
        """The last solution's poses in each robot's own map frame (drift-corrected anchors)."""
        return dict(self._local)
