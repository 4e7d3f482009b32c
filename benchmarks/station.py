"""A base station watching the demo fleet: CPU, memory and view latency for 3 and 8 robots.

Beside a robot process of the same run.

Prints one JSON object. Per fleet size, ``gmmap demo --station`` (simulated robots as
processes, the station as one more, its Rerun view served and recorded): the station's CPU
seconds and peak resident memory (`gmmap.fleet.node.report.resources`, its own process), against
the mean robot process's (the baseline: the station maps every robot's submaps, a robot its
own and those it receives); the submaps it held and showed against those built; the latency
from a robot building and sending a submap to the view first showing it (clock times on one
machine; the view updates every second, which bounds it from below).

    .venv/bin/python benchmarks/station.py [--robots 3 8] [--max-frames N]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from gmmap.cli.demo import backend_follows_drift, run_demo
from gmmap.config import Config
from gmmap.fleet.net.transport import free_port


def one(robots: int, max_frames: int | None) -> dict:
    base = Config()
    ports = {"web_port": free_port(), "grpc_port": free_port()}
    config = replace(base, sim=replace(base.sim, robots=robots),
                     station=replace(base.station, **ports))  # fmt: skip
    config = backend_follows_drift(config)
    with tempfile.TemporaryDirectory() as tmp:
        say = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
        r = run_demo(config, max_frames, Path(tmp), say, station=True)
        reports = [json.loads((Path(tmp) / f"robot_{i}.json").read_text()) for i in range(robots)]
    station = r["station"]
    mine = [x["resources"] for x in reports if x.get("resources")]
    robot_cpu = statistics.mean(x["cpu_s"] for x in mine)
    robot_rss = statistics.mean(x["max_rss_mb"] for x in mine)
    held = sum(v for k, v in station["held"].items() if k != "station")
    return {
        "submaps_built": r["submaps"],
        "station_held": held,
        "station_shown": station["shown"],
        "station_groups": len(station["groups"]),
        "robot_groups": len(r["groups"]),
        "station_cpu_s": station["resources"]["cpu_s"],
        "station_max_rss_mb": station["resources"]["max_rss_mb"],
        "robot_cpu_s_mean": robot_cpu,
        "robot_max_rss_mb_mean": robot_rss,
        "cpu_vs_robot": station["resources"]["cpu_s"] / robot_cpu,
        "rss_vs_robot": station["resources"]["max_rss_mb"] / robot_rss,
        "view_latency_median_s": station["view_latency_s"]["median"],
        "view_latency_max_s": station["view_latency_s"]["max"],
        "wall_s": r["wall_s"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[3, 8], help="Fleet sizes.")
    parser.add_argument("--max-frames", type=int, help="Frames per robot (default: all).")
    args = parser.parse_args()
    out = {f"robots_{n}": one(n, args.max_frames) for n in args.robots}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
