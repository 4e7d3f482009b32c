"""The simulator's section of the configuration (`gmmap.config`, re-exported by
`gmmap.options`). Like `gmmap.options`, nothing heavy is imported here, and each field's meaning
is its ``#:`` comment.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gmmap.errors import InvalidInputError

SENSORS = ("lidar", "depth")


@dataclass(frozen=True)
class SimOptions:
    """The simulator (`gmmap.io.sim`): which world, how many robots, which sensor, how they move.

    ``sensor``: a 16-beam 360° LiDAR over ±``lidar_fov``° of elevation (VLP-16: ±15°; a handheld
    360° LiDAR: 32-64 beams over ±45°; KITTI-like: ±25°), or a 60° depth camera ``width`` px
    wide (4:3), whose narrow views alias more. ``sway``: the carrier rolls and pitches by up to
    this many degrees as a handheld or legged robot does (0: a wheeled robot on a flat floor);
    its odometry knows the tilt, as an IMU would. ``drift``: the simulated odometry's error per
    metre driven (and rad per rad turned; `gmmap.math.drift.Drift.per_metre`), which the robots
    never see. 320 px: the depth demo at that width runs three robots in real time on two cores.
    ``pace``: None, a robot maps its frames as fast as it can; a number, frame k is due ``k /
    (rate * pace)`` s after ``start`` (Unix time; None: when the robot starts), so that robots
    move in step as in the field, however fast each maps (rendezvous links need it).
    """

    world: str = "office"  #: A built-in world, `random-office:<seed>` or a world .json file
    robots: int = 3  #: Simulated robots
    seed: int = 0  #: Seed of the sensor noise and the odometry
    sensor: str = "lidar"  #: lidar (360° LiDAR) or depth (60° depth camera)
    width: int = 320  #: Depth camera image width (px, 4:3)
    beams: int = 16  #: LiDAR channels over ±lidar_fov of elevation
    lidar_fov: float = 15.0  #: LiDAR elevation field, ± degrees
    lidar_range: float = 30.0  #: LiDAR maximum range (m)
    sway: float = 0.0  #: Carrier roll and pitch, up to ± degrees (handheld, legged; 0: flat floor)
    noise: bool = True  #: Sensor noise (depth or range)
    rate: float = 5.0  #: Frames per second
    speed: float = 0.5  #: Driving speed (m/s)
    drift: float = 0.02  #: Simulated odometry error per metre driven (and rad per rad turned)
    pace: float | None = None  #: Frames due at this many times the rate; null: as fast as mapped
    start: float | None = None  #: Unix time paced frames count from; null: when the robot starts

    def __post_init__(self) -> None:
        if self.pace is not None and not (math.isfinite(self.pace) and self.pace > 0):
            raise InvalidInputError(f"sim.pace must be > 0 or null, got {self.pace}")
        if self.sensor not in SENSORS:
            raise InvalidInputError(f"sim.sensor must be one of {SENSORS}, got {self.sensor!r}")
        if self.robots < 1 or self.width < 8 or self.beams < 1:
            raise InvalidInputError("sim.robots >= 1, sim.width >= 8, sim.beams >= 1")
        if not (self.lidar_range > 0 and self.rate > 0 and self.speed > 0 and self.drift >= 0):
            raise InvalidInputError("sim.lidar_range, rate, speed > 0 and drift >= 0")
        if not (0 < self.lidar_fov <= 90 and 0 <= self.sway < 45):
            raise InvalidInputError("sim.lidar_fov in (0, 90] and sim.sway in [0, 45) degrees")
