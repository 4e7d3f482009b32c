"""Simulated exploration runs: robots move where their explorers say, in a world they do not
know; the simulator renders their sensors, checks collisions against the true world and
measures coverage against it.

Modes: ``shared`` (GMM submaps with their horizons and goals go to every robot: one
broadcast each, as on a shared channel), ``no-sharing`` (the same robots, each on its own
map) and ``dense`` (`gmmap.eval.explore.dense`: point clouds shared, a 5 cm occupancy grid).
A run with one robot is the ``alone`` baseline. Odometry is perfect here: the frames between
robots are what the explorers' mappers find (shared) or given (dense, an upper bound).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.explore.coverage import Coverage
from gmmap.fleet.wire.codec import encode
from gmmap.io.sim import DepthCamera, Lidar, World, floor_pose, load_world, sensed, sim_sensor
from gmmap.io.sim.run import EPOCH
from gmmap.mapping.explore import Explorer, SharedSubmap, moving_on, next_move
from gmmap.mapping.frontier import FreeSpace, Horizon

MODES = ("shared", "no-sharing", "dense")
FACING = 0.4  # rad: a depth camera's robot moves only within this of its heading (60° view)
CLAIM_BYTES = 16  # a position and a goal, float32 (x, y) each
Progress = Callable[[str], None]


@dataclass
class Body:
    """A simulated robot's true pose on the floor and what happened to it."""

    xy: np.ndarray
    yaw: float
    path: list[list[float]] = field(default_factory=list)
    collisions: int = 0
    blocked: bool = False

    def pose(self) -> np.ndarray:
        return floor_pose(*self.xy, self.yaw)


@dataclass
class RunResult:
    """One exploration run: the keys `gmmap explore --json` reports (see `summary`)."""

    mode: str
    world: str
    sensor: str
    robots: int
    coverage: float = 0.0
    area: float = 0.0
    time_to_90_s: float | None = None
    collisions: int = 0
    bytes_per_robot: list[int] = field(default_factory=list)
    statuses: list[str] = field(default_factory=list)
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    curve: list[tuple[float, float, float]] = field(default_factory=list)  # (t, surface, area)
    paths: list[list[list[float]]] = field(default_factory=list)

    def summary(self) -> dict:
        d = asdict(self)
        for k in ("curve", "paths"):
            d.pop(k)
        return d


def starts(world: World, n: int) -> list[tuple[float, float, float]]:
    """Where ``n`` robots start, in a file 0.8 m apart along their heading (a corridor fits
    them), the first where the world's ``start`` is, else its first route's third waypoint
    (an office's corridor); places without 30 cm of room are skipped."""
    if world.start is not None:
        x, y, yaw = world.start
    elif world.routes:
        route = world.routes[0]
        (x, y), nxt = route[min(2, len(route) - 1)], route[min(3, len(route) - 1)]
        yaw = math.atan2(nxt[1] - y, nxt[0] - x) if (nxt[0], nxt[1]) != (x, y) else 0.0
    else:
        raise InvalidInputError(f"world {world.name!r} has no start and no route")
    along = np.array([math.cos(yaw), math.sin(yaw)])
    out = []
    for k in (0, 1, -1, 2, -2, 3, -3, 4, -4):
        xy = np.array([x, y]) + k * 0.8 * along
        if world.clearance(xy[None])[0] >= 0.3:
            out.append((float(xy[0]), float(xy[1]), yaw))
        if len(out) == n:
            return out
    raise InvalidInputError(f"{world.name}: no room to start {n} robots in a file at {x, y}")


class Team:
    """The robots of one run and the loop that moves them."""

    def __init__(self, config: Config, mode: str, robots: int | None = None) -> None:
        if mode not in MODES:
            raise InvalidInputError(f"mode must be one of {MODES}, got {mode!r}")
        sim = config.sim
        self.config, self.mode = config, mode
        self.world = load_world(sim.world)
        self.sensor = sim_sensor(sim)
        self.n = robots or sim.robots
        self.bodies = [Body(np.array(s[:2]), s[2]) for s in starts(self.world, self.n)]
        self.map_to_world = [b.pose() for b in self.bodies]
        self.names = [f"robot_{i}" for i in range(self.n)]
        self.grid = None
        if mode == "dense":
            from gmmap.eval.explore.dense import DenseGrid

            self.grid = DenseGrid(self.bodies[0].xy, config.planner.z_band)
        self.agents = [self._agent(i) for i in range(self.n)]
        self.coverage = Coverage(self.world, np.array([b.xy for b in self.bodies]))
        self.bytes = [0] * self.n

    def _agent(self, i: int):
        if self.mode == "dense":
            from gmmap.eval.explore.dense import DenseExplorer

            return DenseExplorer(self.names[i], self.config, self.map_to_world[i], self.grid)
        return Explorer(self.names[i], self.config, share=self.mode == "shared")

    def run(self, progress: Progress | None = None) -> RunResult:
        sim, opt = self.config.sim, self.config.explore
        dt = 1.0 / sim.rate
        spin = 0.0 if isinstance(self.sensor, Lidar) else 2 * math.pi / opt.turn_rate
        result = RunResult(self.mode, self.world.name, type(self.sensor).__name__, self.n)
        t0, t = time.perf_counter(), 0.0
        while t < opt.time_budget:
            idle = [not moving for moving in self._tick(t, dt, spin)]
            if t - (result.curve[-1][0] if result.curve else -1e9) >= 2.0:
                self._measure(result, t, progress)
            t += dt
            if all(idle) and t > spin:
                break
        result.statuses = self._finish()
        self._measure(result, t, progress)
        result.sim_time_s, result.wall_time_s = t, time.perf_counter() - t0
        result.collisions = sum(b.collisions for b in self.bodies)
        result.bytes_per_robot = list(self.bytes)
        result.paths = [b.path for b in self.bodies]
        above = [c[0] for c in result.curve if c[1] >= 0.9]
        result.time_to_90_s = above[0] if above else None
        return result

    def _tick(self, t: float, dt: float, spin: float) -> list[bool]:
        """Every robot senses, then moves; whether each still has somewhere to go."""
        for i in range(self.n):
            seed, start = self.config.sim.seed, self.map_to_world[i]
            frame = sensed(self.sensor, self.world, seed, i, t, self.bodies[i].pose(), start)
            self._share(i, self.agents[i].observe(frame))
        return [self._move(i, t, dt, spin) for i in range(self.n)]

    def _finish(self) -> list[str]:
        """The robots stop: each shares the submap of its last frames; their statuses."""
        for i in range(self.n):
            self._share(i, self.agents[i].flush())
        return [a.status for a in self.agents]

    def _share(self, i: int, shared: SharedSubmap | None) -> None:
        if shared is None:
            return
        if self.mode == "dense":
            self.bytes[i] += shared.wire_bytes
            self.coverage.add_points(shared.points_world)
        else:
            self.bytes[i] += len(encode(shared.submap)) + shared.horizon_bytes
            self.coverage.add_gmm(shared.submap.gmm.transform(shared.submap.gt_anchor))
        for j, agent in enumerate(self.agents):
            if j != i:
                agent.receive(shared)

    def _move(self, i: int, t: float, dt: float, spin: float) -> bool:
        """One step of robot i; False when it has nowhere to go."""
        body, opt = self.bodies[i], self.config.explore
        body.path.append([round(float(body.xy[0]), 3), round(float(body.xy[1]), 3)])
        if t < spin:
            body.yaw += opt.turn_rate * dt
            return True
        direction, exploring = self._decide(i, t)
        if direction is None:
            return exploring
        # A holonomic base: it moves along the direction and turns its sensor towards it; a
        # depth camera's robot first turns until it faces where it goes (it sees only ahead).
        d = self.map_to_world[i][:2, :2] @ direction
        error = (math.atan2(d[1], d[0]) - body.yaw + math.pi) % (2 * math.pi) - math.pi
        body.yaw += max(-opt.turn_rate * dt, min(opt.turn_rate * dt, error))
        if isinstance(self.sensor, DepthCamera) and abs(error) > FACING:
            return True
        target = body.xy + self.config.sim.speed * dt * d
        radius = self.config.planner.robot_radius
        # A collision is a bump: a step refused right after a step taken (pushing on is not
        # another one).
        gap = self.world.clearance(np.array([target, body.xy]), self.config.planner.z_band)
        bump = bool(gap[0] < radius and gap[0] < gap[1])  # backing off a surface is allowed
        body.collisions += int(bump and not body.blocked)
        body.blocked = bump
        if not bump:
            body.xy = target
        return True

    def _decide(self, i: int, t: float) -> tuple[np.ndarray | None, bool]:
        """Robot i's direction of travel in its map frame (None: it stays) and whether it is
        still exploring; a goal it changed goes to its peers as a claim."""
        agent = self.agents[i]
        direction, claim = next_move(agent, EPOCH + t)
        if self.mode != "no-sharing" and claim is not None:
            self.bytes[i] += CLAIM_BYTES
            for j, other in enumerate(self.agents):
                if j != i:
                    other.receive_claim(self.names[i], claim)
        return direction, moving_on(agent.status)

    def _horizons(self) -> list[Horizon]:
        """The team's horizons in the world frame (the area it knows is free)."""
        horizons = []
        for i, agent in enumerate(self.agents):
            horizons += [h.moved(self.map_to_world[i]) for h in agent.own_horizons()]
        return horizons

    def _measure(self, result: RunResult, t: float, progress: Progress | None) -> None:
        if self.grid is not None:
            area = self.coverage.area(self.grid.known_free)
        else:
            area = self.coverage.area(FreeSpace(self._horizons()).contains)
        result.curve.append((round(t, 2), round(self.coverage.surface, 4), round(area, 4)))
        result.coverage, result.area = self.coverage.surface, area
        if progress and len(result.curve) % 10 == 0:
            progress(
                f"{self.mode}: t {t:.0f} s, surface {self.coverage.surface:.0%}, area {area:.0%}"
            )


def run_explore(
    config: Config,
    mode: str = "shared",
    robots: int | None = None,
    progress: Progress | None = None,
) -> RunResult:
    """One exploration run of ``config``'s world, sensor and robots in ``mode``."""
    return Team(config, mode, robots).run(progress)
