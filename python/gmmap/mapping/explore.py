"""Exploration on shared GMM submaps: one robot's algorithm object (it never sees ground truth).

An `Explorer` turns its robot's frames into submaps, each with the free-space horizons of
its path (`gmmap.mapping.frontier`), and holds what its peers share. It places the team's
submaps in its own map frame by the frames its `Mapper` finds between robots, so before two
robots have joined their maps each explores alone, and after, they share one frontier set.

Choosing a goal: the frontiers of the union of every known horizon, minus those behind a
surface (the GMM occupancy field), those a joined peer heads for from nearer than this robot
(its goal within ``claim_radius``; a robot left none waits) and those given up. A route runs
through the graph of viewpoints: consecutive viewpoints of one robot (it drove between them)
and viewpoints within ``link_radius`` whose straight line is known free; a frontier's cost is
the route to the cheapest viewpoint whose horizon holds its target plus the straight, observed
line from there, or the straight line from the robot where that is known free. Frontiers with
unknown space behind them come first, then large ones, then any. Moving: the GMM gradient
planner steers towards the next waypoint on the team's field, zero where the robot's footprint
is known free (EM spans a doorway with the wall's components; the horizons saw through it), and
on a field of what the sensor saw since the last-but-one submap (a robot avoids what it has
just seen, shared or not).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from gmmap.config import Config
from gmmap.mapping.frame import Frame
from gmmap.mapping.frontier import (
    BACK,
    SAME_GOAL,
    FreeSpace,
    Horizon,
    HorizonRecorder,
    clear_lines,
    encode_horizons,
    preferred,
    unit,
)
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.planner import ARRIVED, OccupancyField, Route
from gmmap.mapping.submap import Submap, SubmapBuilder, concatenate
from gmmap.math.gmm import Gmm
from gmmap.math.points import voxel_filter

Node = tuple[str, int]
# Footprint test points: between two of 16 a wall reaches at most 5 mm inside the ring (19 mm
# between two of 8, where a depth camera's robot, blind beside it, drove into walls).
RING = np.linspace(0, 2 * math.pi, 16, endpoint=False)
SWITCH_COST = 2.0  # metres of route a new goal must save to replace the current one
TRIES = 3  # times a goal is given up before it is left for good


@dataclass
class SharedSubmap:
    """What one robot sends of a submap when exploring: the submap and its horizons (in its
    anchor frame); ``horizon_bytes`` is their size on the wire, beside the submap's."""

    submap: Submap
    horizons: list[Horizon]

    @property
    def horizon_bytes(self) -> int:
        return len(encode_horizons(self.horizons))


@dataclass
class Claim:
    """A robot's position and goal in its own map frame (16 bytes on the wire as float32)."""

    position: np.ndarray
    goal: np.ndarray | None


def next_move(agent, stamp: float) -> tuple[np.ndarray | None, Claim | None]:
    """``agent.next_direction(stamp)`` (an `Explorer`, or anything with its ``claim``,
    ``route`` and ``next_direction``) and the claim to tell its peers where it chose a goal,
    new or kept (they weigh how near it is), or its goal went; else None."""
    had = agent.claim().goal is not None
    direction = agent.next_direction(stamp)
    r = agent.route
    changed = (r is not None and r.chosen_at == stamp) or (had and r is None)
    return direction, agent.claim() if changed else None


def moving_on(status: str) -> bool:
    """Whether a robot with ``status`` explores, or waits for peers that may give up a goal."""
    return status == "exploring" or status.startswith("waiting")


@dataclass
class Knowledge:
    """The team's map in the robot's frame: horizons, the occupancy field, the route graph."""

    space: FreeSpace
    field: OccupancyField | None
    edges: list[tuple[int, int]] = field(default_factory=list)
    last_own: int | None = None  # the robot's latest viewpoint among ``space``'s


class Explorer:
    """See the module docstring. ``share``: False keeps the robot to its own submaps."""

    def __init__(self, robot: str, config: Config | None = None, share: bool = True) -> None:
        self.robot = robot
        self.config = config or Config()
        self.options = self.config.explore
        self.planner_options = self.config.planner
        # Its own horizons, at the heights its body occupies, travel beside each submap.
        build = replace(self.config.build, horizon_band=None)
        self.builder = SubmapBuilder(robot, build, self.config.select)
        self.mapper = Mapper(self.config) if share else None
        self.recorder = HorizonRecorder(
            self.options.bins,
            self.options.horizon_spacing,
            self.planner_options.z_band,
            max_distortion=self.options.max_distortion,
        )
        self.team: dict[Node, SharedSubmap] = {}
        self.claims: dict[str, Claim] = {}
        self.route: Route | None = None
        self.failed: list[np.ndarray] = []
        self.status = "exploring"
        self.position = np.zeros(2)
        self._chosen_at = -math.inf
        self._reoptimize = False
        self._recent: np.ndarray | None = None
        self._recent_anchor = np.eye(4)
        self._knowledge: Knowledge | None = None
        self._dirty = True
        self._share_now = False  # close the submap at the next frame: the peers need its view

    # ---- input ------------------------------------------------------------------------------

    def observe(self, frame: Frame) -> SharedSubmap | None:
        """Maps a frame; returns the submap it completed, with its horizons, to share."""
        self.recorder.add(frame)
        self.position = frame.pose[:2, 3].copy()
        submap = self.builder.add(frame)
        if submap is None and self._share_now:
            submap = self.builder.flush()
        self._share_now = False
        return self._shared(submap)

    def flush(self) -> SharedSubmap | None:
        """The submap of the frames since the last one (the robot stops), to share."""
        return self._shared(self.builder.flush())

    def _shared(self, submap: Submap | None) -> SharedSubmap | None:
        shared = None if submap is None else SharedSubmap(submap, self.recorder.take(submap.anchor))
        if shared is not None:
            self._hold(shared)
        return shared

    def own_horizons(self) -> list[Horizon]:
        """This robot's horizons in its map frame."""
        own = [k for k in self.team if k[0] == self.robot]
        moved = [h.moved(self.team[k].submap.anchor) for k in own for h in self.team[k].horizons]
        return moved + self.recorder.all()

    def receive(self, shared: SharedSubmap) -> None:
        """A peer's submap (ignored without sharing)."""
        if self.mapper is not None:
            self._hold(shared)

    def receive_claim(self, robot: str, claim: Claim) -> None:
        """A peer's claim; one that takes this robot's goal makes its next step choose again."""
        self.claims[robot] = claim
        if self.route is not None and self._taken(self.route.goal, self._joined_peers()):
            self.route.chosen_at = -math.inf
        elif claim.goal is None and self.status.startswith("waiting"):
            self._chosen_at = -math.inf  # the peer's goal is gone: it may have left one

    def claim(self) -> Claim:
        return Claim(self.position.copy(), None if self.route is None else self.route.goal.copy())

    def _hold(self, shared: SharedSubmap) -> None:
        """Own submaps change what the robot steers by at once; peers' wait for its next
        choice of goal (placing them means optimising the pose graph)."""
        s = shared.submap
        self.team[(s.robot, s.seq)] = shared
        if self.mapper is not None:
            matches = self.mapper.add([s], horizons={(s.robot, s.seq): shared.horizons})
            self._reoptimize |= s.robot != self.robot or any(m.accepted for m in matches)
        if s.robot == self.robot:
            self._dirty = True
            self._recent = s.points  # until the next submap: in the live field (anchor frame)
            self._recent_anchor = s.anchor

    # ---- where the team's submaps are -------------------------------------------------------

    def _poses(self) -> dict[Node, np.ndarray]:
        """Each team submap's anchor in this robot's map frame (joined robots only)."""
        poses = {k: v.submap.anchor for k, v in self.team.items() if k[0] == self.robot}
        if self.mapper is None:
            return poses
        if self._reoptimize:
            self.mapper.optimize()
            self._reoptimize = False
        result = self.mapper.result
        if result is None or self.robot not in result.to_reference:
            return poses  # nothing of its own placed yet: nothing to place the others by
        group = self.mapper.group_of(self.robot)
        mine = np.linalg.inv(result.to_reference[self.robot])
        for key in self.team:
            if key[0] in group and key in result.poses:
                poses[key] = mine @ result.poses[key]
        return poses

    def _peer_frame(self, robot: str) -> np.ndarray | None:
        if self.mapper is None or self.mapper.result is None:
            return None
        frames = self.mapper.frames
        if self.robot not in frames.robots or robot not in self.mapper.group_of(self.robot):
            return None
        return frames.transform(self.robot, robot)

    def knowledge(self) -> Knowledge:
        """The team's horizons, field and route graph in this robot's frame (cached until a
        submap arrives)."""
        if self._knowledge is not None and not self._dirty:
            return self._knowledge
        poses = self._poses()
        keys = sorted(poses)
        horizons = [h.moved(poses[k]) for k in keys for h in self.team[k].horizons]
        chains = [k[0] for k in keys for _ in self.team[k].horizons]
        gmms = [self.team[k].submap.gmm.transform(poses[k]) for k in keys]
        shares = [self.team[k].submap.n_points for k in keys]
        team_field = (
            OccupancyField(concatenate(gmms, shares), self.planner_options) if gmms else None
        )
        space = FreeSpace(horizons)
        own = [i for i, robot in enumerate(chains) if robot == self.robot]
        # Held before the edges are found: finding them evaluates this knowledge's field.
        self._knowledge = Knowledge(space, team_field, last_own=own[-1] if own else None)
        self._dirty = False
        self._knowledge.edges = self._edges(space, chains)
        return self._knowledge

    # ---- occupancy --------------------------------------------------------------------------

    def _live_field(self) -> OccupancyField | None:
        """What the sensor saw since the last-but-one submap, as small components (5 cm
        spread): a robot steers clear of what it has just seen, shared or not."""
        parts = []
        if self.builder.anchor is not None and len(self.builder.buffer):
            a = self.builder.anchor
            parts.append(self.builder.buffer.centroids() @ a[:3, :3].T + a[:3, 3])
        if self._recent is not None:
            a = self._recent_anchor
            parts.append(self._recent @ a[:3, :3].T + a[:3, 3])
        if not parts:
            return None
        pts = np.vstack(parts)
        lo, hi = self.planner_options.z_band
        pts = voxel_filter(pts[(pts[:, 2] >= lo) & (pts[:, 2] <= hi)], 0.1)
        if not len(pts):
            return None
        covs = np.tile(np.eye(3) * 0.05**2, (len(pts), 1, 1))
        return OccupancyField(Gmm(np.full(len(pts), 1 / len(pts)), pts, covs), self.planner_options)

    def space(self) -> FreeSpace:
        """The team's horizons and this robot's since its last submap."""
        return FreeSpace([*self.knowledge().space.horizons, *self.recorder.all()])

    def roomy(self, xy: np.ndarray, space: FreeSpace) -> np.ndarray:
        """Whether the robot's footprint about each (N, 2) point is all known free: the
        horizons saw through it. There the team's mixtures may not close a passage: EM spans
        a doorway with the wall's components, and only the horizons say that rays went through
        it. The disc a robot stood on does not count: a depth camera never sees beside it, and
        a robot that passed a wall within `BODY` would take the wall for free."""
        reach = self.planner_options.robot_radius + self.planner_options.margin
        ring = reach * np.stack([np.cos(RING), np.sin(RING)], -1)
        pts = np.atleast_2d(xy)[:, None, :] + np.vstack([np.zeros((1, 2)), ring])[None]
        seen = space.contains(pts.reshape(-1, 2), body=False)
        return seen.reshape(len(pts), -1).all(axis=1)

    def occupancy(
        self, xy: np.ndarray, live: OccupancyField | None, space: FreeSpace | None = None
    ) -> np.ndarray:
        """The team's field where the robot's footprint is not known free, or the live
        field, whichever is larger, at (N, 2) points."""
        xy = np.atleast_2d(xy)
        out = np.zeros(len(xy))
        team = self.knowledge().field
        if team is not None and len(team):
            out = team.occupancy_tiled(xy)
            out[self.roomy(xy, space or self.space())] = 0.0
        if live is not None and len(live):
            out = np.maximum(out, live.occupancy_tiled(xy))
        return out

    def _blocked(self, live: OccupancyField | None, space: FreeSpace | None = None):
        level = self.planner_options.max_occupancy
        space = space or self.space()
        return lambda xy: self.occupancy(xy, live, space) >= level

    # ---- the route graph --------------------------------------------------------------------

    def _edges(self, space: FreeSpace, chains: list[str]) -> list[tuple[int, int]]:
        """Edges between viewpoints: consecutive ones of one robot, and near ones with a known
        free, clear line between them."""
        edges = [(i, i + 1) for i in range(len(chains) - 1) if chains[i] == chains[i + 1]]
        if len(space) < 2:
            return edges
        pairs = cKDTree(space.origins).query_pairs(self.options.link_radius, output_type="ndarray")
        if not len(pairs):
            return edges
        ok = clear_lines(space, space.origins[pairs[:, 0]], space.origins[pairs[:, 1]])
        return edges + [tuple(p) for p in pairs[ok]]

    # ---- goals ------------------------------------------------------------------------------

    def _choose(self, stamp: float, live: OccupancyField | None) -> None:
        self._dirty |= self._reoptimize
        k = self.knowledge()
        o = self.options
        space = self.space()
        fronts = space.frontiers(self._blocked(live, space))
        # A goal where it stands it cannot see past: given up for good. Others given up come
        # last, back once nothing else is left (a route may stick on what nobody saw yet).
        here = [f.goal for f in fronts if np.linalg.norm(f.goal - self.position) < ARRIVED]
        self.failed += here * TRIES
        tries = [sum(np.linalg.norm(f.goal - g) < 0.75 for g in self.failed) for f in fronts]
        fronts = [f for f, n in zip(fronts, tries, strict=True) if n == min(tries) < TRIES]
        if not fronts:
            self._stop("done: no frontier left that it can reach")
            return
        peers = self._joined_peers()
        fronts = [f for f in fronts if not self._taken(f.goal, peers)]
        if not fronts:  # following a peer, it would arrive after it and find nothing left
            self._stop("waiting: the frontiers left are nearer peers' goals")
            return
        # Kinds after peers' goals (a robot waited while the team had one open frontier); its
        # goal kept whatever its kind only among peers, whose submaps and claims change kinds.
        heading = None if self.route is None or not peers else self.route.goal
        fronts = preferred(fronts, o.min_frontier, heading)
        dist, pred, start = self._distances(space, k, live)
        # Through the cheapest viewpoint whose horizon holds the goal, not only the one that
        # found it: that one may lie far back, round a corner the robot has since turned.
        goals, rows = np.array([f.goal for f in fronts]), np.arange(len(fronts))
        seen = space.seen_by(goals, shrink=BACK)
        seen[rows, [f.horizon for f in fronts]] = True
        legs = np.where(seen, np.linalg.norm(goals[:, None] - space.origins[None], axis=2), np.inf)
        through = np.argmin(dist[None, : len(space)] + legs, axis=1)
        via = dist[through] + legs[rows, through]
        # Straight there where the line is known free: a corridor's far end was seen from a
        # viewpoint behind the robot, and the route through it would go back first.
        straight = np.linalg.norm(goals - self.position, axis=1)
        direct = clear_lines(space, np.repeat(self.position[None], len(goals), 0), goals)
        direct &= straight < via
        route_cost = np.where(direct, straight, via)
        costs = [c + self._crowding(f.goal, peers) for c, f in zip(route_cost, fronts, strict=True)]
        best = int(np.argmin(costs))
        if not math.isfinite(costs[best]):
            self.route = None
            self.status = f"stopped: {len(fronts)} frontiers, none reachable on known free space"
            return
        current = self._still_open(fronts, costs, peers)
        if current is not None and costs[current] <= costs[best] + SWITCH_COST:
            self.route.chosen_at = stamp  # keep going: switching goals back and forth wastes more
            return
        f = fronts[best]
        chain, node = [], (start if direct[best] else int(through[best]))
        while node != start and node >= 0:
            chain.append(space.origins[node])
            node = pred[node]
        waypoints = np.array([*reversed(chain), f.goal])
        self.route = Route(waypoints, f.goal, stamp)
        self.status = "exploring"

    def _stop(self, status: str) -> None:
        """No goal left: its submap goes out at once, so that no peer sets out for its view."""
        self._share_now |= self.status == "exploring"
        self.route, self.status = None, status

    def _still_open(self, fronts: list, costs: list[float], peers: list) -> int | None:
        """The frontier the current route heads for, if it is still one and not a peer's."""
        if self.route is None or self._taken(self.route.goal, peers):
            return None
        gaps = [float(np.linalg.norm(f.goal - self.route.goal)) for f in fronts]
        i = int(np.argmin(gaps))
        return i if gaps[i] < SAME_GOAL and math.isfinite(costs[i]) else None

    def _distances(
        self, space: FreeSpace, k: Knowledge, live: OccupancyField | None
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """Route lengths from the robot to every viewpoint (the robot is the last node)."""
        n, own = len(space), len(k.space)
        edges = list(k.edges)
        pending = list(range(own, n))  # this robot's viewpoints since its last submap
        edges += [(i, i + 1) for i in pending[:-1]]
        if pending and k.last_own is not None:
            edges.append((k.last_own, pending[0]))  # it drove from one to the other
        start = n
        near = np.array(
            cKDTree(space.origins).query_ball_point(self.position, self.options.link_radius), int
        )
        if len(near):
            # From just off the robot: it stands where it stands, even inside a margin.
            off = self.position + 0.3 * unit(space.origins[near] - self.position)
            clear = clear_lines(space, off, space.origins[near])
            edges += [(start, int(i)) for i in near[clear]]
        latest = pending[-1] if pending else k.last_own
        if latest is not None:
            edges.append((start, latest))  # the viewpoint it is at, or just left
        e = np.array(edges, dtype=int).reshape(-1, 2)
        pts = np.vstack([space.origins, self.position[None]])
        w = np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1) + 1e-6
        graph = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n + 1, n + 1)).tocsr()
        dist, pred = dijkstra(graph, directed=False, indices=start, return_predecessors=True)
        return dist, pred, start

    def _joined_peers(self) -> list[tuple[np.ndarray, np.ndarray | None]]:
        """Each joined peer's last claim in this robot's frame: (position, goal or None)."""
        out = []
        for robot, claim in self.claims.items():
            T = self._peer_frame(robot)
            if T is not None:
                R, t = T[:2, :2], T[:2, 3]
                goal = None if claim.goal is None else R @ claim.goal + t
                out.append((R @ claim.position + t, goal))
        return out

    def _taken(self, goal: np.ndarray, peers: list) -> bool:
        """Whether a joined peer heads for ``goal`` (its goal within ``claim_radius``) from
        nearer than this robot is (where it last chose: nearer since); a nearer robot takes it
        over and the peer yields at its next choice."""
        mine = float(np.linalg.norm(goal - self.position))
        return any(
            g is not None
            and np.linalg.norm(goal - g) <= self.options.claim_radius
            and np.linalg.norm(g - p) < mine
            for p, g in peers
        )

    def _crowding(self, goal: np.ndarray, peers: list) -> float:
        """A cost for goals nearer a joined peer than this robot: robots spread out."""
        mine = float(np.linalg.norm(goal - self.position))
        return sum(max(0.0, mine - float(np.linalg.norm(goal - p))) for p, _ in peers)

    # ---- moving -----------------------------------------------------------------------------

    def next_direction(self, stamp: float) -> np.ndarray | None:
        """The unit direction (map frame) to move in now, or None: no goal (see ``status``)."""
        r = self.route
        waiting = self.status != "exploring" and stamp - self._chosen_at < self.options.replan_s
        if r is None and waiting and not self._dirty:
            return None  # nothing to do until the team's map changes or time passes
        live = self._live_field()
        if r is None or stamp - r.chosen_at >= self.options.replan_s:
            self._chosen_at = stamp
            self._choose(stamp, live)
            r = self.route
        if r is None:
            return None
        target = r.next_waypoint(self.position)
        if target is None:
            self.route = None  # arrived: the next step chooses again
            return None
        direction = r.steer(self.position, target, self.planner_options, _MaxField(self, live))
        if direction is None:
            self.failed.append(r.goal)
            self.route = None
        return direction


class _MaxField:
    """The field the planner steers on near the robot: the team's, zero where the robot's
    footprint is known free, and the live field, whichever is larger."""

    def __init__(self, explorer: Explorer, live: OccupancyField | None) -> None:
        self.explorer, self.space = explorer, explorer.space()
        team = explorer.knowledge().field
        near = explorer.position
        self.team = team.near(near, 0.5) if team is not None and len(team) else None
        self.live = live.near(near, 0.5) if live is not None and len(live) else None

    def occupancy(self, xy: object) -> np.ndarray:
        return self.gradient(xy)[0]

    def gradient(self, xy: object) -> tuple[np.ndarray, np.ndarray]:
        xy = np.atleast_2d(np.asarray(xy, dtype=np.float64))
        occ, grad = np.zeros(len(xy)), np.zeros((len(xy), 2))
        if self.team is not None and len(self.team):
            occ, grad = self.team.gradient(xy)
            roomy = self.explorer.roomy(xy, self.space)
            occ[roomy], grad[roomy] = 0.0, 0.0
        if self.live is not None and len(self.live):
            o, g = self.live.gradient(xy)
            more = o > occ
            occ[more], grad[more] = o[more], g[more]
        return occ, grad
