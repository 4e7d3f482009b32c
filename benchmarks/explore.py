"""Exploration: robots sharing GMM submaps against one robot alone, the same robots without
sharing, and frontier exploration on a 5 cm grid from shared point clouds (dense), on the same
worlds in the same run.

Prints one JSON object: per case (world x sensor) each run's coverage (surface within 10 cm
of the map, and floor known free), time to 90 % surface coverage, collisions and bytes, and
the ratios the issue sets goals for: ``speedup_vs_alone`` (alone's time to 90 % over the
team's), ``time_vs_dense`` (the team's over dense's) and ``bytes_dense_over_gmm``. The worlds
are procedural offices never used while the explorer was written (it was tried on ``office``
and ``passage``).

``processes`` (``--processes random-office:101``): the team sharing GMMs with each robot a
``gmmap robot --explore`` process over Zenoh (`gmmap explore`'s default) and in one process
(the rest of this benchmark), on the same world: coverage, collisions, bytes and wall time.
``sweep`` (``--sweep random-office:103,...``): the team alone on more worlds and sensors
(``--sweep-sensors``, ``--sweep-budget`` simulated seconds): collisions, coverage, time to
90 % and each robot's status at the end. ``aerial`` (``--aerial two-storey``): one aerial
robot exploring in 3D (`gmmap explore --aerial`), surfaces at every height; there is no
baseline for it. ``collisions`` counts every run of all parts.

    .venv/bin/python benchmarks/explore.py [--worlds random-office:101,...] [--sensors lidar]
        [--sweep random-office:103,...] [--sweep-sensors lidar,depth] [--sweep-budget 150]
        [--processes random-office:101] [--processes-sensors lidar] [--processes-budget 150]
        [--aerial two-storey] [--aerial-budget 300]
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace

from gmmap.config import Config
from gmmap.eval.explore.aerial import run_aerial
from gmmap.eval.explore.processes import run_processes
from gmmap.eval.explore.team import run_explore

MODES = {"gmm": ("shared", None), "alone": ("shared", 1), "no_sharing": ("no-sharing", None)}
MODES["dense"] = ("dense", None)


def ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None or b == 0 else round(a / b, 3)


def configured(world: str, sensor: str, robots: int, budget: float) -> Config:
    base = Config()
    return replace(
        base,
        sim=replace(base.sim, world=world, sensor=sensor, robots=robots),
        explore=replace(base.explore, time_budget=budget),
    )


def case(world: str, sensor: str, robots: int, budget: float) -> dict:
    config = configured(world, sensor, robots, budget)
    runs = {}
    for name, (mode, n) in MODES.items():
        print(f"{world} {sensor}: {name}", file=sys.stderr)
        runs[name] = run_explore(config, mode, n).summary()
    gmm, alone, dense = runs["gmm"], runs["alone"], runs["dense"]
    return {
        "world": world,
        "sensor": sensor,
        "robots": robots,
        "runs": runs,
        "speedup_vs_alone": ratio(alone["time_to_90_s"], gmm["time_to_90_s"]),
        "time_vs_dense": ratio(gmm["time_to_90_s"], dense["time_to_90_s"]),
        "bytes_dense_over_gmm": ratio(sum(dense["bytes_per_robot"]), sum(gmm["bytes_per_robot"])),
    }


def sweep(worlds: list[str], sensors: list[str], robots: int, budget: float) -> dict:
    """The team alone on more worlds: collisions, and whether each run ends or explores on."""
    runs = []
    for world in worlds:
        for sensor in sensors:
            print(f"sweep {world} {sensor}", file=sys.stderr)
            r = run_explore(configured(world, sensor, robots, budget), "shared").summary()
            keep = ("world", "sensor", "coverage", "time_to_90_s", "collisions", "statuses")
            runs.append({k: r[k] for k in keep})
            print(f"  {json.dumps(runs[-1])}", file=sys.stderr)  # a cut run keeps what ended
    return {
        "budget_s": budget,
        "runs": runs,
        "collisions": sum(r["collisions"] for r in runs),
        "reached_90": sum(r["time_to_90_s"] is not None for r in runs),
    }


def processes(worlds: list[str], sensors: list[str], robots: int, budget: float) -> dict:
    """The team as robot processes and in one process: the same exploration, its wall time."""
    runs = []
    keep = ("coverage", "time_to_90_s", "collisions", "bytes_per_robot", "wall_time_s")
    for world in worlds:
        for sensor in sensors:
            config = configured(world, sensor, robots, budget)
            print(f"processes {world} {sensor}", file=sys.stderr)
            apart = run_processes(config).summary()
            print(f"in one process {world} {sensor}", file=sys.stderr)
            together = run_explore(config, "shared").summary()
            runs.append(
                {
                    "world": world,
                    "sensor": sensor,
                    "processes": {k: apart[k] for k in keep},
                    "in_process": {k: together[k] for k in keep},
                    "wall_processes_over_in_process": ratio(
                        apart["wall_time_s"], together["wall_time_s"]
                    ),
                }
            )
    collisions = sum(r[m]["collisions"] for r in runs for m in ("processes", "in_process"))
    return {"budget_s": budget, "robots": robots, "runs": runs, "collisions": collisions}


def aerial(worlds: list[str], budget: float) -> list[dict]:
    """One aerial robot per world, in 3D."""
    out = []
    for world in worlds:
        print(f"aerial {world}", file=sys.stderr)
        r = run_aerial(configured(world, "lidar", 1, budget)).summary()
        out.append({**r, "budget_s": budget})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default="random-office:101,random-office:102")
    parser.add_argument("--sensors", default="lidar")
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--budget", type=float, default=300.0, help="simulated seconds")
    parser.add_argument("--sweep", default="", help="more worlds, the team alone (collisions)")
    parser.add_argument("--sweep-sensors", default="lidar,depth")
    parser.add_argument("--sweep-budget", type=float, default=150.0, help="simulated seconds")
    parser.add_argument("--processes", default="", help="worlds run as robot processes too")
    parser.add_argument("--processes-sensors", default="lidar")
    parser.add_argument("--processes-budget", type=float, default=150.0, help="simulated seconds")
    parser.add_argument("--aerial", default="", help="worlds an aerial robot explores in 3D")
    parser.add_argument("--aerial-budget", type=float, default=300.0, help="simulated seconds")
    args = parser.parse_args()
    cases = [
        case(w, s, args.robots, args.budget)
        for w in filter(None, args.worlds.split(","))
        for s in args.sensors.split(",")
    ]
    out = {"cases": cases, "budget_s": args.budget}
    if args.sweep:
        sensors = args.sweep_sensors.split(",")
        out["sweep"] = sweep(args.sweep.split(","), sensors, args.robots, args.sweep_budget)
    if args.processes:
        sensors = args.processes_sensors.split(",")
        worlds = args.processes.split(",")
        out["processes"] = processes(worlds, sensors, args.robots, args.processes_budget)
    if args.aerial:
        out["aerial"] = aerial(args.aerial.split(","), args.aerial_budget)
    in_cases = sum(r["collisions"] for c in cases for r in c["runs"].values())
    in_aerial = sum(r["collisions"] for r in out.get("aerial", []))
    parts = sum(out.get(k, {}).get("collisions", 0) for k in ("sweep", "processes"))
    out["collisions"] = in_cases + parts + in_aerial
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
