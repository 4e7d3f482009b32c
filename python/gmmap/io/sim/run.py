"""Multi-robot simulation runs: robots driving routes through a world with a sensor, their
ground truth, and their own odometry (each in its own map frame, unknown to the others)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from gmmap.errors import InvalidInputError
from gmmap.io.datasets.ply import write_ply
from gmmap.io.datasets.trajectory import write_trajectory
from gmmap.io.datasets.tum import depth_to_points
from gmmap.io.sim.robots import Motion, route_poses
from gmmap.io.sim.sensors import DepthCamera, Lidar, sense, sim_sensor
from gmmap.io.sim.world import World
from gmmap.io.sim.worlds import load_world
from gmmap.mapping.frame import Frame
from gmmap.math.drift import Drift
from gmmap.options import SimOptions

Sensor = DepthCamera | Lidar
Progress = Callable[[int], None]
# Stamps start at a fixed epoch so runs are reproducible byte for byte.
EPOCH = 1_700_000_000.0
# The worlds' vertical. Simulated robots drive on the floor with an IMU: give their `Drift` this
# ``up`` and only heading and position drift, not roll and pitch.
UP = (0.0, 0.0, 1.0)


@dataclass
class SimRobot(Sequence):
    """One simulated robot: a lazy sequence of Frames, rendered on access (deterministic).

    ``gt_poses`` are sensor→world; ``odom_poses`` sensor→map, where the robot's map frame is
    its start pose on the floor (gravity-aligned); ``map_to_world`` relates the two.
    Depth frames are back-projected with ``min_range``/``max_range`` as the TUM loader does.
    """

    name: str
    number: int  # the robot's index in the run (seeds its noise)
    world: World
    sensor: Sensor
    stamps: np.ndarray
    gt_poses: np.ndarray
    odom_poses: np.ndarray
    map_to_world: np.ndarray
    seed: int
    min_range: float = 0.1
    max_range: float = 5.0

    def __len__(self) -> int:
        return len(self.stamps)

    def _rng(self, i: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, self.number, i])

    def depth_raw(self, i: int) -> np.ndarray:
        """Frame i's depth image as a TUM PNG stores it: uint16, metres × depth_factor."""
        if not isinstance(self.sensor, DepthCamera):
            raise InvalidInputError(f"{self.name}: the sensor is not a depth camera")
        depth = self.sensor.render(self.world, self.gt_poses[i], self._rng(i))
        return np.round(depth * self.sensor.depth_factor).astype(np.uint16)

    def points(self, i: int) -> np.ndarray:
        if isinstance(self.sensor, Lidar):
            return self.sensor.scan(self.world, self.gt_poses[i], self._rng(i))
        return depth_to_points(
            self.depth_raw(i),
            self.sensor.intrinsics,
            self.sensor.depth_factor,
            1,
            self.min_range,
            self.max_range,
        )

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = range(len(self))[i]
        return Frame(
            float(self.stamps[i]),
            self.points(i),
            self.odom_poses[i].copy(),
            self.gt_poses[i].copy(),
        )


class Paced(Sequence):
    """A robot's frames, each released once its stamp has come on the wall clock: frame k
    ``(stamp_k - stamp_0) / pace`` s after ``start`` (Unix time). A frame asked for late is
    released at once: a robot that maps slower than it moves falls behind, as on a robot."""

    def __init__(self, robot: SimRobot, pace: float, start: float) -> None:
        self.robot, self.pace, self.start = robot, pace, start

    def __len__(self) -> int:
        return len(self.robot)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = range(len(self))[i]
        stamps = self.robot.stamps
        wait = self.start + (stamps[i] - stamps[0]) / self.pace - time.time()
        if wait > 0:
            time.sleep(wait)
        return self.robot[i]


OdometryModel = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def simulate(
    world: World,
    robots: int = 3,
    seed: int = 0,
    sensor: Sensor | None = None,
    motion: Motion | None = None,
    odometry: OdometryModel | None = None,
    max_frames: int | None = None,
) -> list[SimRobot]:
    """Plans the run: one robot per route of the world (then the routes reversed).

    ``odometry(true_poses, rng) -> poses`` turns each robot's true sensor→map poses into its
    odometry (None: perfect odometry). ``max_frames`` keeps only each robot's first frames.
    """
    sensor = sensor or DepthCamera()
    motion = motion or Motion()
    routes = [*world.routes, *(list(reversed(r)) for r in world.routes)]
    if not 1 <= robots <= len(routes):
        raise InvalidInputError(
            f"world {world.name!r} has routes for 1 to {len(routes)} robots, not {robots}"
        )
    run = []
    for i in range(robots):
        body = route_poses(routes[i], motion)[:max_frames]
        gt = body @ sensor.mount()
        map_to_world = upright(body[0])  # a swaying carrier's map frame is still level
        true_odom = np.linalg.inv(map_to_world) @ gt
        rng = np.random.default_rng([seed, i, 1 << 20])
        odom = odometry(true_odom, rng) if odometry else true_odom
        stamps = EPOCH + np.arange(len(body)) / motion.rate
        run.append(SimRobot(f"robot_{i}", i, world, sensor, stamps, gt, odom, map_to_world, seed))
    return run


def upright(pose: np.ndarray) -> np.ndarray:
    """``pose`` with its roll and pitch taken out: the heading about +z and the position."""
    out = np.eye(4)
    yaw = np.arctan2(pose[1, 0], pose[0, 0])
    out[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    out[:3, 3] = pose[:3, 3]
    return out


def write_tum(robot: SimRobot, folder: str | Path, progress: Progress | None = None) -> None:
    """Writes a TUM RGB-D style folder: depth/*.png, depth.txt, groundtruth.txt (world frame),
    odometry.txt (the robot's map frame) and intrinsics.txt; `datasets.open` reads it back."""
    cam = robot.sensor
    if not isinstance(cam, DepthCamera):
        raise InvalidInputError("TUM folders hold depth images; use a DepthCamera")
    folder = Path(folder)
    (folder / "depth").mkdir(parents=True, exist_ok=True)
    names = [f"depth/{s:.6f}.png" for s in robot.stamps]
    for i, name in enumerate(names):
        Image.fromarray(robot.depth_raw(i)).save(folder / name)
        if progress:
            progress(i)
    lines = [f"{s:.6f} {n}" for s, n in zip(robot.stamps, names, strict=True)]
    (folder / "depth.txt").write_text("# timestamp filename\n" + "\n".join(lines) + "\n")
    write_trajectory(folder / "groundtruth.txt", robot.stamps, robot.gt_poses)
    write_trajectory(folder / "odometry.txt", robot.stamps, robot.odom_poses)
    (folder / "intrinsics.txt").write_text(f"{cam.fx} {cam.fy} {cam.cx} {cam.cy}\n")


def write_pointfiles(robot: SimRobot, folder: str | Path, progress: Progress | None = None) -> None:
    """Writes a point-file folder: one binary PLY per scan named by its stamp (float32 x y z in
    the sensor frame), poses.txt (odometry, the robot's map frame) and groundtruth.txt (world
    frame); `datasets.open` reads it back with pose = odometry and gt_pose = ground truth."""
    if not isinstance(robot.sensor, Lidar):
        raise InvalidInputError("point-file folders hold LiDAR scans; use a Lidar")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for i, stamp in enumerate(robot.stamps):
        # The loader matches files to poses by the stamp in the name: the same 6 decimals as
        # the trajectory files.
        write_ply(folder / f"{stamp:.6f}.ply", robot.points(i), comment=f"gmmap sim {robot.name}")
        if progress:
            progress(i)
    write_trajectory(folder / "poses.txt", robot.stamps, robot.odom_poses)
    write_trajectory(folder / "groundtruth.txt", robot.stamps, robot.gt_poses)


def writer_for(sensor: Sensor) -> Callable[[SimRobot, str | Path, Progress | None], None]:
    """The folder format of a sensor: TUM RGB-D for depth cameras, point files for LiDARs."""
    return write_pointfiles if isinstance(sensor, Lidar) else write_tum


def write_run(
    run: list[SimRobot],
    out: str | Path,
    seed: int,
    progress: Callable[[str, int, int], None] | None = None,
    **info: object,
) -> dict:
    """Writes every robot's folder (``write_tum`` or ``write_pointfiles``, by sensor), the world
    file and ``sim.json`` (the run's metadata, including each robot's map→world transform: the
    ground truth the robots do not know). Keyword arguments are recorded in sim.json too (e.g.
    the drift parameters)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for r in run:
        step = (lambda i, r=r: progress(r.name, i + 1, len(r))) if progress else None
        writer_for(r.sensor)(r, out / r.name, step)
    run[0].world.save(out / "world.json")
    meta = {
        "world": run[0].world.name,
        "seed": seed,
        "sensor": type(run[0].sensor).__name__,
        **info,
        "robots": [
            {"name": r.name, "frames": len(r), "map_to_world": r.map_to_world.tolist()} for r in run
        ],
    }
    (out / "sim.json").write_text(json.dumps(meta, indent=1))
    return meta


def simulate_options(options: SimOptions, max_frames: int | None = None) -> list[SimRobot]:
    """`simulate` as the ``sim`` section of the configuration describes it."""
    o = options
    world = load_world(o.world)
    drift = Drift.per_metre(o.drift, o.seed, UP)
    motion = Motion(speed=o.speed, rate=o.rate, sway=o.sway)
    return simulate(world, o.robots, o.seed, sim_sensor(o), motion, drift, max_frames)


def sensed(
    sensor: DepthCamera | Lidar,
    world: World,
    seed: int,
    i: int,
    t: float,
    body: np.ndarray,
    start: np.ndarray,
) -> Frame:
    """Robot i's frame at time t of a run: its sensor's points with the body at ``body``
    (4x4, world; the frame's ``gt_pose``), its odometry perfect from ``start`` (its map frame
    in the world). The noise depends on (seed, i, t) alone: a robot renders the same frame
    in its own process as in the simulator's."""
    gt = body @ sensor.mount()
    rng = np.random.default_rng([seed, i, round(t * 1000)])
    return Frame(EPOCH + t, sense(sensor, world, gt, rng), np.linalg.inv(start) @ gt, gt)


def floor_pose(x: float, y: float, yaw: float) -> np.ndarray:
    """A ground robot's body pose (4x4) at (x, y) on the floor, heading ``yaw``."""
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = x, y
    return T


class Sensing:
    """Robot ``index``'s frames in an exploration run of the ``sim`` section's world and
    sensor, at the true floor poses it is given (x, y, yaw), its odometry perfect from the
    first (its map frame)."""

    def __init__(self, options: SimOptions, index: int) -> None:
        self.world, self.sensor = load_world(options.world), sim_sensor(options)
        self.seed, self.index = options.seed, index
        self.start: np.ndarray | None = None

    def __call__(self, t: float, x: float, y: float, yaw: float) -> Frame:
        body = floor_pose(x, y, yaw)
        if self.start is None:
            self.start = body
        return sensed(self.sensor, self.world, self.seed, self.index, t, body, self.start)
