"""Fleet scaling: how bytes, CPU and memory per robot grow from 2 to 8 robots.

Prints one JSON object. For each fleet size the whole demo runs (``gmmap.cli.demo.run_demo``:
simulated robots in the office world as separate ``gmmap robot`` processes on loopback Zenoh,
16-beam LiDAR, 20 frames per submap). Per robot: payload bytes sent and received, the
bytes a point-cloud system would send for the same submaps (voxelised points as float32, the
baseline of the paper's Fig. 9), CPU seconds (user + system) and peak resident memory, read by
each robot process from getrusage at its end; and how right the kept registrations, the
robot pairs where they met and their map frames are. Robots beyond the office's five routes
drive them in reverse.

    .venv/bin/python benchmarks/fleet.py [--robots 2,4,6,8] [--max-frames N]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

from gmmap.cli.demo import backend_follows_drift, run_demo
from gmmap.config import Config
from gmmap.options import RobotOptions, SimOptions


def per_robot(values: dict) -> dict:
    vals = [v for v in values.values() if v is not None]
    return {"mean": statistics.mean(vals), "max": max(vals)} if vals else {}


def worst(pairs: list[dict]) -> dict:
    keys = ("t_error", "r_error_deg", "frame_t_error", "frame_r_error_deg")
    return {"n": len(pairs), **{k: max(p[k] for p in pairs) for k in keys if pairs}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="2,4,6,8")
    parser.add_argument("--max-frames", type=int, default=None)
    args = parser.parse_args()
    rows = []
    for n in (int(x) for x in args.robots.split(",")):
        with tempfile.TemporaryDirectory() as out:
            config = backend_follows_drift(
                Config(sim=SimOptions(robots=n), robot=RobotOptions(linger=3.0))
            )
            r = run_demo(config, args.max_frames, Path(out), lambda m: print(m, file=sys.stderr))
        res = r["resources"]
        bpsm = r["bytes_per_submap"]
        submaps_per_robot = r["submaps"] / n
        rows.append(
            {
                "robots": n,
                "wall_s": round(r["wall_s"], 1),
                "submaps_per_robot": submaps_per_robot,
                "bytes_sent": per_robot(r["bytes_sent"]),
                "bytes_received": per_robot(r["bytes_received"]),
                "points_float32_sent_equivalent": submaps_per_robot * bpsm["points_float32"],
                "cpu_s": per_robot({k: v and v["cpu_s"] for k, v in res.items()}),
                "max_rss_mb": per_robot({k: v and v["max_rss_mb"] for k, v in res.items()}),
                "groups": r["groups"],
                "kept_matches_vs_truth": r["match_errors"],
                # Pairs with kept matches between them, and pairs joined only through others
                # (measured at their nearest submaps).
                "pairs_vs_truth_max": {
                    kind: worst([p for p in r["pairs"] if p["t_error"] is not None and test(p)])
                    for kind, test in (
                        ("matched", lambda p: p["matches"] > 0),
                        ("through_others", lambda p: p["matches"] == 0),
                    )
                },
            }
        )
        print(json.dumps(rows[-1]), file=sys.stderr)
    print(json.dumps({"world": "office", "fleets": rows}, indent=1))


if __name__ == "__main__":
    main()
