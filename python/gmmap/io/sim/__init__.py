"""The multi-robot simulator: worlds of primitives, ray-cast sensors, robots with odometry."""

from gmmap.io.sim.robots import Motion, route_poses
from gmmap.io.sim.run import (
    UP,
    Paced,
    Sensing,
    SimRobot,
    floor_pose,
    sensed,
    simulate,
    simulate_options,
    write_pointfiles,
    write_run,
    write_tum,
)
from gmmap.io.sim.sensors import DepthCamera, Lidar, sense, sim_sensor
from gmmap.io.sim.world import Box, Cylinder, World
from gmmap.io.sim.worlds import WORLDS, get_world, load_world

__all__ = [
    "UP",
    "WORLDS",
    "Box",
    "Cylinder",
    "DepthCamera",
    "Lidar",
    "Motion",
    "Paced",
    "Sensing",
    "SimRobot",
    "World",
    "floor_pose",
    "get_world",
    "load_world",
    "route_poses",
    "sense",
    "sensed",
    "sim_sensor",
    "simulate",
    "simulate_options",
    "write_pointfiles",
    "write_run",
    "write_tum",
]
