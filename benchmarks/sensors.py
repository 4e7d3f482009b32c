"""The sensor matrix: does the front end join maps on every sensor, and never wrongly?

Prints one JSON object. Per simulated setup (the office, drifting odometry, the defaults) and
seed, and per real cross-session case, through `gmmap.eval.sessions.evaluate_sessions`:

- ``pairs`` (robot pairs), ``met`` (robot pairs with at least one overlapping submap pair at
  the truth: `gmmap.eval.place.positives`), ``joined`` (met pairs whose map frames are within
  0.5 m and 5° where they met) and ``wrong`` (joined pairs farther off): a wrong join is
  worse than none;
- ``verified``, ``precision`` and ``recall`` of the verified matches (`evaluate_sessions`),
  beside the points + GICP verification on the same candidates (``gicp``: candidates it
  registers right; its recall at full precision scored by its inlier fraction);
- ``bytes_median`` per submap on the wire (`gmmap.encode`), ``bytes_per_metre`` of odometry
  path (all robots' submaps over all robots' paths), ``eval_time_per_candidate_s``
  (the whole evaluation per candidate: the merge, the GICP baseline and the floor);
- ``no_guess``: registration with no initial guess on the pairs that overlap, right and time per
  pair, gmmap's beside KISS-Matcher's on the same pairs, gmmap's as verification registers (its
  solutions that fill seen free space dropped), and gmmap's started at the truth (the most any
  search on its objective can reach; `gmmap.eval.noguess`).

Setups: ``lidar16`` (16 beams over ±15°, 5 Hz, a wheeled robot), ``lidar360_2hz`` and
``lidar360_10hz`` (32 beams over ±45°, 10° of roll and pitch: a handheld 360° LiDAR),
``depth`` (the 60° depth camera, 320 px, 5 Hz). Real (`real`): TUM fr1_xyz's first 400
frames against the recording re-sampled at 10 Hz from frame 201 (`benchmarks/merge.py`'s
case), and TUM fr3 cabinet's keyframes split into two overlapping halves of its loop. Building the
submaps and the baselines dominate the time: 1-4 minutes per 3-robot case on 2 cores (22
minutes for the defaults), so `make bench` leaves this one out.

    .venv/bin/python benchmarks/sensors.py [--seeds 3] [--robots 3] [--setups lidar16,...]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from gmmap import encode
from gmmap.config import Config
from gmmap.eval.sessions import evaluate_sessions
from gmmap.io import datasets
from gmmap.io.sim import simulate_options
from gmmap.mapping.submap import build_submaps
from gmmap.options import SimOptions

DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
HANDHELD = {"beams": 32, "lidar_fov": 45.0, "sway": 10.0}
SETUPS = {
    "lidar16": {"sensor": "lidar"},
    "lidar360_2hz": {"sensor": "lidar", "rate": 2.0, **HANDHELD},
    "lidar360_10hz": {"sensor": "lidar", "rate": 10.0, **HANDHELD},
    "depth": {"sensor": "depth"},
}
REAL = {
    "tum_fr1_xyz_second_session_10hz": (
        "tum_fr1_xyz",
        lambda f: {"a": f[0:400], "b": [f[i] for i in range(201, len(f), 3)]},
    ),
    "tum_fr3_cabinet_halves": (
        "tum_fr3_cabinet_keyframes",
        lambda f: {"a": f[0:35], "b": f[25 : len(f)]},
    ),
}
WRONG = (0.5, 5.0)  # m, degrees: a joined pair's frame error beyond this is a wrong join


def path_length(poses: np.ndarray) -> float:
    """Metres of path through (M, 4, 4) poses."""
    return float(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum())


def case(sessions: dict, config: Config, metres: float) -> dict:
    start = time.perf_counter()
    r = evaluate_sessions(sessions, config)
    elapsed = time.perf_counter() - start
    robots = sorted(sessions)
    met = r["positives_by_robots"]
    joined = [p for p in r["merge"].get("pairs", []) if p["frame_t_error"] is not None]
    wrong = [p for p in joined if p["t_error"] is None or p["t_error"] > WRONG[0]
             or p["r_error_deg"] > WRONG[1]]  # fmt: skip
    sizes = [len(encode(s)) for subs in sessions.values() for s in subs]
    return {
        "submaps": {name: len(subs) for name, subs in sessions.items()},
        "pairs": len(robots) * (len(robots) - 1) // 2,
        "met": len(met),
        "joined": len(joined) - len(wrong),
        "wrong": len(wrong),
        **{k: r[k] for k in ("positives", "candidates", "verified", "precision", "recall")},
        "registered_right": r["candidates_registered_right"],
        "gicp": r["gicp"],
        "no_guess": r["no_guess"],
        "bytes_median": float(np.median(sizes)),
        "bytes_per_metre": sum(sizes) / metres,
        "eval_time_per_candidate_s": elapsed / max(1, r["candidates"]),
    }


def simulated_sessions(setup: str, robots: int, seed: int, config: Config) -> tuple[dict, float]:
    """Each simulated robot's submaps, and the metres of odometry path of them all."""
    run = simulate_options(SimOptions(robots=robots, seed=seed, **SETUPS[setup]))
    sessions = {r.name: list(build_submaps(r, r.name, config.build, config.select)) for r in run}
    return sessions, sum(path_length(r.odom_poses) for r in run)


def simulated(setup: str, robots: int, seed: int, config: Config) -> dict:
    sessions, metres = simulated_sessions(setup, robots, seed, config)
    return case(sessions, config, metres)


def real(config: Config) -> dict:
    """Two sessions of one real recording each, split where they overlap: TUM fr1_xyz's first
    400 frames against the recording re-sampled at 10 Hz from frame 201 (a desk), and TUM fr3
    cabinet's keyframes 0-34 against 25-57 (a loop round a box whose sides look alike)."""
    out: dict = {}
    for name in REAL:
        built = real_sessions(name, config)
        if built is None:
            out[name] = {"skipped": f"{DATA / REAL[name][0]} not found"}
        else:
            out[name] = case(built[0], config, built[1])
    return out


def real_sessions(name: str, config: Config) -> tuple[dict, float] | None:
    """The two sessions of real case ``name`` (`REAL`) and their metres of path; None where
    its recording is absent."""
    folder, split = REAL[name]
    if not (DATA / folder).exists():
        return None
    parts = split(datasets.open(DATA / folder))
    sessions = {
        robot: list(build_submaps(part, robot, config.build, config.select))
        for robot, part in parts.items()
    }
    return sessions, sum(path_length(np.array([f.pose for f in part])) for part in parts.values())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--robots", default="3")
    parser.add_argument("--setups", default=",".join(SETUPS))
    args = parser.parse_args()
    config = Config()
    out: dict = {}
    for setup in args.setups.split(","):
        for robots in (int(n) for n in args.robots.split(",")):
            runs = []
            for seed in range(args.seeds):
                print(f"{setup}, {robots} robots, seed {seed}", file=sys.stderr, flush=True)
                runs.append(simulated(setup, robots, seed, config))
            out[f"{setup}_{robots}_robots"] = {**totals(runs), "seeds": args.seeds, "runs": runs}
    print("real cross-session cases", file=sys.stderr, flush=True)
    out["real"] = real(config)
    print(json.dumps(out, indent=1))


def totals(runs: list[dict]) -> dict:
    """Sums over the seeds, and the verified precision over all of them."""
    keys = ("pairs", "met", "joined", "wrong", "positives", "verified", "registered_right")
    total = {k: sum(r[k] for r in runs) for k in keys}
    total["gicp_registered_right"] = sum(r["gicp"]["candidates_registered_right"] for r in runs)
    right = sum(round((r["precision"] or 0) * r["verified"]) for r in runs)
    total["precision"] = right / total["verified"] if total["verified"] else None
    total["recall"] = right / total["positives"] if total["positives"] else None
    pairs = sum(r["no_guess"]["pairs"] for r in runs)
    for method in ("gmmap", "gmmap_free_space", "from_truth", "kiss_matcher"):
        done = [r["no_guess"][method] for r in runs if "right" in r["no_guess"][method]]
        total[f"no_guess_{method}"] = {
            "right": sum(d["right"] for d in done) if done else None,
            "pairs": pairs,
            "time_s": float(np.mean([d["time_s"] for d in done])) if done else None,
        }
    total["bytes_median"] = float(np.median([r["bytes_median"] for r in runs]))
    total["bytes_per_metre"] = float(np.median([r["bytes_per_metre"] for r in runs]))
    return total


if __name__ == "__main__":
    main()
