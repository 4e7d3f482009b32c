"""Wrong joins in the simulator: seeds × robot counts × sensors, with the defaults.

Prints one JSON object: per sensor and robot count, over the seeds, the robot pairs whose maps
joined, the joined pairs whose relative pose where they met is more than 0.5 m or 5° off the
truth ("wrong"), and the matches verified and kept. A wrong merge is worse than none: the
defaults must keep "wrong" at 0. Building the submaps dominates the time (about 15 minutes for
the default 10 seeds on 2 cores), so `make bench` leaves this one out.

    .venv/bin/python benchmarks/merge_sweep.py [--seeds 10] [--robots 3,5] [--sensors lidar,depth]
"""

from __future__ import annotations

import argparse
import json
import sys

from gmmap.config import Config
from gmmap.eval.merge import merge
from gmmap.io.sim import UP, get_world, sim_sensor, simulate
from gmmap.mapping.submap import build_submaps
from gmmap.math.drift import Drift
from gmmap.options import SimOptions


def case(sensor: str, robots: int, seed: int, config: Config) -> dict:
    options = SimOptions(sensor=sensor, robots=robots, seed=seed)
    odometry = Drift.per_metre(options.drift, seed, UP)
    run = simulate(get_world("office"), robots, seed, sim_sensor(options), odometry=odometry)
    submaps = {r.name: list(build_submaps(r, r.name, config.build, config.select)) for r in run}
    _, report = merge(submaps, config)
    joined = [p for p in report["pairs"] if p["frame_t_error"] is not None]
    wrong = [
        p for p in joined if p["t_error"] is None or p["t_error"] > 0.5 or p["r_error_deg"] > 5
    ]
    return {
        "pairs": robots * (robots - 1) // 2,
        "joined": len(joined) - len(wrong),
        "wrong": len(wrong),
        "verified": report["verified"],
        "kept": report["accepted_edges"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--robots", default="3,5")
    parser.add_argument("--sensors", default="lidar,depth")
    args = parser.parse_args()
    config = Config()
    out: dict = {}
    for sensor in args.sensors.split(","):
        for robots in (int(n) for n in args.robots.split(",")):
            runs = []
            for seed in range(args.seeds):
                print(f"{sensor}, {robots} robots, seed {seed}", file=sys.stderr, flush=True)
                runs.append(case(sensor, robots, seed, config))
            total = {k: sum(r[k] for r in runs) for k in runs[0]}
            out[f"{sensor}_{robots}_robots"] = {**total, "seeds": args.seeds, "runs": runs}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
