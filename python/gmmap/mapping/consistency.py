"""Pairwise consistency maximisation (PCM) for the pose-graph backend, `gmmap.mapping.backend`.

Free functions, no graph state: the χ² threshold, the pairwise Mahalanobis test of matches
between one robot pair with the odometry drift between their anchors propagated (see the
backend's module docstring for the estimator), the drift prefix sums it needs, the maximum
clique search, and the grouping of matches by robot pair and of robots into connected groups.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.math.geometry import adjoint, invert, invert_with_cov, pose_distance, se3_log

if TYPE_CHECKING:
    from gmmap.mapping.backend import Match, Node


def chi2_quantile(p: float, dof: int = 6) -> float:
    """Quantile of the χ² distribution with an even number of degrees of freedom, by bisection
    on its closed-form CDF 1 − e^(−x/2) Σ_{j<dof/2} (x/2)ʲ/j!  (scipy is not a dependency)."""
    if dof <= 0 or dof % 2:
        raise InvalidInputError(f"dof must be even and positive, got {dof}")

    def cdf(x: float) -> float:
        h = x / 2
        return 1 - math.exp(-h) * sum(h**j / math.factorial(j) for j in range(dof // 2))

    lo, hi = 0.0, 1.0
    while cdf(hi) < p:
        hi *= 2
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < p else (lo, mid)
    return 0.5 * (lo + hi)


def max_clique(
    adjacent: np.ndarray, budget: int = 20_000, order: list[int] | None = None
) -> tuple[list[int], bool]:
    """A maximum clique of an undirected graph (boolean adjacency, no self loops).

    Heuristics first (peeling the least connected vertex until a clique remains, which suits
    PCM's graphs, a near-clique of true matches plus sparse wrong ones; and greedy growth from
    the best-connected vertices), then branch and bound with greedy-colouring bounds (Tomita's
    MCQ, on integer bitsets) looks for a larger one. Returns the clique (sorted) and whether
    the search finished within ``budget`` branch nodes (exact). ``order`` lists vertices by
    preference: among cliques of one size the more preferred tend to win.
    """
    n = len(adjacent)
    if n == 0:
        return [], True
    order = list(order) if order is not None else list(range(n))
    A = np.asarray(adjacent, dtype=bool)[np.ix_(order, order)]  # vertex v here is order[v]
    best = _heuristic_clique(A)
    nbr = [int.from_bytes(np.packbits(row, bitorder="little").tobytes(), "little") for row in A]
    state = {"best": best, "nodes": 0}

    def colour_sort(P: int) -> list[tuple[int, int]]:
        # P's vertices with colour bounds, colours increasing (a clique has ≤ 1 per colour);
        # within a colour, lower (more preferred) vertices first.
        out, colour = [], 0
        while P:
            colour += 1
            avail = P
            while avail:
                v = (avail & -avail).bit_length() - 1
                out.append((v, colour))
                P &= ~(1 << v)
                avail &= ~nbr[v] & ~(1 << v)
        return out

    def expand(R: list[int], P: int) -> bool:
        for v, colour in reversed(colour_sort(P)):
            if len(R) + colour <= len(state["best"]):
                return True
            state["nodes"] += 1
            if state["nodes"] > budget:
                return False
            newP = P & nbr[v]
            if newP:
                if not expand([*R, v], newP):
                    return False
            elif len(R) + 1 > len(state["best"]):
                state["best"] = [*R, v]
            P &= ~(1 << v)
        return True

    exact = expand([], (1 << n) - 1)
    return sorted(order[v] for v in state["best"]), exact


def _heuristic_clique(A: np.ndarray, seeds: int = 8) -> list[int]:
    """The larger of: peeling (drop a vertex of least degree, the least preferred on ties,
    until the rest is a clique) and greedy growth from the ``seeds`` best-connected vertices
    (add the candidate with most candidate neighbours: PCM's heuristic)."""
    n = len(A)
    alive = np.ones(n, dtype=bool)
    degree = A.sum(axis=1).astype(np.int64)
    while True:
        idx = np.flatnonzero(alive)
        d = degree[idx]
        if d.min() >= len(idx) - 1:
            best = list(idx)
            break
        v = idx[len(d) - 1 - np.argmin(d[::-1])]
        alive[v] = False
        degree -= A[:, v]
    for seed in np.argsort(-A.sum(axis=1), kind="stable")[:seeds]:
        clique, cand = [int(seed)], A[seed].copy()
        while cand.any():
            idx = np.flatnonzero(cand)
            v = int(idx[np.argmax(A[np.ix_(idx, idx)].sum(axis=1))])
            clique.append(v)
            cand &= A[v]
        if len(clique) > len(best):
            best = clique
    return [int(v) for v in best]


def by_robot_pair(matches: list[Match]) -> dict[tuple[str, str], list[Match]]:
    pairs: dict[tuple[str, str], list[Match]] = {}
    for m in matches:
        key = tuple(sorted((m.target[0], m.source[0])))
        pairs.setdefault(key, []).append(m)
    return pairs


def independent(matches: list[Match]) -> int:
    """How many of one robot pair's ``matches`` count as independent evidence: the fewer
    distinct submaps either robot gives them. A query misplaced along a corridor matches the
    other robot's consecutive submaps there, and those matches agree with each other (that
    robot's odometry moved it along the same corridor), but they all rest on the one query."""
    sides: dict[str, set[Node]] = {}
    for m in matches:
        for node in (m.target, m.source):
            sides.setdefault(node[0], set()).add(node)
    return min((len(nodes) for nodes in sides.values()), default=0)


def components(robots: list[str], matches: list[Match]) -> list[list[str]]:
    """Connected components of robots linked by matches, each sorted, sorted by first name."""
    parent = {r: r for r in robots}

    def find(r: str) -> str:
        while parent[r] != r:
            parent[r] = parent[parent[r]]
            r = parent[r]
        return r

    for m in matches:
        a, b = find(m.target[0]), find(m.source[0])
        if a != b:
            parent[max(a, b)] = min(a, b)
    groups: dict[str, list[str]] = {}
    for r in robots:
        groups.setdefault(find(r), []).append(r)
    return sorted(sorted(g) for g in groups.values())


def pairwise_mahalanobis(
    pair: list[Match],
    anchors: Mapping[Node, np.ndarray],
    seqs: Mapping[str, list[int]],
    prefix: Callable[[str], np.ndarray],
) -> np.ndarray:
    """(m, m) squared Mahalanobis distances of Fₖ·Fₗ⁻¹ from identity (the backend's module
    docstring) for the matches of one robot pair; ``anchors`` and ``seqs`` (sorted) are the
    graph's, ``prefix(robot)`` its `drift_prefix` over those seqs.

    Everything is expressed as left perturbations in robot a's map frame (a = target robot
    of the first match; matches the other way round are inverted first).
    """
    a, b = pair[0].target[0], pair[0].source[0]
    Z, Cz, ia, jb = [], [], [], []
    for m in pair:
        if m.target[0] == a and m.source[0] == b:
            T, C, (_, i), (_, j) = m.transform, m.covariance, m.target, m.source
        else:  # the same robot pair the other way round: invert the measurement
            (T, C), (_, i), (_, j) = (
                invert_with_cov(m.transform, m.covariance),
                m.source,
                m.target,
            )
        Z.append(T)
        Cz.append(C)
        ia.append(i)
        jb.append(j)
    A = np.array([anchors[(a, i)] for i in ia])
    B = np.array([anchors[(b, j)] for j in jb])
    Z, Cz = np.array(Z), np.array(Cz)
    F = A @ Z @ invert(B)
    AdA = adjoint(A)
    Q = AdA @ Cz @ AdA.transpose(0, 2, 1)  # match noise of Fₖ in a's map frame
    # Positions along each robot's sorted seqs: S is indexed by them.
    ia_ = np.searchsorted(seqs[a], ia)
    jb_ = np.searchsorted(seqs[b], jb)
    Sa, Sb = prefix(a)[ia_], prefix(b)[jb_]
    AdF = adjoint(F)
    Finv = invert(F)
    d2 = np.empty((len(pair), len(pair)))
    for k0 in range(0, len(pair), 64):  # row blocks: memory O(64·m), not O(m²)
        k = slice(k0, k0 + 64)
        sa = np.sign(ia_[None, :] - ia_[k, None])[..., None, None]
        sb = np.sign(jb_[None, :] - jb_[k, None])[..., None, None]
        dSa = sa * (Sa[None] - Sa[k, None])
        dSb = sb * (Sb[None] - Sb[k, None])
        Ad = AdF[k, None]
        cov = Q[k, None] + Q[None] + dSa + Ad @ dSb @ np.swapaxes(Ad, -1, -2)
        r = se3_log(F[k, None] @ Finv[None])
        sol = np.linalg.solve(cov + 1e-12 * np.eye(6), r[..., None])[..., 0]
        d2[k] = np.einsum("kli,kli->kl", r, sol)
    return 0.5 * (d2 + d2.T)


def drift_prefix(anchors: np.ndarray, sigmas: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """(n, 6, 6) Sᵢ = Σ_{s≤i} Ad(anchor_s) Σ_s Ad(anchor_s)ᵀ over a robot's (n, 4, 4) anchors in
    seq order, ``sigmas`` the drift model's (M, 6) sigmas (ω, v) of (M, 4, 4) relative motions:
    the covariance of anchor j relative to anchor i, as a left perturbation in the map frame,
    is Sⱼ − Sᵢ (independent steps)."""
    S = np.zeros((len(anchors), 6, 6))
    if len(anchors) > 1:
        steps = invert(anchors[:-1]) @ anchors[1:]
        sig = sigmas(steps)
        Ad = adjoint(anchors[1:])
        S[1:] = np.cumsum(Ad @ (sig[:, :, None] ** 2 * Ad.transpose(0, 2, 1)), axis=0)
    return S


def contradicted(
    joining: Mapping[tuple[str, str], list[Match]],
    consistent: Mapping[tuple[str, str], list[Match]],
    anchors: Mapping[Node, np.ndarray],
    distance: float,
    angle_deg: float,
    strong: float,
) -> set[tuple[str, str]]:
    """The robot pairs of ``joining`` that a path through a third robot contradicts.

    ``consistent`` holds every pair's PCM inliers (joining or not). For a pair (a, b), a path
    is a match a–x and a match x–b; it contradicts the pair when it puts b's submap on it more
    than ``distance`` or ``angle_deg`` away from where the pair's most confident match does,
    and its weaker match is strong (confidence >= ``strong``) and more confident than the
    pair's median match: weak or equal evidence does not overrule agreement. PCM sees one
    robot pair at a time, so wrong matches that agree with each other (a corridor seen end for
    end, four times in a row) pass it; the third robot that met both elsewhere does not agree.
    Matches without a confidence take no part. One wrong but confident match on a path holds a
    true join back: the safe way to fail.
    """
    links: dict[tuple[str, str], list[tuple[np.ndarray, float, Node]]] = {}
    for pair in consistent.values():
        for m in pair:
            if m.confidence is None:
                continue
            F, c = anchors[m.target] @ m.transform @ invert(anchors[m.source]), m.confidence
            links.setdefault((m.target[0], m.source[0]), []).append((F, c, m.source))
            links.setdefault((m.source[0], m.target[0]), []).append((invert(F), c, m.target))
    robots = {r for pair in consistent for r in pair}
    out = set()
    for (a, b), pair in joining.items():
        if (a, b) not in links:
            continue
        F_ab, _, _ = max(links[(a, b)], key=lambda link: link[1])
        median = float(np.median([m.confidence for m in pair if m.confidence is not None]))
        for x in sorted(robots - {a, b}):
            for (F_ax, c_ax, _), (F_xb, c_xb, node) in itertools.product(
                links.get((a, x), []), links.get((x, b), [])
            ):
                weaker = min(c_ax, c_xb)
                if weaker < strong or weaker <= median:
                    continue
                # Both estimates of where b's submap on the path sits in a's map.
                moved, turned = pose_distance(F_ax @ F_xb @ anchors[node], F_ab @ anchors[node])
                if moved > distance or turned > angle_deg:
                    out.add((a, b))
    return out
