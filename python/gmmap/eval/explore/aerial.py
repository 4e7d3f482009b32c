"""Simulated exploration in 3D: an aerial robot with a 360° LiDAR in a world it does not know
(its sensor: 32 beams over ±45°, the range and noise of the ``sim`` section).

The robot is a ball of the planner's radius that flies where its `AerialExplorer` says, at the
simulator's speed, holding its heading (a spinning LiDAR sees all round). Its odometry is
perfect and its map frame is the world's, so coverage is measured by placing its submaps where
they are. A collision is a step that would bring the ball nearer to a shape than its radius
(checked against the true world; such a step is refused, as a bump).
"""

from __future__ import annotations

import time

import numpy as np

from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.explore.coverage import AerialCoverage
from gmmap.eval.explore.team import Progress, RunResult, starts
from gmmap.fleet.wire.codec import encode
from gmmap.io.sim import Lidar, load_world
from gmmap.io.sim.run import EPOCH
from gmmap.mapping.aerial.explorer import AerialExplorer, SphereSubmap
from gmmap.mapping.aerial.space import swept_cells
from gmmap.mapping.frame import Frame

START_HEIGHT = 1.2  # metres above the floor the robot takes off to


def run_aerial(config: Config, progress: Progress | None = None) -> RunResult:
    """One aerial exploration run of ``config``'s world (one robot, its LiDAR)."""
    sim, opt, planner = config.sim, config.explore, config.planner
    world = load_world(sim.world)
    if sim.sensor != "lidar":
        raise InvalidInputError("the aerial robot carries a 360° LiDAR: use --sensor lidar")
    # A 32-beam ±45° LiDAR (a Hesai XT32-like dome): a VLP-16's ±15° would leave an aerial
    # robot blind to most of the floor and ceiling it flies between.
    sensor = Lidar(32, 45.0, -45.0, max_range=sim.lidar_range, noise_std=0.01 * sim.noise)
    x, y, _ = world.start or starts(world, 1)[0]
    position = np.array([x, y, START_HEIGHT])
    # A beam that returns nothing met nothing within its range, or something nearer than its
    # minimum range (a wall the robot brushes): only the minimum is safe to call free.
    explorer = AerialExplorer(
        "robot_0", swept_cells(sensor.fov_down, sensor.fov_up), sensor.min_range, config
    )
    coverage = AerialCoverage(world, position, planner.robot_radius + planner.margin)
    result = RunResult("shared", world.name, "Lidar", 1)
    dt, step = 1.0 / sim.rate, sim.speed / sim.rate
    sent, path, blocked, t, t0 = 0, [], False, 0.0, time.perf_counter()

    def share(shared: SphereSubmap | None) -> int:
        if shared is None:
            return 0
        coverage.add_gmm(shared.submap.gmm.transform(shared.submap.gt_anchor))
        return len(encode(shared.submap)) + shared.horizon_bytes

    def measure() -> None:
        area = coverage.area(lambda p: explorer.space().contains(p))
        result.curve.append((round(t, 2), round(coverage.surface, 4), round(area, 4)))
        result.coverage, result.area = coverage.surface, area
        if progress and len(result.curve) % 10 == 0:
            progress(f"aerial: t {t:.0f} s, surface {coverage.surface:.0%}, space {area:.0%}")

    while t < opt.time_budget:
        pose = np.eye(4)
        pose[:3, 3] = position
        rng = np.random.default_rng([sim.seed, round(t * 1000)])
        points = sensor.scan(world, pose, rng)
        sent += share(explorer.observe(Frame(EPOCH + t, points, pose, pose)))
        path.append([round(float(v), 3) for v in position])
        direction = explorer.next_direction(EPOCH + t, step)
        if direction is None and explorer.status != "exploring":
            break
        if direction is not None:
            target = position + step * direction
            gap = world.distance(np.array([target, position]))
            bump = bool(gap[0] < planner.robot_radius and gap[0] < gap[1])
            result.collisions += int(bump and not blocked)
            blocked = bump
            if not bump:
                position = target
        if t - (result.curve[-1][0] if result.curve else -1e9) >= 2.0:
            measure()
        t += dt
    sent += share(explorer.flush())
    measure()
    result.sim_time_s, result.wall_time_s = t, time.perf_counter() - t0
    result.bytes_per_robot, result.statuses, result.paths = [sent], [explorer.status], [path]
    above = [c[0] for c in result.curve if c[1] >= 0.9]
    result.time_to_90_s = above[0] if above else None
    return result
