"""The GMM gradient-field local planner (paper V-C): navigation directly on a GMM map.

The map becomes a smooth 2D occupancy field over the robot's height band. Each component k
contributes a_k(x) = m_k exp(-d_k(x)^2 / 2): m_k in [0, 1] is how much of the component lies
inside the band (a floor or a ceiling component contributes nothing), and d_k is a Mahalanobis
distance scaled so that a_k equals ``max_occupancy`` a robot radius outside the surface the
component covers, grown by the robot radius and a safety margin (its footprint).
Components combine by a smooth maximum, o = (sum_k a_k^8)^(1/8): about 1 on a surface, 0 in
free space, independent of the map's size and weights, with an analytic gradient.

The paper's rule, replanned at every step: move towards the goal if the directional gradient
g(r) = grad o . r is under g_thr; otherwise try goal +-30 deg, +-60 deg, ... (12 directions).
Two additions make it usable: a step is refused if it would enter occupancy above
``max_occupancy`` (the rule alone bounds the slope, not the distance), and while the goal
direction stays refused the robot keeps to the side (left or right) it chose first, so it
follows an obstacle round instead of dithering in front of it. A run ends ``reached``, or
``stuck`` when no direction is allowed or the robot has not got closer to the goal for
``stuck_window`` steps (an unreachable goal ends, it does not loop).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import ndtr

from gmmap.errors import InvalidInputError
from gmmap.math.gmm import Gmm
from gmmap.options import PlannerOptions

# Components combine by a smooth maximum (a p-norm): o is about the largest a_k, so the faint
# tails of many components do not add up to close a doorway, as a sum or a product would.
SOFTMAX_POWER = 8  # `_softmax` multiplies it out
ARRIVED = 0.35  # metres from a route's waypoint that count as there
STUCK_STEPS = 24  # steps without getting closer to a route's waypoint before it is given up
FAINT = 1e-3  # a component's term under this is left out where a field is evaluated locally


class OccupancyField:
    """The occupancy o(x) of a GMM map over a height band, and its analytic gradient, at
    (N, 2) horizontal positions."""

    def __init__(self, gmm: Gmm, options: PlannerOptions | None = None) -> None:
        self.options = options or PlannerOptions()
        mass = _band_mass(gmm.means[:, 2], gmm.covariances[:, 2, 2], self.options.z_band)
        mass *= _support(gmm, mass > 1e-3, self.options.min_support)
        keep = mass > 1e-3
        self.mass = mass[keep]
        self.means = gmm.means[keep, :2].copy()
        self.precisions = _footprints(
            gmm.covariances[keep][:, :2, :2],
            self.options.robot_radius + self.options.margin,
            self.options.max_occupancy,
        )

    def __len__(self) -> int:
        return len(self.mass)

    @cached_property
    def _index(self) -> tuple[cKDTree, np.ndarray]:
        """A tree of the means and each component's reach: the distance past which its term
        is under ``FAINT`` (along its widest footprint axis)."""
        widest = np.linalg.eigvalsh(self.precisions)[:, 0] if len(self) else np.zeros(0)
        reach = np.sqrt(2 * np.log(np.maximum(self.mass, FAINT) / FAINT) / np.maximum(widest, 1e-9))
        return cKDTree(self.means if len(self) else np.zeros((0, 2))), reach

    def near(self, centre: object, radius: float) -> OccupancyField:
        """The components whose terms reach within ``radius`` of ``centre``: the same field
        there, to within ``FAINT``, at a fraction of the cost on a large map."""
        tree, reach = self._index
        if not len(self):
            return self
        idx = np.array(tree.query_ball_point(_as_xy(centre)[0], radius + reach.max()), int)
        if len(idx):
            gap = np.linalg.norm(self.means[idx] - _as_xy(centre)[0], axis=1)
            idx = idx[gap < radius + reach[idx]]
        return self.subset(idx)

    def occupancy_tiled(self, xy: object, tile: float = 1.5) -> np.ndarray:
        """`occupancy` at many points of a large map, tile by tile on the components near."""
        xy = _as_xy(xy)
        out = np.zeros(len(xy))
        cells = np.floor(xy / tile).astype(np.int64)
        keys, inverse = np.unique(cells, axis=0, return_inverse=True)
        for i, key in enumerate(keys):
            rows = np.flatnonzero(inverse.ravel() == i)
            local = self.near((key + 0.5) * tile, tile * 0.71)
            if len(local):
                out[rows] = local.occupancy(xy[rows])
        return out

    def subset(self, keep: np.ndarray) -> OccupancyField:
        """The field of the kept components only, each as it is in this one (its support
        stays relative to the whole map): to evaluate a large map near a few places."""
        out = object.__new__(OccupancyField)
        out.options = self.options
        out.mass, out.means, out.precisions = (
            self.mass[keep],
            self.means[keep],
            self.precisions[keep],
        )
        return out

    def _terms(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """a_k at each point (N, K) and P_k (x - mu_k) (N, K, 2), written out in 2D (einsum
        is several times slower on these shapes)."""
        dx = xy[:, 0, None] - self.means[None, :, 0]
        dy = xy[:, 1, None] - self.means[None, :, 1]
        p = self.precisions
        px = p[None, :, 0, 0] * dx + p[None, :, 0, 1] * dy
        py = p[None, :, 1, 0] * dx + p[None, :, 1, 1] * dy
        return self.mass * np.exp(-0.5 * (dx * px + dy * py)), np.stack([px, py], -1)

    def occupancy(self, xy: object) -> np.ndarray:
        xy = _as_xy(xy)
        if not len(self):
            return np.zeros(len(xy))
        return _softmax(self._terms(xy)[0])[0]

    def gradient(self, xy: object) -> tuple[np.ndarray, np.ndarray]:
        """(occupancy (N,), gradient (N, 2)) with o = (sum_k a_k^p)^(1/p) and
        d o = o^(1-p) sum_k a_k^(p-1) d a_k, where d a_k = -a_k P_k (x - mu_k)."""
        xy = _as_xy(xy)
        if not len(self):
            return np.zeros(len(xy)), np.zeros((len(xy), 2))
        a, pd = self._terms(xy)
        o, slope = _softmax(a)
        return o, -((a * slope)[..., None] * pd).sum(axis=1)


def _softmax(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """o = (sum_k a_k^p)^(1/p) per row and d o / d a_k = (a_k / o)^(p-1), for p = 8."""
    # Scaled by the largest term: far from every surface the a_k^p underflow to zero.
    top = a.max(axis=1, keepdims=True)
    r = np.divide(a, top, out=np.zeros_like(a), where=top > 0)
    r2 = r * r
    r4 = r2 * r2
    s = (r4 * r4).sum(axis=1, keepdims=True) ** (1 / SOFTMAX_POWER)
    s = np.where(s > 0, s, 1.0)
    q = r / s
    q2 = q * q
    return (top * s)[:, 0], q2 * q2 * q2 * q  # (a_k / o)^7


def _footprints(cov: np.ndarray, radius: float, level: float) -> np.ndarray:
    """Precisions of Gaussians whose ``level`` set is each component's horizontal extent grown
    by ``radius``: along each principal axis the extent of a uniform segment with the
    component's spread (sqrt(3) sigma) plus the radius. A plain Gaussian fades before a
    surface ends, so a robot would clip wall ends and corners."""
    eigval, eigvec = np.linalg.eigh(cov)
    semi = np.sqrt(3 * np.maximum(eigval, 0)) + radius
    scale = 2 * math.log(1 / level)  # exp(-scale / 2) == level on the grown extent
    return np.einsum("kij,kj,klj->kil", eigvec, scale / semi**2, eigvec)


def _support(gmm: Gmm, in_band: np.ndarray, min_support: float) -> np.ndarray:
    """Each component's peak density relative to ``min_support`` times the median of the
    band's components, capped at 1. EM sometimes spans the free space between two objects with
    one broad, light component; its density is orders of magnitude under a surface's, and it
    must not close the gap between them."""
    peak = gmm.weights / np.sqrt(np.linalg.det(gmm.covariances))
    if not in_band.any() or min_support <= 0:
        return np.ones(len(gmm))
    return np.minimum(1.0, peak / (min_support * np.median(peak[in_band])))


def _band_mass(mu_z: np.ndarray, var_z: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """How much of each component's height distribution lies in the band, relative to the most
    a distribution of that spread could put there (so a tall wall component counts fully)."""
    sd = np.sqrt(np.maximum(var_z, 1e-12))
    inside = ndtr((band[1] - mu_z) / sd) - ndtr((band[0] - mu_z) / sd)
    best = 2 * ndtr(0.5 * (band[1] - band[0]) / sd) - 1
    return np.clip(inside / np.maximum(best, 1e-12), 0.0, 1.0)


def _as_xy(xy: object) -> np.ndarray:
    arr = np.atleast_2d(np.asarray(xy, dtype=np.float64))
    if arr.shape[1] != 2 or not np.isfinite(arr).all():
        raise InvalidInputError(f"positions must be finite (N, 2), got shape {arr.shape}")
    return arr


@dataclass
class PlanResult:
    """A run of the planner: the positions visited (start first), how it ended, and timing."""

    path: np.ndarray
    status: str  # "reached" or "stuck"
    steps: int
    time_per_step_s: float
    reason: str = ""

    @property
    def success(self) -> bool:
        return self.status == "reached"

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.diff(self.path, axis=0), axis=1).sum())


@dataclass
class Route:
    """Waypoints to a goal (an explorer's, chosen at ``chosen_at``), followed with the
    gradient planner."""

    waypoints: np.ndarray
    goal: np.ndarray
    chosen_at: float
    reached: int = 0
    best: float = math.inf
    since_best: int = 0
    planner: GradientPlanner | None = None
    turned_back: bool = False

    def next_waypoint(self, position: np.ndarray) -> np.ndarray | None:
        """Passes the waypoints within ``ARRIVED`` of ``position`` and returns the next one
        (None: arrived), counting the steps that got no closer to it."""
        while (
            self.reached < len(self.waypoints)
            and np.linalg.norm(self.waypoints[self.reached] - position) < ARRIVED
        ):
            self.reached, self.best, self.since_best = self.reached + 1, math.inf, 0
        if self.reached == len(self.waypoints):
            return None
        target = self.waypoints[self.reached]
        gap = float(np.linalg.norm(target - position))
        self.best, self.since_best = (
            (gap, 0) if gap < self.best - 0.05 else (self.best, self.since_best + 1)
        )
        return target

    def steer(
        self, position: np.ndarray, target: np.ndarray, options: PlannerOptions, field: object
    ) -> np.ndarray | None:
        """The planner's unit direction towards ``target`` on ``field`` (one planner per route:
        the side it follows round an obstacle stays); None when every direction is refused or
        the robot has got no closer for ``STUCK_STEPS`` round each side of an obstacle. After
        the first side's steps it turns back round the other, once: passing a door jamb at an
        angle, the gentler side can be the wall beside the door (traced on random-office:102).
        Turning at half the steps gave up walls that end 1.5 m to the side."""
        if self.planner is None:
            self.planner = GradientPlanner(None, options, field)
        if self.since_best >= STUCK_STEPS:
            if self.turned_back or not self.planner.side:
                return None
            # Going back towards the goal counts as getting closer again, so the other side
            # gets as many steps as the first had.
            self.planner.side, self.turned_back = -self.planner.side, True
            self.best, self.since_best = float(np.linalg.norm(target - position)), 0
        self.planner.field = field
        return self.planner.choose(position, target)


class GradientPlanner:
    """Plans on a GMM map (map frame) from a start to a goal, one step at a time."""

    def __init__(
        self, gmm: Gmm | None, options: PlannerOptions | None = None, field: object = None
    ) -> None:
        """On the field of ``gmm``, or on ``field`` (anything with this module's
        ``occupancy`` and ``gradient``: an explorer adds what its sensor sees now)."""
        self.options = options or PlannerOptions()
        self.field = field if gmm is None else OccupancyField(gmm, self.options)
        if self.field is None:
            raise InvalidInputError("a planner needs a GMM or an occupancy field")
        step = 2 * math.pi / self.options.directions
        half = self.options.directions // 2
        # Offsets from the goal direction in the paper's order: 0, +-1, +-2, ... sectors.
        offsets = [(0, 0)] + [(k, s) for k in range(1, half) for s in (1, -1)] + [(half, 1)]
        self._offsets = np.array(offsets)
        self._sector = step
        self.side = 0  # the side (+1 left, -1 right) followed round an obstacle; 0: none

    def choose(self, position: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
        """The unit direction of the next step, or None when every direction is refused."""
        opt = self.options
        heading = math.atan2(goal[1] - position[1], goal[0] - position[0])
        step = min(opt.step, float(np.linalg.norm(goal - position)))
        _, grad = self.field.gradient(position)
        angles = heading + self._offsets[:, 0] * self._offsets[:, 1] * self._sector
        dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        slope = dirs @ grad[0]
        allowed = (slope < opt.g_thr) & (
            self.field.occupancy(position + step * dirs) < opt.max_occupancy
        )
        k, side = self._offsets[:, 0], self._offsets[:, 1]
        # Committed to a side: the goal, then round that side, then the other; otherwise the
        # paper's order, the gentler slope first at equal angles.
        keys = (k, side != self.side, k > 0) if self.side else (slope, k)
        order = np.lexsort(keys)
        for i in order:
            if allowed[i]:
                self.side = int(side[i]) if k[i] else 0
                return dirs[i]
        return None

    def plan(self, start: object, goal: object) -> PlanResult:
        """Steps from ``start`` until the goal is within tolerance or the robot is stuck."""
        opt = self.options
        position = _as_xy(start)[0].copy()
        goal_xy = _as_xy(goal)[0]
        path = [position.copy()]
        best, since_best = math.inf, 0
        status, reason = "stuck", f"no arrival within {opt.max_steps} steps"
        t0 = time.perf_counter()
        for _ in range(opt.max_steps):
            dist = float(np.linalg.norm(goal_xy - position))
            if dist <= opt.goal_tolerance:
                status, reason = "reached", ""
                break
            if dist < best - 1e-3:
                best, since_best = dist, 0
            else:
                since_best += 1
                if since_best > opt.stuck_window:
                    reason = f"no progress towards the goal for {opt.stuck_window} steps"
                    break
            direction = self.choose(position, goal_xy)
            if direction is None:
                reason = "every direction is blocked"
                break
            position = position + min(opt.step, dist) * direction
            path.append(position.copy())
        steps = len(path) - 1
        elapsed = time.perf_counter() - t0
        return PlanResult(np.array(path), status, steps, elapsed / max(steps, 1), reason)


def plan(
    gmm: Gmm, start: object, goal: object, options: PlannerOptions | None = None
) -> PlanResult:
    """Plans from ``start`` to ``goal`` ((x, y), the map's frame) on a GMM map."""
    return GradientPlanner(gmm, options).plan(start, goal)
