"""Exploration measured against the true world, never against the map.

``surface``: the share of the world's vertical surfaces (every 10 cm, 0.3-1.7 m above the
floor: what a ground robot's sensor can see of walls and furniture) that lie within 10 cm of
the team's map, placed by ground truth (of a GMM map: inside a component's 2-sigma ellipsoid
grown by 5 cm; of a point map: within 10 cm of a point). Floors, ceilings and table tops are
left out: a sensor looks along them, and they would measure its field of view, not exploration.
Samples inside or against another shape, or outside the world's bounds (the outer faces of
its walls), cannot be seen and are not counted, nor are surfaces farther than 45 cm from the
floor the robots can reach. ``area``: the share of that floor (a 25 cm grid, 20 cm from any
shape, connected to where the robots start) that the team knows is free. An aerial robot's
(`AerialCoverage`) counts the surfaces at every height, and the space it can fly in.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from gmmap.errors import InvalidInputError
from gmmap.io.sim import Box, Cylinder, World
from gmmap.math.gmm import Gmm

STEP = 0.1  # metres between surface samples
HEIGHTS = np.arange(0.3, 1.71, STEP)
WITHIN = 0.1  # metres from the map that count as covered


def surface_samples(
    world: World, heights: np.ndarray = HEIGHTS, band: tuple[float, float] | None = (0.3, 1.7)
) -> np.ndarray:
    """(N, 3) points on the world's visible vertical surfaces at ``heights`` (see the module
    docstring); against another shape means within 2 cm of one that occupies ``band`` (None:
    of any shape, in 3D)."""
    pts = []
    for s in world.shapes:
        if isinstance(s, Box):
            z0, z1 = s.centre[2] - s.size[2] / 2, s.centre[2] + s.size[2] / 2
            zs = heights[(z0 < heights) & (z1 > heights)]
            c, sn = math.cos(s.yaw), math.sin(s.yaw)
            hx, hy = s.size[0] / 2, s.size[1] / 2
            for ax, half, other in ((0, hx, hy), (1, hy, hx)):
                along = np.arange(-other + STEP / 2, other, STEP)
                for side in (-1.0, 1.0):
                    local = np.zeros((len(along), 2))
                    local[:, ax], local[:, 1 - ax] = side * (half + 0.03), along
                    xy = np.c_[
                        c * local[:, 0] - sn * local[:, 1], sn * local[:, 0] + c * local[:, 1]
                    ]
                    xy += s.centre[:2]
                    pts += [np.c_[xy, np.full(len(xy), z)] for z in zs]
        elif isinstance(s, Cylinder):
            zs = heights[(s.z_min < heights) & (s.z_max > heights)]
            n = max(6, int(2 * math.pi * s.radius / STEP))
            a = np.linspace(0, 2 * math.pi, n, endpoint=False)
            xy = np.c_[s.x + (s.radius + 0.03) * np.cos(a), s.y + (s.radius + 0.03) * np.sin(a)]
            pts += [np.c_[xy, np.full(len(xy), z)] for z in zs]
    p = np.vstack(pts) if pts else np.zeros((0, 3))
    lo, hi = world.bounds()
    inside = ((p[:, :2] > lo[:2] + 0.05) & (p[:, :2] < hi[:2] - 0.05)).all(axis=1)
    p = p[inside]
    # Each sample sits 3 cm off its face: one closer than 2 cm to a shape is against another.
    gap = world.distance(p) if band is None else world.clearance(p[:, :2], band)
    return p[gap > 0.02]


def floor_samples(
    world: World, starts: np.ndarray, clearance: float = 0.2, cell: float = 0.25
) -> np.ndarray:
    """(N, 2) points of the floor where a robot fits and that it can reach from ``starts``
    ((M, 2)), every ``cell`` m (the part of a world's bounds outside its walls is not)."""
    lo, hi = world.bounds()
    xs, ys = np.arange(lo[0] + cell / 2, hi[0], cell), np.arange(lo[1] + cell / 2, hi[1], cell)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1)
    fits = (world.clearance(grid.reshape(-1, 2), (0.05, 1.2)) > clearance).reshape(grid.shape[:2])
    labels, _ = ndimage.label(fits)
    at = np.floor((np.atleast_2d(starts) - lo[:2]) / cell).astype(int)
    mine = {int(labels[i, j]) for i, j in at if 0 <= i < len(xs) and 0 <= j < len(ys)} - {0}
    return grid[np.isin(labels, list(mine))]


class Coverage:
    """Covered surface samples, updated as maps (world frame) arrive. Only what robots
    starting at ``starts`` can reach counts: the floor connected to them and the surfaces
    within 45 cm of it."""

    def __init__(self, world: World, starts: np.ndarray) -> None:
        self.floor = floor_samples(world, starts)
        samples = surface_samples(world)
        near = cKDTree(self.floor).query(samples[:, :2], distance_upper_bound=0.45)[0]
        self._keep(samples[np.isfinite(near)])

    def _keep(self, samples: np.ndarray) -> None:
        self.samples = samples
        self.covered = np.zeros(len(samples), dtype=bool)
        self._tree = cKDTree(samples)

    def add_gmm(self, gmm: Gmm) -> None:
        """Marks the samples within 10 cm of a mixture's surfaces (world frame): inside some
        component's 2-sigma ellipsoid once its covariance is grown by (5 cm)^2, so a surface
        component's 2 sigma reaches 10 cm off it."""
        covs = gmm.covariances + (WITHIN / 2) ** 2 * np.eye(3)
        precisions = np.linalg.inv(covs)
        reach = 2 * np.sqrt(np.linalg.eigvalsh(covs)[:, -1])
        for mean, precision, r in zip(gmm.means, precisions, reach, strict=True):
            idx = np.array(self._tree.query_ball_point(mean, r), dtype=int)
            if len(idx):
                d = self.samples[idx] - mean
                inside = np.einsum("ni,ij,nj->n", d, precision, d) <= 4.0
                self.covered[idx[inside]] = True

    def add_points(self, points_world: np.ndarray) -> None:
        if not len(points_world):
            return
        hits = self._tree.query_ball_point(np.asarray(points_world, float), WITHIN)
        idx = [i for h in hits for i in h]
        if idx:
            self.covered[np.array(idx)] = True

    @property
    def surface(self) -> float:
        return float(self.covered.mean()) if len(self.samples) else 0.0

    def area(self, known_free: Callable[[np.ndarray], np.ndarray]) -> float:
        """The share of ``floor`` that ``known_free`` ((N, 2) world points → bool) says is
        free: the team's horizons, or the dense baseline's grid."""
        return float(known_free(self.floor).mean()) if len(self.floor) else 0.0


def volume_samples(world: World, start: np.ndarray, clearance: float, cell: float = 0.3):
    """(N, 3) points of the space an aerial robot fits in (``clearance`` from every shape)
    and can reach from ``start``, every ``cell`` m."""
    lo, hi = world.bounds()
    axes = [np.arange(a + cell / 2, b, cell) for a, b in zip(lo, hi, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    fits = (world.distance(grid.reshape(-1, 3)) > clearance).reshape(grid.shape[:3])
    labels, _ = ndimage.label(fits)
    at = tuple(np.floor((np.asarray(start) - lo) / cell).astype(int))
    if not all(0 <= i < n for i, n in zip(at, labels.shape, strict=True)) or not labels[at]:
        raise InvalidInputError(f"{world.name}: no room for the robot at {start}")
    return grid[labels == labels[at]]


class AerialCoverage(Coverage):
    """`Coverage` for an aerial robot: the vertical surfaces at every height (10 cm steps from
    0.3 m to 0.3 m under the top) within 75 cm of a point of the space it can reach (a 30 cm
    lattice, its points ``clearance`` from every shape); ``area`` becomes the share of that
    space known free."""

    def __init__(self, world: World, start: np.ndarray, clearance: float) -> None:
        top = world.bounds()[1][2]
        self.floor = volume_samples(world, start, clearance)
        samples = surface_samples(world, np.arange(0.3, top - 0.29, STEP), band=None)
        near = cKDTree(self.floor).query(samples, distance_upper_bound=0.75)[0]
        self._keep(samples[np.isfinite(near)])
