"""Planner: time per step of the GMM gradient-field planner against the A* baseline.

Prints one JSON object. Each of the paper's four scenes is mapped once (the normal pipeline,
``gmmap.eval.planner.map_scene``); then, on the same map, the GMM planner's run and A*'s full
plan on the 5 cm grid of the same scans (what a planner that replans every step pays) are timed
``--repeat`` times and the medians compared: ``astar_over_gmm`` is how many GMM steps one A*
plan costs. Also how the GMM step cost grows with the map's component count (the scene's map
concatenated with shifted copies of itself).

    .venv/bin/python benchmarks/planner.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from gmmap.eval.planner import SCENES, astar, map_scene, occupancy_grid, shortcut
from gmmap.io.sim import get_world
from gmmap.mapping.planner import GradientPlanner, PlannerOptions
from gmmap.mapping.submap import concatenate


def timed(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    options = PlannerOptions()
    out: dict = {"robot_radius": options.robot_radius, "scenes": {}}
    for name in SCENES:
        world = get_world(name)
        scene = map_scene(world)
        start, goal = np.array(world.start[:2]), np.array(world.goal)
        run = GradientPlanner(scene.gmm, options).plan(start, goal)
        grid = occupancy_grid(scene.points, options.robot_radius, options.z_band)

        def gmm_run(g=scene.gmm, a=start, b=goal):
            return GradientPlanner(g, options).plan(a, b)

        def astar_run(g=grid, a=start, b=goal):
            return shortcut(g, astar(g, a, b))

        gmm_total, astar_plan = timed(gmm_run, args.repeat), timed(astar_run, args.repeat)
        per_step = gmm_total / max(run.steps, 1)
        out["scenes"][name] = {
            "components": len(scene.gmm),
            "gmm_steps": run.steps,
            "gmm_time_per_step_s": per_step,
            "astar_plan_s": astar_plan,
            "astar_over_gmm": round(astar_plan / per_step, 1),
        }
    world = get_world("clutter")
    base = map_scene(world).gmm
    planner_xy = np.array(world.start[:2])
    scaling = []
    for copies in (1, 4, 16):
        shifted = [base.transform(_shift(20.0 * i)) for i in range(copies)]
        planner = GradientPlanner(concatenate(shifted), options)
        t = timed(lambda p=planner: p.choose(planner_xy, np.array(world.goal)), 50)
        scaling.append({"components": len(base) * copies, "choose_s": t})
    out["step_time_vs_components"] = scaling
    print(json.dumps(out, indent=1))


def _shift(x: float) -> np.ndarray:
    t = np.eye(4)
    t[0, 3] = x
    return t


if __name__ == "__main__":
    main()
