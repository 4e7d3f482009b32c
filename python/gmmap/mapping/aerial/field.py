"""The GMM gradient planner in 3D, for an aerial robot (paper V-C, 12 directions → a sphere).

The occupancy of a GMM map in space: each component k contributes m_k exp(-d_k(x)^2 / 2),
with d_k the Mahalanobis distance under the component's extent grown by the robot's radius
and margin (`gmmap.mapping.planner`'s footprints, in three axes), combined by the same smooth
maximum. No height band: an aerial robot meets floors and ceilings too. A step goes towards
the waypoint unless it would enter occupancy above ``max_occupancy`` or climb the field faster
than ``g_thr`` per metre; otherwise along the surface in front of it (`Steering`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from gmmap.mapping.planner import SOFTMAX_POWER, _footprints, _support
from gmmap.math.gmm import Gmm
from gmmap.options import PlannerOptions

TOWARDS = 0.25  # weight of the target's direction beside the tangent, following a surface
AHEAD = 5  # steps straight at the target that must be clear to stop following a surface
# A term under this never moves the smooth maximum across the levels the explorer tests
# (0.1-0.5): (0.02 / 0.1)^8 is 3e-6. The 2D field's 1e-3 would reach metres along a wall.
FAINT = 0.02
MANY = 256  # points beyond which the components visit the points, not the other way
CHUNK = 256  # components per visit


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (1 + math.sqrt(5)) * i
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


SPHERE = fibonacci_sphere(48)  # headings tried: neighbours about 30° apart, as the 2D 12


class Field3D:
    """Occupancy of a GMM map at (N, 3) points, over every height."""

    def __init__(self, gmm: Gmm, options: PlannerOptions | None = None) -> None:
        self.options = options or PlannerOptions()
        mass = _support(gmm, np.ones(len(gmm), dtype=bool), self.options.min_support)
        keep = mass > 1e-3
        self.mass, self.means = mass[keep], gmm.means[keep].copy()
        self.precisions = _footprints(
            gmm.covariances[keep],
            self.options.robot_radius + self.options.margin,
            self.options.max_occupancy,
        )
        widest = np.linalg.eigvalsh(self.precisions)[:, 0] if len(self.mass) else np.ones(0)
        self.reach = np.sqrt(2 * np.log(np.maximum(self.mass, FAINT) / FAINT) / widest)
        self._tree = cKDTree(self.means if len(self.mass) else np.zeros((0, 3)))

    def __len__(self) -> int:
        return len(self.mass)

    def occupancy(self, points: np.ndarray) -> np.ndarray:
        pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
        total = np.zeros(len(pts))
        if not len(self) or not len(pts):
            return total
        if len(pts) <= MANY:
            near = self._tree.query_ball_point(pts, float(self.reach.max()))
            self._add(total, pts, [(i, np.asarray(n, int)) for i, n in enumerate(near) if n], 1)
        else:
            # Many points (a lattice): each component visits the points within its own reach,
            # a few hundred at a time, so memory stays bounded however large the map.
            tree = cKDTree(pts)
            for at in range(0, len(self), CHUNK):
                ks = range(at, min(at + CHUNK, len(self)))
                near = tree.query_ball_point(self.means[at : ks.stop], self.reach[at : ks.stop])
                self._add(
                    total,
                    pts,
                    [(k, np.asarray(n, int)) for k, n in zip(ks, near, strict=True) if n],
                    0,
                )
        return total ** (1 / SOFTMAX_POWER)

    def _add(self, total: np.ndarray, pts: np.ndarray, groups: list, point_major: int) -> None:
        """Adds the p-th powers of the terms of (one index, its neighbours) groups: (point,
        components) when ``point_major``, else (component, points)."""
        if not groups:
            return
        one = np.concatenate([np.full(len(n), i) for i, n in groups])
        many = np.concatenate([n for _, n in groups])
        p, k = (one, many) if point_major else (many, one)
        d = pts[p] - self.means[k]
        m2 = np.einsum("ni,nij,nj->n", d, self.precisions[k], d)
        np.add.at(total, p, (self.mass[k] * np.exp(-0.5 * m2)) ** SOFTMAX_POWER)


class Steering:
    """The 3D planner along one route. A step goes straight at the target where allowed;
    where refused, the robot follows the surface in front of it (round, over or under it),
    always on the side it chose first, until ``AHEAD`` steps straight at the target are all
    allowed: leaving at the first allowed step would sink it back into the dip between two
    of the surface's components, where it would dither."""

    def __init__(self, options: PlannerOptions) -> None:
        self.options = options
        self.side: np.ndarray | None = None  # the last step while following a surface

    def next(self, occupancy, position: np.ndarray, target: np.ndarray, step: float):
        """The unit direction of the next step of ``step`` m on a field (``occupancy``: (N, 3)
        points → (N,)); None where every direction is refused."""
        gap = target - position
        dist = float(np.linalg.norm(gap))
        if dist < 1e-9:
            return None
        goal = gap / dist
        tried = np.vstack([goal, SPHERE])
        here = float(occupancy(position[None])[0])
        after = occupancy(position + min(step, dist) * tried)
        climb = (after - here) / step
        # Leaving a high field is always allowed: a robot pushed into a margin must get out.
        allowed = (after < self.options.max_occupancy) & (climb < self.options.g_thr)
        allowed |= after < here - 1e-6
        if allowed[0] and (self.side is None or self._clear(occupancy, position, goal, dist)):
            self.side = None
            return goal
        if not allowed.any():
            return None
        normal = -(climb[1:, None] * SPHERE).sum(axis=0)  # downhill, away from the surface
        normal /= max(float(np.linalg.norm(normal)), 1e-12)
        side = goal if self.side is None else self.side
        tangent = side - (side @ normal) * normal
        if np.linalg.norm(tangent) < 0.2:  # the target straight through: go over it
            tangent = np.array([0.0, 0.0, 1.0]) - normal[2] * normal
        tangent /= max(float(np.linalg.norm(tangent)), 1e-12)
        score = tried @ tangent + TOWARDS * (tried @ goal)
        self.side = tried[int(np.argmax(np.where(allowed, score, -np.inf)))]
        return self.side

    def _clear(self, occupancy, position: np.ndarray, goal: np.ndarray, dist: float) -> bool:
        ahead = np.minimum(np.arange(1, AHEAD + 1) * self.options.step, dist)
        return bool(
            (occupancy(position + ahead[:, None] * goal) < self.options.max_occupancy).all()
        )
