"""Rerun recordings of a merged map (the optional ``viz`` extra: ``pip install 'gmmap[viz]'``).

A recording holds, in the reference robot's map frame (z up): points sampled from the map,
each component as its 2-sigma ellipsoid, and every robot's trajectory of submap anchors. Open
it with ``rerun map.rrd``.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np

from gmmap.errors import GmmapError
from gmmap.mapping.globalmap import GlobalMap


def available() -> bool:
    """Whether the Rerun SDK is installed."""
    return importlib.util.find_spec("rerun") is not None


def save_rerun(
    gmap: GlobalMap, path: str | os.PathLike, n_points: int = 100_000, sigmas: float = 2.0
) -> Path:
    """Writes ``gmap`` as a Rerun recording (.rrd) at ``path``."""
    if not available():
        raise GmmapError("Rerun is not installed: pip install 'gmmap[viz]' (rerun-sdk)")
    import rerun as rr

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(f"gmmap-{gmap.reference}")  # rerun warns of "/" in an id
    rec.save(str(path))
    rec.log("map", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    points = gmap.sample(n_points)
    rec.log("map/points", rr.Points3D(points, colors=_height_colours(points[:, 2])), static=True)
    rec.log("map/components", ellipsoids3d([gmap.gmm], sigmas), static=True)
    for robot, trajectory in gmap.trajectories.items():
        rec.log(
            f"map/trajectories/{robot}",
            rr.LineStrips3D([trajectory], labels=[robot]),
            static=True,
        )
    rec.flush()
    return path


def save_paths(paths: list, dt: float, path: str | os.PathLike, curve: list | None = None) -> Path:
    """Robots' paths ((x, y) or (x, y, z) per step, world frame) as a Rerun recording on a
    ``sim_time`` timeline: each robot's position and its path so far at every step, and the
    coverage curve ((t, surface, area) rows) as scalars."""
    if not available():
        raise GmmapError("Rerun is not installed: pip install 'gmmap[viz]' (rerun-sdk)")
    import rerun as rr

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("gmmap-explore")
    rec.save(str(path))
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for robot, steps in enumerate(paths):
        xyz = np.asarray(steps, float).reshape(len(steps), -1)
        if xyz.shape[1] == 2:  # a ground robot's path, on the floor
            xyz = np.c_[xyz, np.zeros(len(xyz))]
        for k in range(0, len(xyz), 5):
            rec.set_time("sim_time", duration=k * dt)
            rec.log(f"world/robot_{robot}/position", rr.Points3D(xyz[k : k + 1], radii=0.2))
            rec.log(f"world/robot_{robot}/path", rr.LineStrips3D([xyz[: k + 1]]))
    for t, surface, area in curve or []:
        rec.set_time("sim_time", duration=t)
        rec.log("coverage/surface", rr.Scalars(surface))
        rec.log("coverage/area", rr.Scalars(area))
    rec.flush()
    return path


def ellipsoids3d(gmms: list, sigmas: float = 2.0, **style):
    """The components of ``gmms`` as one Rerun Ellipsoids3D, each its ``sigmas`` ellipsoid."""
    import rerun as rr

    axes = [g.ellipsoids(sigmas) for g in gmms]
    quaternions = [rr.Quaternion(xyzw=q) for quats, _ in axes for q in quats]
    half_sizes = np.concatenate([h for _, h in axes])
    centres = np.concatenate([g.means for g in gmms])
    return rr.Ellipsoids3D(centers=centres, half_sizes=half_sizes, quaternions=quaternions, **style)


def _height_colours(z: np.ndarray) -> np.ndarray:
    """Blue (low) to yellow (high) over the 2nd-98th percentile of heights."""
    lo, hi = np.percentile(z, [2, 98]) if len(z) else (0.0, 1.0)
    t = np.clip((z - lo) / max(hi - lo, 1e-9), 0, 1)[:, None]
    low, high = np.array([40, 60, 200]), np.array([250, 220, 40])
    return (low + t * (high - low)).astype(np.uint8)
