"""Exploration in 3D for an aerial robot: one algorithm object that never sees ground truth.

An `AerialExplorer` turns its robot's frames into GMM submaps, each with the spherical
horizons of its path (`gmmap.mapping.aerial.space`), and chooses where to fly from those
alone: what it would send to a peer is all it steers by.

Choosing a goal: the known free space (the union of the horizons) and the occupancy of the
submaps' mixtures (`Field3D`) are sampled on a lattice of ``LATTICE`` m over the horizons'
extent. A frontier point is a known-free point the robot fits at, beside a point that is
neither known free nor within reach of a surface (behind a wall the field is high: the
surface's components, grown by the robot, are thicker than the lattice step); or in front of
the nearest return of a cell whose beams glimpsed such a point past it (a doorway seen down a
corridor, which EM spans with the wall's components and no cell sees through); or on the line
to a component seen with no known free space in front of it (through such a gap). Frontier points
are grouped into connected clusters; the goal is the cheapest point of a cluster of at least
``explore.min_frontier`` points (any cluster once none is that large). Its cost is a route
through the graph of viewpoints (consecutive ones, and any two within ``link_radius`` whose
straight line is known free) to a viewpoint whose horizon holds the point, plus the straight
line from there, which that horizon saw free.

Moving: the 3D gradient planner (`gmmap.mapping.aerial.field.Steering`) on the submaps' field,
zero where the robot's whole footprint is known free (EM may span a doorway or the edge of a
void with a surface's components; the horizons saw through it), and on a field of the points
seen since the last-but-one submap.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from gmmap.config import Config
from gmmap.mapping.aerial.field import Field3D, Steering, fibonacci_sphere
from gmmap.mapping.aerial.space import (
    SphereHorizon,
    SphereRecorder,
    SphereSpace,
    encode_spheres,
)
from gmmap.mapping.frame import Frame
from gmmap.mapping.frontier import clear_lines
from gmmap.mapping.planner import ARRIVED, STUCK_STEPS, Route
from gmmap.mapping.submap import Submap, SubmapBuilder, concatenate
from gmmap.math.gmm import Gmm
from gmmap.math.points import voxel_filter

LATTICE = 0.3  # metres between the points known free space is sampled on
MAX_LATTICE = 400_000  # points; a larger extent gets a coarser lattice
OPEN_LEVEL = 0.1  # field under which an unknown point may hide unexplored space
FIT_LEVEL = 0.3  # field under which the robot fits at a frontier point
FOOTPRINT = np.vstack([np.zeros((1, 3)), fibonacci_sphere(14)])  # test points, unit radius
GIVE_UP = 1.0  # metres about a goal given up where frontier points are ignored


@dataclass
class SphereSubmap:
    """A submap with the spherical horizons of its path (anchor frame)."""

    submap: Submap
    horizons: list[SphereHorizon]

    @property
    def horizon_bytes(self) -> int:
        return len(encode_spheres(self.horizons))


class AerialExplorer:
    """See the module docstring. ``swept``: the direction cells the sensor's beams cross
    (`gmmap.mapping.aerial.space.swept_cells`), free to ``reach`` metres where they hit
    nothing."""

    def __init__(self, robot: str, swept: np.ndarray, reach: float, config: Config | None = None):
        self.robot = robot
        self.config = config or Config()
        self.options, self.planner_options = self.config.explore, self.config.planner
        # Its sphere horizons stand for the free space it saw; no level band would.
        build = replace(self.config.build, horizon_band=None)
        self.builder = SubmapBuilder(robot, build, self.config.select)
        self.recorder = SphereRecorder(swept, reach, self.options.horizon_spacing)
        self.submaps: list[SphereSubmap] = []
        self.route: Route | None = None
        self.failed: list[np.ndarray] = []
        self.status = "exploring"
        self.position = np.zeros(3)
        self._steered: Route | None = None  # the route ``_steering`` follows
        self._steering = Steering(self.planner_options)
        self._field: Field3D | None = None

    # ---- input ------------------------------------------------------------------------------

    def observe(self, frame: Frame) -> SphereSubmap | None:
        """Maps a frame; returns the submap it completed, with its horizons."""
        self.recorder.add(frame)
        self.position = frame.pose[:3, 3].copy()
        return self._keep(self.builder.add(frame))

    def flush(self) -> SphereSubmap | None:
        return self._keep(self.builder.flush())

    def _keep(self, submap: Submap | None) -> SphereSubmap | None:
        if submap is None:
            return None
        shared = SphereSubmap(submap, self.recorder.take(submap.anchor))
        self.submaps.append(shared)
        self._field = None
        return shared

    # ---- what it knows ----------------------------------------------------------------------

    def space(self) -> SphereSpace:
        """Every horizon in the map frame, the latest last."""
        moved = [h.moved(s.submap.anchor) for s in self.submaps for h in s.horizons]
        return SphereSpace(moved + self.recorder.closed)

    def field(self) -> Field3D | None:
        """The occupancy of the submaps' mixtures (map frame)."""
        if self._field is None and self.submaps:
            gmms = [s.submap.gmm.transform(s.submap.anchor) for s in self.submaps]
            shares = [s.submap.n_points for s in self.submaps]
            self._field = Field3D(concatenate(gmms, shares), self.planner_options)
        return self._field

    def _live(self) -> Field3D | None:
        """The points seen since the last-but-one submap as small components."""
        parts = []
        if self.builder.anchor is not None and len(self.builder.buffer):
            a = self.builder.anchor
            parts.append(self.builder.buffer.centroids() @ a[:3, :3].T + a[:3, 3])
        if self.submaps:
            s = self.submaps[-1].submap
            parts.append(s.points @ s.anchor[:3, :3].T + s.anchor[:3, 3])
        if not parts:
            return None
        pts = voxel_filter(np.vstack(parts), 0.1)
        covs = np.tile(np.eye(3) * 0.05**2, (len(pts), 1, 1))
        return Field3D(Gmm(np.full(len(pts), 1 / len(pts)), pts, covs), self.planner_options)

    def roomy(self, points: np.ndarray, space: SphereSpace) -> np.ndarray:
        """Whether the robot's footprint about each (N, 3) point is all known free (seen
        through, not only flown through)."""
        reach = self.planner_options.robot_radius + self.planner_options.margin
        pts = np.atleast_2d(points)[:, None, :] + reach * FOOTPRINT[None]
        seen = space.contains(pts.reshape(-1, 3), body=False)
        return seen.reshape(len(pts), -1).all(axis=1)

    def occupancy(self, points: np.ndarray, live: Field3D | None, space: SphereSpace):
        """The submaps' field where the footprint is not known free, or the live field,
        whichever is larger."""
        pts = np.atleast_2d(points)
        out = np.zeros(len(pts))
        team = self.field()
        if team is not None:
            out = team.occupancy(pts)
            out[self.roomy(pts, space)] = 0.0
        if live is not None:
            out = np.maximum(out, live.occupancy(pts))
        return out

    # ---- goals ------------------------------------------------------------------------------

    def _lattice(self, space: SphereSpace) -> tuple[np.ndarray, tuple[int, int, int], float]:
        lo, hi = space.extent()
        step = LATTICE
        while np.prod(np.ceil((hi - lo) / step) + 1) > MAX_LATTICE:
            step *= 1.25
        axes = [np.arange(a, b + step, step) for a, b in zip(lo, hi, strict=True)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
        return grid.reshape(-1, 3), grid.shape[:3], step

    def frontiers(self, space: SphereSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frontier points (M, 3), their cluster labels (M,) and which horizons hold each
        (M, H)."""
        points, shape, step = self._lattice(space)
        inside = space.inside(points, shrink=0.05)
        free = inside.any(axis=1)
        occ = np.zeros(len(points))
        if self.field() is not None:
            occ = self.field().occupancy(points)
        open_ = ~free & (occ < OPEN_LEVEL)
        open_[open_] = ~space.blind(points[open_])
        open_ = open_.reshape(shape)
        beside = np.zeros(shape, dtype=bool)
        for axis in range(3):
            for shift in (-1, 1):
                moved = np.roll(open_, shift, axis)
                edge = [slice(None)] * 3
                edge[axis] = 0 if shift == 1 else -1
                moved[tuple(edge)] = True  # past the lattice is unknown
                beside |= moved
        fits = free & (occ < FIT_LEVEL)
        front = fits.reshape(shape) & beside
        # Unknown space some beam glimpsed past a nearer return (a doorway down a corridor),
        # and surfaces seen with no known free space in front of them (through such a gap):
        # the known-free point in front of that return is a frontier too, moved towards the
        # viewpoint along the line it saw while the robot does not fit there.
        unknown = points[open_.ravel()]
        seer = space.glimpsed(unknown)
        lost, by = self.unsighted(space)
        owners = np.concatenate([seer[seer >= 0], by])
        look = space.look_outs(np.vstack([unknown[seer >= 0], lost]), owners)
        seen = ~np.isnan(look[:, 0])
        look, origin = look[seen], space.origins[owners[seen]]
        for f in (1.0, 0.75, 0.5):
            at = np.round((origin + f * (look - origin) - points[0]) / step).astype(int)
            within = ((at >= 0) & (at < shape)).all(axis=1)
            flat = np.ravel_multi_index(at[within].T, shape)
            ok = np.zeros(len(look), dtype=bool)
            ok[within] = fits[flat]
            np.put(front, flat[ok[within]], True)
            look, origin = look[~ok], origin[~ok]
        labels, _ = ndimage.label(front, structure=np.ones((3, 3, 3)))
        keep = front.ravel()
        return points[keep], labels.ravel()[keep], inside[keep]

    def unsighted(self, space: SphereSpace) -> tuple[np.ndarray, np.ndarray]:
        """The means (M, 3) of the submaps' components with no known free space half a metre
        in front of them (seen through a gap), and (M,) the viewpoints they were seen from:
        each one's nearest of its own submap's."""
        means, owners, first = [np.zeros((0, 3))], [np.zeros(0, int)], 0
        for s in self.submaps:
            n = len(s.horizons)
            if n:
                m = s.submap.gmm.means @ s.submap.anchor[:3, :3].T + s.submap.anchor[:3, 3]
                d = np.linalg.norm(m[:, None] - space.origins[None, first : first + n], axis=2)
                means.append(m)
                owners.append(first + np.argmin(d, axis=1))
            first += n
        m, owner = np.vstack(means), np.concatenate(owners)
        v = space.origins[owner]
        away = np.linalg.norm(v - m, axis=1)
        front = m + 0.5 * (v - m) / np.maximum(away, 1e-9)[:, None]
        lost = (away > 1.0) & ~space.contains(front)
        return m[lost], owner[lost]

    def _distances(self, space: SphereSpace) -> tuple[np.ndarray, np.ndarray, int]:
        """Route lengths from the robot (the last node) to every viewpoint."""
        n = len(space)
        edges = [(i, i + 1) for i in range(n - 1)]  # one robot: it flew from one to the next
        pairs = cKDTree(space.origins).query_pairs(self.options.link_radius, output_type="ndarray")
        if len(pairs):
            ok = clear_lines(space, space.origins[pairs[:, 0]], space.origins[pairs[:, 1]])
            edges += [tuple(p) for p in pairs[ok]]
        near = np.array(
            cKDTree(space.origins).query_ball_point(self.position, self.options.link_radius), int
        )
        if len(near):
            ok = clear_lines(
                space, np.repeat(self.position[None], len(near), 0), space.origins[near]
            )
            edges += [(n, int(i)) for i in near[ok]]
        edges.append((n, n - 1))  # the viewpoint it is at or just left
        e = np.array(edges, dtype=int)
        pts = np.vstack([space.origins, self.position[None]])
        w = np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1) + 1e-6
        graph = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n + 1, n + 1)).tocsr()
        dist, pred = dijkstra(graph, directed=False, indices=n, return_predecessors=True)
        return dist, pred, n

    def _choose(self, stamp: float) -> None:
        space = self.space()
        if not len(space):
            return
        points, labels, inside = self.frontiers(space)
        # Frontier points where the robot stands, having looked again, it cannot see past.
        self.failed += list(points[np.linalg.norm(points - self.position, axis=1) < ARRIVED])
        if self.failed and len(points):
            keep = cKDTree(np.array(self.failed)).query(points)[0] > GIVE_UP
            points, labels, inside = points[keep], labels[keep], inside[keep]
        if not len(points):
            self.route, self.status = None, "done: no frontier left that it can reach"
            return
        dist, pred, start = self._distances(space)
        legs = np.linalg.norm(points[:, None] - space.origins[None], axis=2)
        legs = np.where(inside, legs + dist[None, : len(space)], np.inf)
        through = np.argmin(legs, axis=1)
        cost = legs[np.arange(len(points)), through]
        reachable = np.isfinite(cost)
        if not reachable.any():
            self.route = None
            self.status = f"stopped: {len(points)} frontier points, none reachable"
            return
        big = reachable & (np.bincount(labels)[labels] >= self.options.min_frontier)
        best = int(np.argmin(np.where(big if big.any() else reachable, cost, np.inf)))
        goal = points[best]
        r = self.route
        if r is not None and np.linalg.norm(goal - r.goal) < GIVE_UP:
            r.chosen_at = stamp  # the same goal: keep the route, and its count of steps in vain
            return
        chain, node = [], int(through[best])
        while node != start and node >= 0:
            chain.append(space.origins[node])
            node = pred[node]
        self.route = Route(np.array([*reversed(chain), goal]), goal, stamp)
        self.status = "exploring"

    # ---- moving -----------------------------------------------------------------------------

    def next_direction(self, stamp: float, step: float) -> np.ndarray | None:
        """The unit direction (map frame) of the next step of ``step`` m, or None: no goal
        (see ``status``)."""
        r = self.route
        if r is None or stamp - r.chosen_at >= self.options.replan_s:
            self._choose(stamp)
            r = self.route
        if r is None:
            return None
        target = r.next_waypoint(self.position)
        if target is None:
            self.route = None  # arrived: look again from here, then choose again
            self.recorder.again()
            return None
        live, space = self._live(), self.space()
        if r is not self._steered:
            self._steered, self._steering = r, Steering(self.planner_options)
        direction = None
        if r.since_best < STUCK_STEPS:
            field = lambda p: self.occupancy(p, live, space)  # noqa: E731
            direction = self._steering.next(field, self.position, target, step)
        if direction is None:
            self.failed.append(r.goal)
            self.route = None
        return direction
