"""The multi-robot simulator: worlds of primitives, ray-cast sensors, robots with odometry."""

from gmmap.sim.robots import Motion, route_poses
from gmmap.sim.run import UP, SimRobot, simulate, write_pointfiles, write_run, write_tum
from gmmap.sim.sensors import ROBOT_SENSORS, DepthCamera, Lidar, robot_sensor
from gmmap.sim.world import Box, Cylinder, World
from gmmap.sim.worlds import WORLDS, get_world

__all__ = [
    "ROBOT_SENSORS",
    "UP",
    "WORLDS",
    "Box",
    "Cylinder",
    "DepthCamera",
    "Lidar",
    "Motion",
    "SimRobot",
    "World",
    "get_world",
    "robot_sensor",
    "route_poses",
    "simulate",
    "write_pointfiles",
    "write_run",
    "write_tum",
]
