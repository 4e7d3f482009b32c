"""Simulated sensors: a depth camera and a spinning 3-D LiDAR, by ray casting in the Rust core."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gmmap.io.datasets.tum import Intrinsics, depth_to_points
from gmmap.io.sim.world import World
from gmmap.options import SimOptions

# Body frame: x forward, y left, z up. Camera frame: z forward, x right, y down.
BODY_TO_CAMERA_ROTATION = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class DepthCamera:
    """A Kinect-like depth camera (TUM-like intrinsics by default).

    Noise model: Gaussian along the ray with σ(z) = 0.0012 + 0.0019 (z − 0.4)² metres (the
    axial noise of a Kinect, Nguyen et al. 2012), then quantised to 1 / depth_factor metres as
    a TUM depth PNG stores it. Nothing is returned beyond ``max_depth`` (value 0).
    """

    width: int = 640
    height: int = 480
    fx: float = 525.0
    fy: float = 525.0
    cx: float = 319.5
    cy: float = 239.5
    max_depth: float = 8.0
    depth_factor: float = 5000.0
    noise: bool = True
    mount_height: float = 1.0  # above the floor

    @classmethod
    def scaled(cls, width: int, height: int, noise: bool = True) -> DepthCamera:
        """The default camera's field of view at another resolution."""
        d = cls()
        return cls(
            width=width,
            height=height,
            fx=d.fx * width / d.width,
            fy=d.fy * height / d.height,
            cx=(width - 1) / 2,
            cy=(height - 1) / 2,
            noise=noise,
        )

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics(self.fx, self.fy, self.cx, self.cy)

    def mount(self) -> np.ndarray:
        """Sensor → body transform."""
        T = np.eye(4)
        T[:3, :3] = BODY_TO_CAMERA_ROTATION
        T[2, 3] = self.mount_height
        return T

    def render(self, world: World, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(H, W) float32 depth in metres for the sensor→world ``pose``, 0 = no reading."""
        z = world.scene.depth_image(
            np.ascontiguousarray(pose, dtype=np.float64),
            self.fx,
            self.fy,
            self.cx,
            self.cy,
            self.width,
            self.height,
            self.max_depth,
        )
        if self.noise:
            hit = z > 0
            sigma = 0.0012 + 0.0019 * (z[hit] - 0.4) ** 2
            z[hit] += (sigma * rng.standard_normal(int(hit.sum()))).astype(np.float32)
            z[hit & ((z <= 0) | (z >= self.max_depth))] = 0.0
        return (np.round(z * self.depth_factor) / self.depth_factor).astype(np.float32)


@dataclass(frozen=True)
class Lidar:
    """A spinning multi-beam LiDAR (VLP-16-like by default): ``beams`` channels evenly spread
    from ``fov_down`` to ``fov_up`` degrees, ``azimuth_steps`` per revolution, Gaussian range
    noise of ``noise_std`` metres. Points are returned in the sensor frame (x forward, z up)."""

    beams: int = 16
    fov_up: float = 15.0
    fov_down: float = -15.0
    azimuth_steps: int = 1024
    min_range: float = 0.3
    max_range: float = 30.0
    noise_std: float = 0.01
    mount_height: float = 0.8

    def mount(self) -> np.ndarray:
        T = np.eye(4)
        T[2, 3] = self.mount_height
        return T

    def directions(self) -> np.ndarray:
        """(beams · azimuth_steps, 3) unit ray directions in the sensor frame."""
        elev = np.radians(np.linspace(self.fov_down, self.fov_up, self.beams))
        azim = np.linspace(0, 2 * math.pi, self.azimuth_steps, endpoint=False)
        e, a = np.meshgrid(elev, azim, indexing="ij")
        return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(
            -1, 3
        )

    def scan(self, world: World, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(N, 3) float32 points in the sensor frame for the sensor→world ``pose``."""
        dirs = self.directions()
        r = world.scene.ranges(np.ascontiguousarray(pose, dtype=np.float64), dirs, self.max_range)
        hit = np.isfinite(r)
        r = r[hit] + self.noise_std * rng.standard_normal(int(hit.sum()))
        keep = (r > self.min_range) & (r < self.max_range)
        return (dirs[hit][keep] * r[keep, None]).astype(np.float32)


def sense(sensor: DepthCamera | Lidar, world: World, pose: np.ndarray, rng) -> np.ndarray:
    """One frame's points in the sensor frame, the sensor at ``pose`` (4x4, world): a LiDAR
    scan, or a depth image quantised as a TUM PNG stores it and back-projected (0.1-5 m)."""
    if isinstance(sensor, Lidar):
        return sensor.scan(world, pose, rng)
    depth = sensor.render(world, pose, rng)
    raw = np.round(depth * sensor.depth_factor).astype(np.uint16)
    return depth_to_points(raw, sensor.intrinsics, sensor.depth_factor, 1, 0.1, 5.0)


def sim_sensor(options: SimOptions) -> DepthCamera | Lidar:
    """The sensor of the ``sim`` configuration section."""
    o = options
    if o.sensor == "lidar":
        noise = Lidar.noise_std if o.noise else 0.0
        return Lidar(
            beams=o.beams,
            fov_up=o.lidar_fov,
            fov_down=-o.lidar_fov,
            max_range=o.lidar_range,
            noise_std=noise,
        )
    return DepthCamera.scaled(o.width, o.width * 3 // 4, o.noise)
