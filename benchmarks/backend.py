"""Backend benchmark: time per update as the joint graph grows, and robustness to wrong matches.

Synthetic world: N robots wander (2 m between submaps, smooth random yaw, kept inside a square)
through one area; each robot's map frame is its own start, so the true frame of robot r in the
reference robot's is G_ref(0)⁻¹·G_r(0). Odometry is drifted with `Drift` (its defaults, per
submap). Place recognition is simulated: submaps of different robots whose true anchors lie
within ``--radius`` give a match with probability ``--detect``, measured with registration-like
noise (left perturbation, σ = 0.01 rad, 0.03 m) and that information. Wrong matches are added
until they are ``--wrong`` of all: random pairs of submaps of different robots with a random
yaw and up to 2 m offset (what a global registration of two unrelated places returns), with
the same information. Submaps arrive round-robin (one per robot per round), each match once
both of its submaps have arrived; every round ends with an `optimize` (an "update").

Compared in the same run: `PoseGraph` with PCM + GNC (default options) against plain
Levenberg-Marquardt on every match (no PCM, no GNC), on the same stream; and an oracle (plain
LM on the true matches only: the errors the data allow), whose stream is also timed through
gtsam.ISAM2 (the incremental solver the backend does not use: it cannot run GNC).

    .venv/bin/python benchmarks/backend.py [--robots 8] [--submaps 1000] [--wrong 0.2] [--seed 0]

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import gtsam
import numpy as np

from gmmap.mapping.backend import BackendOptions, PoseGraph
from gmmap.math.drift import Drift, apply_drift
from gmmap.math.geometry import adjoint, invert, right_information, rotation_angle, so3_exp

MATCH_SIGMA_R = 0.01
MATCH_SIGMA_T = 0.03


def trajectories(rng: np.random.Generator, robots: int, n: int, size: float, step: float = 2.0):
    """Per robot (n, 4, 4) true anchor poses: a smooth random walk kept inside a square of side
    ``size`` (steering back to the centre near the border), z ~ 0 with small bumps."""
    out = {}
    for r in range(robots):
        xy = rng.uniform(0.2 * size, 0.8 * size, 2)
        yaw = rng.uniform(-np.pi, np.pi)
        P = np.tile(np.eye(4), (n, 1, 1))
        for i in range(n):
            P[i, :3, :3] = so3_exp(np.array([[0.0, 0.0, yaw]]))[0]
            P[i, :3, 3] = [*xy, 0.1 * np.sin(0.3 * i + r)]
            to_centre = np.arctan2(*(size / 2 - xy)[::-1])
            near_edge = np.any((xy < 0.1 * size) | (xy > 0.9 * size))
            turn = np.angle(np.exp(1j * (to_centre - yaw))) * 0.5 if near_edge else 0.0
            yaw += turn + rng.normal(0, 0.25)
            xy = xy + step * np.array([np.cos(yaw), np.sin(yaw)])
        out[f"r{r}"] = P
    return out


def perturb(rng: np.random.Generator, sr: float, st: float) -> np.ndarray:
    E = np.eye(4)
    E[:3, :3] = so3_exp(rng.normal(0, sr, (1, 3)))[0]
    E[:3, 3] = rng.normal(0, st, 3)
    return E


def make_matches(rng, G, radius: float, detect: float, wrong: float):
    """(target, source, transform, is_true) tuples: true ones near in truth, then wrong ones so
    that they are ``wrong`` of all."""
    names = sorted(G)
    pos = {r: G[r][:, :3, 3] for r in names}
    out = []
    for ia, a in enumerate(names):
        for b in names[ia + 1 :]:
            d = np.linalg.norm(pos[a][:, None] - pos[b][None], axis=2)
            for i, j in zip(*np.nonzero(d < radius), strict=True):
                if rng.random() < detect:
                    Z = invert(G[a][i]) @ G[b][j]
                    Z = perturb(rng, MATCH_SIGMA_R, MATCH_SIGMA_T) @ Z
                    out.append(((a, int(i)), (b, int(j)), Z, True))
    n_wrong = round(len(out) * wrong / (1 - wrong))
    n = len(G[names[0]])
    for _ in range(n_wrong):
        a, b = rng.choice(names, 2, replace=False)
        i, j = (int(k) for k in rng.integers(n, size=2))
        Z = np.eye(4)
        Z[:3, :3] = so3_exp(np.array([[0, 0, rng.uniform(-np.pi, np.pi)]]))[0]
        Z[:3, 3] = [*rng.uniform(-2, 2, 2), rng.normal(0, 0.05)]
        out.append(((str(a), i), (str(b), j), Z, False))
    return out


def frame_errors(estimates: dict[str, np.ndarray], truth: dict[str, np.ndarray]) -> dict:
    """Translation (m) and rotation (deg) errors of estimated frames, over non-reference robots."""
    t, r = [], []
    for robot, T in estimates.items():
        if robot in truth:
            E = invert(truth[robot]) @ T
            t.append(float(np.linalg.norm(E[:3, 3])))
            r.append(float(np.degrees(rotation_angle(E[:3, :3]))[0]))
    if not t:
        return {}
    return {
        "t_mean_m": float(np.mean(t)),
        "t_max_m": float(np.max(t)),
        "r_mean_deg": float(np.mean(r)),
        "r_max_deg": float(np.max(r)),
    }


def weighted_mean(T: np.ndarray, W: np.ndarray, iterations: int = 5) -> np.ndarray:
    """argmin_X Σᵢ rᵢᵀ Wᵢ rᵢ, rᵢ = Log(X⁻¹ Tᵢ) (right perturbations), by Gauss-Newton."""
    X = gtsam.Pose3(T[0])
    H = W.sum(axis=0)
    for _ in range(iterations):
        r = np.array([gtsam.Pose3.Logmap(X.between(gtsam.Pose3(Ti))) for Ti in T])
        X = X.compose(gtsam.Pose3.Expmap(np.linalg.solve(H, np.einsum("kij,kj->i", W, r))))
    return X.matrix()


def alternatives(pg: PoseGraph, result, odo) -> dict[str, dict[str, np.ndarray]]:
    """to_reference by other estimators than the backend's (its first submap), from every
    submap's Tᵢ = P(r,i)·anchor(r,i)⁻¹: the plain mean, and the mean weighted by the inverse of
    (odometry drift covariance since the start + the match floor), both as left perturbations
    in the robot's map frame."""
    o = pg.options
    floor = np.diag([o.match_floor_rotation**2] * 3 + [o.match_floor_translation**2] * 3)
    weighted, plain = {}, {}
    for robot, ref in result.reference.items():
        if robot == ref:
            continue
        P = np.array([result.poses[(robot, i)] for i in range(len(odo[robot]))])
        T = P @ invert(odo[robot])
        Ad = adjoint(odo[robot])
        W = np.linalg.inv(pg._drift_prefix(robot) + Ad @ floor @ Ad.transpose(0, 2, 1))
        weighted[robot] = weighted_mean(T, W)
        plain[robot] = weighted_mean(T, np.tile(np.eye(6), (len(T), 1, 1)))
    return {"drift_weighted_mean": weighted, "unweighted_mean": plain}


def timing_summary(times: list[float], sizes: list[int], checkpoints: int = 10) -> dict:
    idx = np.linspace(0, len(times) - 1, checkpoints).round().astype(int)
    return {
        "mean_s": float(np.mean(times)),
        "p95_s": float(np.percentile(times, 95)),
        "max_s": float(np.max(times)),
        "last_s": float(times[-1]),
        "by_size": [{"submaps": sizes[k], "s": round(times[k], 4)} for k in idx],
    }


def run(args: argparse.Namespace) -> dict:
    rng = np.random.default_rng(args.seed)
    n = args.submaps // args.robots
    G = trajectories(rng, args.robots, n, args.size)
    odo = {
        r: apply_drift(invert(G[r][0]) @ G[r], Drift(seed=args.seed * 100 + k))
        for k, r in enumerate(sorted(G))
    }
    matches = make_matches(rng, G, args.radius, args.detect, args.wrong)
    order = rng.permutation(len(matches))
    info = np.linalg.inv(np.diag([MATCH_SIGMA_R**2] * 3 + [MATCH_SIGMA_T**2] * 3))
    # A match arrives in the round where its later submap does.
    by_round: dict[int, list[int]] = {}
    for k in order:
        (_, i), (_, j), _, _ = matches[k]
        by_round.setdefault(max(i, j), []).append(int(k))

    systems = {
        "robust": PoseGraph(BackendOptions()),
        "plain_lm": PoseGraph(BackendOptions(pcm=False, gnc=False)),
    }
    times = {name: [] for name in systems}
    solvers: dict[str, int] = {}
    sizes: list[int] = []
    ids: dict[str, dict[int, int]] = {name: {} for name in systems}  # edge id → match index
    results = {}
    for i in range(n):
        for name, pg in systems.items():
            start = time.perf_counter()
            for r in sorted(G):
                pg.add_submap(r, i, odo[r][i])
            for k in by_round.get(i, []):
                target, source, Z, _ = matches[k]
                ids[name][pg.add_match(target, source, Z, info, confidence=0.5)] = k
            results[name] = pg.optimize()
            times[name].append(time.perf_counter() - start)
        sizes.append(systems["robust"].n_submaps)
        solver = results["robust"].stats["solver"]
        solvers[solver] = solvers.get(solver, 0) + 1
        if args.progress and i % 10 == 0:
            print(
                f"round {i}/{n}: {sizes[-1]} submaps, {times['robust'][-1]:.3f} s", file=sys.stderr
            )

    ref = sorted(G)[0]
    truth = {r: invert(G[ref][0]) @ G[r][0] for r in sorted(G) if r != ref}
    out: dict = {
        "robots": args.robots,
        "submaps": systems["robust"].n_submaps,
        "matches_true": sum(m[3] for m in matches),
        "matches_wrong": sum(not m[3] for m in matches),
        "updates": n,
        "seed": args.seed,
    }
    for name, pg in systems.items():
        res = results[name]
        is_true = {e: matches[k][3] for e, k in ids[name].items()}
        rejected = res.rejected
        wrong_total = sum(not v for v in is_true.values())
        groups_ok = len(res.groups) == 1
        est = {r: T for r, T in res.to_reference.items() if res.reference[r] == ref}
        entry = {
            "time_per_update": timing_summary(times[name], sizes),
            "groups": res.groups,
            "to_reference_error": frame_errors(est, truth),
            "wrong_rejected": sum(not is_true[e] for e in rejected),
            "wrong_total": wrong_total,
            "true_rejected": sum(is_true[e] for e in rejected),
            "rejected_by": {
                stage: sum(1 for s in rejected.values() if s == stage) for stage in ("pcm", "gnc")
            },
            "pose_rmse_m": pose_rmse(res, G, ref),
            "stats": {k: v for k, v in res.stats.items() if k != "submaps"},
        }
        if name == "robust":
            entry["to_reference_error_alternatives"] = {
                k: frame_errors(v, truth) for k, v in alternatives(pg, res, odo).items()
            }
            entry["solver_per_update"] = solvers
        entry["all_connected"] = groups_ok
        out[name] = entry
    # The best this data allows: the true matches only, no robust stage, streamed the same way
    # (the warm batch solve), and the same stream through ISAM2 for the solver-time comparison.
    oracle = PoseGraph(BackendOptions(pcm=False, gnc=False))
    oracle_times = []
    for i in range(n):
        start = time.perf_counter()
        for r in sorted(G):
            oracle.add_submap(r, i, odo[r][i])
        for k in by_round.get(i, []):
            if matches[k][3]:
                oracle.add_match(*matches[k][:3], info)
        res = oracle.optimize()
        oracle_times.append(time.perf_counter() - start)
    est = {r: T for r, T in res.to_reference.items() if res.reference[r] == ref}
    out["oracle_lm"] = {
        "to_reference_error": frame_errors(est, truth),
        "pose_rmse_m": pose_rmse(res, G, ref),
        "all_connected": len(res.groups) == 1,
        "time_per_update": timing_summary(oracle_times, sizes),
    }
    out["oracle_isam2"] = {
        "time_per_update": timing_summary(
            isam2_times(oracle, G, odo, by_round, matches, info), sizes
        )
    }
    return out


def isam2_times(pg: PoseGraph, G, odo, by_round, matches, info) -> list[float]:
    """Per-round times of gtsam.ISAM2 (QR: Cholesky failed on these graphs) on the true-match
    stream, factors and noise models as `PoseGraph` builds them; the other robots' first
    submaps get a 10 m / 10 rad prior for a gauge (ISAM2 has no damping to fall back on)."""
    params = gtsam.ISAM2Params()
    params.setFactorization("QR")
    isam = gtsam.ISAM2(params)
    names = sorted(G)
    estimate: dict[tuple[str, int], np.ndarray] = {}
    times = []
    for i in range(len(odo[names[0]])):
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        for r in names:
            key = pg._key[(r, i)]
            if i == 0:
                sigma = 1e-4 if r == names[0] else 10.0
                noise = gtsam.noiseModel.Isotropic.Sigma(6, sigma)
                graph.add(gtsam.PriorFactorPose3(key, gtsam.Pose3(odo[r][0]), noise))
                estimate[(r, 0)] = odo[r][0]
            else:
                graph.add(pg._odometry_factors[(r, i - 1, i)])
                step = invert(odo[r][i - 1]) @ odo[r][i]
                estimate[(r, i)] = estimate[(r, i - 1)] @ step
            values.insert(key, gtsam.Pose3(estimate[(r, i)]))
        for k in by_round.get(i, []):
            target, source, Z, ok = matches[k]
            if ok:
                graph.add(
                    gtsam.BetweenFactorPose3(
                        pg._key[target],
                        pg._key[source],
                        gtsam.Pose3(Z),
                        gtsam.noiseModel.Gaussian.Information(right_information(Z, info)),
                    )
                )
        start = time.perf_counter()
        isam.update(graph, values)
        result = isam.calculateEstimate()
        times.append(time.perf_counter() - start)
        for r in names:
            estimate[(r, i)] = result.atPose3(pg._key[(r, i)]).matrix()
    return times


def pose_rmse(result, G, ref: str) -> float:
    """RMS translation error of the optimised anchors in the reference frame (robots in the
    reference's group)."""
    W = invert(G[ref][0])
    err = [
        np.linalg.norm((W @ G[r][i])[:3, 3] - P[:3, 3])
        for (r, i), P in result.poses.items()
        if result.reference[r] == ref
    ]
    return float(np.sqrt(np.mean(np.square(err))))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--robots", type=int, default=8)
    p.add_argument("--submaps", type=int, default=1000)
    p.add_argument("--size", type=float, default=60.0, help="side of the square area (m)")
    p.add_argument("--radius", type=float, default=2.0, help="true distance of a match (m)")
    p.add_argument("--detect", type=float, default=0.25, help="chance a near pair matches")
    p.add_argument("--wrong", type=float, default=0.2, help="fraction of wrong matches")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--progress", action="store_true")
    print(json.dumps(run(p.parse_args()), indent=1))


if __name__ == "__main__":
    main()
