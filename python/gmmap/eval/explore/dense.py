"""The dense-map baseline: frontier exploration on a 5 cm occupancy grid built from shared
point clouds, what a dense-map multi-robot system does.

Each robot sends its points as 5 cm voxel centroids (float32 x, y, z: 12 bytes each, plus a
64-byte pose) once per ``build.submap_distance`` m or ``build.submap_angle``° of motion, as
gmmap sends a submap. Every robot integrates every cloud into the same grid (rays through the
height band the robot occupies mark cells free, their ends occupied), so the team's grid is
computed once. The frames between robots are given (an upper bound on what a dense system
would know). Goals: the nearest frontier cluster (free cells beside unknown ones) by Dijkstra
over cells a robot fits through; robots follow the grid path with the same local planner, claims
and spreading rule as the GMM explorers (the planner on the grid's occupied cells).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from gmmap import _core
from gmmap.config import Config
from gmmap.mapping.explore import Claim, Route
from gmmap.mapping.frame import Frame
from gmmap.mapping.planner import OccupancyField
from gmmap.math.gmm import Gmm

CELL = 0.05
SIZE = 1600  # cells per side: 80 m around the first robot's start
UNKNOWN, FREE, OCCUPIED = 0, 1, 2
POINT_BYTES, POSE_BYTES = 12, 64
MIN_CLUSTER = 10  # frontier cells (50 cm of frontier) a goal needs


@dataclass
class DenseShare:
    """One robot's cloud as sent: voxel centroids in the world frame."""

    points_world: np.ndarray
    origin_world: np.ndarray

    @property
    def wire_bytes(self) -> int:
        return POINT_BYTES * len(self.points_world) + POSE_BYTES


class DenseGrid:
    """The team's occupancy grid (world frame, fixed 80 m extent about ``centre``)."""

    def __init__(self, centre: np.ndarray, band: tuple[float, float]) -> None:
        self.cells = np.zeros((SIZE, SIZE), np.int8)
        self.low = np.asarray(centre, float) - SIZE * CELL / 2
        self.band = band
        self.version = 0

    def index(self, xy: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((xy - self.low) / CELL).astype(int), 0, SIZE - 1)

    def centre_of(self, ij: np.ndarray) -> np.ndarray:
        return self.low + (ij + 0.5) * CELL

    def integrate(self, origin: np.ndarray, points: np.ndarray) -> None:
        """Rays from ``origin`` (x, y) to each point (world, z up) through the band."""
        lo, hi = self.band
        hit = points[(points[:, 2] >= lo) & (points[:, 2] <= hi)]
        floor = points[points[:, 2] < lo]
        ends = np.unique(self.index(np.vstack([hit[:, :2], floor[:, :2]])), axis=0)
        if len(ends):
            start = self.index(origin[None])[0]
            steps = int(np.abs(ends - start).max()) + 1
            t = np.linspace(0.0, 1.0, steps, endpoint=False)
            ray = np.rint(start + t[None, :, None] * (ends - start)[:, None]).astype(int)
            ray = ray.reshape(-1, 2)
            free = self.cells[ray[:, 0], ray[:, 1]] != OCCUPIED
            self.cells[ray[free, 0], ray[free, 1]] = FREE
        occ = self.index(hit[:, :2])
        self.cells[occ[:, 0], occ[:, 1]] = OCCUPIED
        self.version += 1

    def known_free(self, xy: np.ndarray) -> np.ndarray:
        ij = self.index(np.atleast_2d(xy))
        return self.cells[ij[:, 0], ij[:, 1]] == FREE


class DenseExplorer:
    """One robot of the dense baseline (frames in its map frame, grid in the world's)."""

    def __init__(self, robot: str, config: Config, map_to_world: np.ndarray, grid: DenseGrid):
        self.robot, self.config, self.grid = robot, config, grid
        self.map_to_world = map_to_world
        self.buffer = _core.VoxelBuffer(CELL)
        self.travelled, self.turned, self.last = 0.0, 0.0, None
        self.position = map_to_world[:2, 3].copy()  # world frame
        self.claims: dict[str, Claim] = {}
        self.failed: list[np.ndarray] = []
        self.route: Route | None = None
        self.status = "exploring"
        self._chosen_at = -math.inf

    # ---- the interface the team loop drives (as `gmmap.mapping.explore.Explorer`) ----------

    def observe(self, frame: Frame) -> DenseShare | None:
        pose = self.map_to_world @ frame.pose
        pts = np.asarray(frame.points, float) @ pose[:3, :3].T + pose[:3, 3]
        self.position = pose[:2, 3].copy()
        self.grid.integrate(self.position, pts)
        self.buffer.offer(np.ascontiguousarray(pts, np.float32), np.eye(4), 0.0)
        self._move(pose)
        o = self.config.build
        if self.travelled >= (o.submap_distance or math.inf) or self.turned >= (
            o.submap_angle or math.inf
        ):
            return self.flush()
        return None

    def _move(self, pose: np.ndarray) -> None:
        if self.last is not None:
            step = np.linalg.inv(self.last) @ pose
            self.travelled += float(np.linalg.norm(step[:3, 3]))
            cos = (np.trace(step[:3, :3]) - 1) / 2
            self.turned += math.degrees(math.acos(min(1.0, max(-1.0, cos))))
        self.last = pose

    def flush(self) -> DenseShare | None:
        if not len(self.buffer):
            return None
        share = DenseShare(self.buffer.centroids(), self.position.copy())
        self.buffer = _core.VoxelBuffer(CELL)
        self.travelled = self.turned = 0.0
        return share

    def receive(self, share: DenseShare) -> None:
        """Clouds of peers are already in the team's grid (integrated once, see the module)."""

    def receive_claim(self, robot: str, claim: Claim) -> None:
        self.claims[robot] = claim

    def claim(self) -> Claim:
        goal = None if self.route is None else self.route.goal.copy()
        return Claim(self.position.copy(), goal)

    # ---- goals and motion -------------------------------------------------------------------

    def next_direction(self, stamp: float) -> np.ndarray | None:
        """The unit direction in this robot's map frame, or None (see ``status``)."""
        o = self.config.explore
        if (
            self.route is None
            and self.status != "exploring"
            and stamp - self._chosen_at < o.replan_s
        ):
            return None
        if self.route is None or stamp - self._chosen_at >= o.replan_s:
            self._chosen_at = stamp
            self._choose()
        if self.route is None:
            return None
        target = self.route.next_waypoint(self.position)
        direction = None
        if target is not None:
            direction = self.route.steer(self.position, target, self.config.planner, self._field())
        if direction is None:  # arrived (the frontier is seen) or cannot get there
            self.failed.append(self.route.goal)
            self.route = None
            return None
        return self.map_to_world[:2, :2].T @ direction

    def _field(self) -> OccupancyField:
        """The occupied cells within 3 m as small components: the same local planner as the
        GMM explorers steers the dense robots (on the grid's surfaces instead of mixtures)."""
        g = self.grid
        c = g.index(self.position[None])[0]
        r = int(3.0 / CELL)
        lo = np.maximum(c - r, 0)
        cells = np.argwhere(g.cells[lo[0] : c[0] + r, lo[1] : c[1] + r] == OCCUPIED) + lo
        xy = g.centre_of(cells) if len(cells) else np.zeros((1, 2)) + 1e6
        means = np.c_[xy, np.full(len(xy), 0.5)]
        covs = np.tile(np.eye(3) * CELL**2, (len(xy), 1, 1))
        return OccupancyField(Gmm(np.full(len(xy), 1 / len(xy)), means, covs), self.config.planner)

    def _choose(self) -> None:
        g = self.grid
        known = np.argwhere(g.cells != UNKNOWN)
        lo, hi = known.min(axis=0) - 2, known.max(axis=0) + 3
        sub = g.cells[lo[0] : hi[0], lo[1] : hi[1]]
        p = self.config.planner
        # A cell's centre may lie half a cell nearer a surface than its occupied cell's.
        gap = ndimage.distance_transform_edt(sub != OCCUPIED) * CELL
        passable = (sub == FREE) & (gap > p.robot_radius + p.margin)
        start = g.index(self.position[None])[0] - lo
        # Where it stands is passable, and the free cells about it: it may stand in a margin.
        ii, jj = np.ogrid[: sub.shape[0], : sub.shape[1]]
        near = (ii - start[0]) ** 2 + (jj - start[1]) ** 2 <= (0.3 / CELL) ** 2
        passable |= near & (sub == FREE)
        passable[start[0], start[1]] = True
        unknown = sub == UNKNOWN
        beside = ndimage.binary_dilation(unknown, np.ones((3, 3), bool))
        frontier = passable & beside
        labels, n = ndimage.label(frontier, np.ones((3, 3), bool))
        if n == 0:
            self.route = None
            self.status = "done: no frontier left that it can reach"
            return
        dist, pred = _grid_dijkstra(passable, start)
        best, best_cost, best_cell = None, math.inf, None
        for c, cells in enumerate(ndimage.find_objects(labels), start=1):
            idx = np.argwhere(labels[cells] == c) + np.array([cells[0].start, cells[1].start])
            if len(idx) < MIN_CLUSTER:
                continue
            flat = idx[:, 0] * sub.shape[1] + idx[:, 1]
            reach = dist[flat]
            if not np.isfinite(reach).any():
                continue
            centre = idx.mean(axis=0)
            pick = idx[
                np.argmin(
                    np.where(np.isfinite(reach), np.linalg.norm(idx - centre, axis=1), np.inf)
                )
            ]
            goal = g.centre_of(pick + lo)
            if any(np.linalg.norm(goal - f) < 0.75 for f in self.failed):
                continue
            cost = dist[pick[0] * sub.shape[1] + pick[1]] * CELL + self._crowding(goal)
            if cost < best_cost:
                best, best_cost, best_cell = goal, cost, pick
        if best is None:
            self.route = None
            self.status = "stopped: no frontier reachable on the grid"
            return
        cells = _walk_back(pred, best_cell, sub.shape, start)
        pts = g.centre_of(cells[::10] + lo)  # every 50 cm
        path = np.vstack([pts[1:], best[None]]) if len(pts) > 1 else best[None]
        self.route = Route(path, best, self._chosen_at)
        self.status = "exploring"

    def _crowding(self, goal: np.ndarray) -> float:
        cost, mine = 0.0, float(np.linalg.norm(goal - self.position))
        for claim in self.claims.values():
            cost += max(0.0, mine - float(np.linalg.norm(goal - claim.position)))
            if (
                claim.goal is not None
                and np.linalg.norm(goal - claim.goal) < self.config.explore.claim_radius
            ):
                cost += 1e3
        return cost


def _grid_dijkstra(passable: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shortest paths over 8-connected passable cells (lengths in cells) from ``start``."""
    h, w = passable.shape
    ids = np.arange(h * w).reshape(h, w)
    rows, cols, weights = [], [], []
    for di, dj, cost in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, math.sqrt(2)), (1, -1, math.sqrt(2))):
        r1, c0, c1 = h - di, max(0, -dj), w - max(0, dj)
        ok = passable[:r1, c0:c1] & passable[di : r1 + di, c0 + dj : c1 + dj]
        here = ids[:r1, c0:c1][ok]
        rows.append(here)
        cols.append(here + di * w + dj)
        weights.append(np.full(len(here), cost))
    graph = coo_matrix(
        (np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), (h * w, h * w)
    ).tocsr()
    return dijkstra(
        graph, directed=False, indices=int(ids[start[0], start[1]]), return_predecessors=True
    )


def _walk_back(
    pred: np.ndarray, cell: np.ndarray, shape: tuple[int, int], start: np.ndarray
) -> np.ndarray:
    node, out = int(cell[0] * shape[1] + cell[1]), []
    first = int(start[0] * shape[1] + start[1])
    while node >= 0 and node != first:
        out.append(divmod(node, shape[1]))
        node = int(pred[node])
    return np.array(out[::-1] or [tuple(cell)])
