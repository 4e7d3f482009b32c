"""Exploration: horizons on the wire, frontiers, and simulated robots exploring small worlds
with a short-range LiDAR (so that they must move to see), measured against the true world."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from gmmap.cli import main
from gmmap.config import Config
from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.eval.explore.coverage import Coverage
from gmmap.eval.explore.team import run_explore
from gmmap.io.sim import World, sim_sensor
from gmmap.io.sim.run import floor_pose, sensed
from gmmap.io.sim.world import slab, wall
from gmmap.mapping.explore import TRIES, Explorer
from gmmap.mapping.frame import Frame
from gmmap.mapping.frontier import (
    FreeSpace,
    Horizon,
    HorizonRecorder,
    decode_horizons,
    encode_horizons,
    horizon_from,
    preferred,
)
from gmmap.mapping.planner import OccupancyField
from gmmap.math.gmm import Gmm
from gmmap.options import ExploreOptions, PlaceOptions


def closed(name: str, x1: float, y1: float, inner: list, start) -> World:
    shapes = [slab(0, 0, x1, y1, -0.025)]
    for a, b in (((0, 0), (x1, 0)), ((x1, 0), (x1, y1)), ((x1, y1), (0, y1)), ((0, y1), (0, 0))):
        shapes += wall(*a, *b)
    return World(name, shapes + inner, start=start)


def corridor() -> World:
    """A 1.6 m wide corridor, 16 m long; the robots start in its middle."""
    return closed("corridor", 16.0, 1.6, [], (8.0, 0.8, 0.0))


def two_rooms() -> World:
    """Two 5 x 5 m rooms either side of a 2 m hall, a door into each; start in the hall. The
    doors are not opposite: a world the same turned half round would leave the robots no way
    to tell their maps' right join from its 180° flip."""
    inner = wall(5.0, 0, 5.0, 5.0, doors=((2.5, 1.0),)) + wall(
        7.0, 0, 7.0, 5.0, doors=((1.5, 1.0),)
    )
    return closed("two-rooms", 12.0, 5.0, inner, (6.0, 1.2, np.pi / 2))


def config(world: str, robots: int, budget: float = 200.0, reach: float = 5.0) -> Config:
    base = Config()
    return replace(
        base,
        sim=replace(base.sim, world=world, robots=robots, sensor="lidar", lidar_range=reach),
        explore=replace(base.explore, time_budget=budget),
    )


def saved(world: World, tmp_path) -> str:
    path = tmp_path / f"{world.name}.json"
    world.save(path)
    return str(path)


# ---- horizons and frontiers -----------------------------------------------------------------


def _spread(at, points, bins: int = 72) -> np.ndarray:
    """Each point as a sensor sees a surface: returns across its whole direction bin from
    ``at``, at the point's range and height."""
    out = []
    for p in np.atleast_2d(points):
        d = p[:2] - np.asarray(at)
        r, width = np.hypot(*d), 2 * math.pi / bins
        start = math.floor(math.atan2(d[1], d[0]) / width) * width
        for a in start + width * np.array([0.05, 0.5, 0.95]):
            out.append([at[0] + r * math.cos(a), at[1] + r * math.sin(a), p[2]])
    return np.array(out)


def test_a_horizon_keeps_the_nearest_return_and_leaves_unseen_directions_unknown():
    pts = np.array([[2.0, 0.05, 0.5], [3.0, 0.05, 0.5], [0.0, 1.5, 0.0], [0.0, 4.0, 2.5]])
    r = horizon_from(_spread((0, 0), pts), np.zeros(2), (0.05, 1.2), 72)
    assert r[0] == pytest.approx(2.0, abs=1e-3)  # the nearer wall point in the band
    assert r[18] == pytest.approx(1.5)  # a floor return: free that far
    assert np.isnan(r[36]) and np.isnan(r[54])  # nothing seen; above the band says nothing
    # The edge of a camera's view grazes a direction: what it missed may hold a nearer wall.
    edge = horizon_from(_spread((0, 0), pts)[:2], np.zeros(2), (0.05, 1.2), 72)
    assert np.isnan(edge[0])


def test_horizons_round_trip_the_wire_and_garbage_is_a_typed_error():
    ranges = np.full(72, np.nan)
    ranges[:10] = np.linspace(0.5, 12.0, 10)
    h = [Horizon(np.array([1.23, -4.56]), ranges), Horizon(np.zeros(2), np.full(72, 3.0))]
    data = encode_horizons(h)
    back = decode_horizons(data)
    assert len(data) < 2 * 76
    assert np.allclose(back[0].origin, [1.23, -4.56])
    assert np.array_equal(np.isnan(back[0].ranges), np.isnan(ranges))
    assert np.nanmax(np.abs(back[0].ranges - ranges)) <= 0.1 + 1e-9  # floored to 10 cm
    for bad in (b"", b"not a horizon", data[:-3]):
        with pytest.raises(FileFormatError):
            decode_horizons(bad)


def _frame(at, points) -> Frame:
    pose = np.eye(4)
    pose[:2, 3] = at
    return Frame(0.0, np.asarray(_spread(at, points), dtype=np.float32) - [*at, 0.0], pose)


def test_a_view_from_elsewhere_does_not_free_a_jamb_beside_the_viewpoint():
    """A horizon's viewpoint north of a wall whose end (a door jamb) lies 0.5 m south of it;
    the next view, 0.94 m away through the door, sees a wall far south. The line from the
    viewpoint to what that view saw crosses the jamb, which nobody saw: it must stay unknown
    (traced: a depth robot's collision on random-office:109). Binned from the viewpoint, the
    view would free it: it starts a horizon of its own."""
    wall = [[x, -3.0, 0.5] for x in np.linspace(-0.5, 1.1, 60)]
    for distortion, freed in ((None, True), (ExploreOptions().max_distortion, False)):
        recorder = HorizonRecorder(72, 1.0, (0.05, 1.2), max_distortion=distortion)
        recorder.add(_frame([0.3, 0.5], [[0.3, 3.0, 0.5]]))
        recorder.add(_frame([-0.1, -0.35], wall))
        assert FreeSpace(recorder.all()).contains([[0.3, 0.0]], body=False)[0] == freed


def test_a_view_through_a_door_does_not_free_the_wall_beside_it():
    """Traced: a depth robot on random-office:101 drove into a door jamb. A horizon's viewpoint
    is 0.5 m north of a wall (y 4.69-4.79, a door at x < 1.86) and has seen north only; the
    next view, 0.84 m away through the door, sees a room far to the south-east. The lines from
    the viewpoint to that room cross the wall just past the jamb: a thin stretch, next to the
    room's area, that nobody saw. It must stay unknown."""
    room = np.c_[np.linspace(1.0, 8.0, 700), np.full(700, 1.5), np.full(700, 0.5)]
    pose = np.eye(4)
    pose[:2, 3] = [1.66, 4.47]
    through = Frame(0.0, np.asarray(room - pose[:3, 3], dtype=np.float32), pose)
    for distortion, freed in ((None, True), (ExploreOptions().max_distortion, False)):
        recorder = HorizonRecorder(72, 1.0, (0.05, 1.2), max_distortion=distortion)
        recorder.add(_frame([1.67, 5.31], [[1.67, 8.0, 0.5]]))
        recorder.add(through)
        inside_wall = FreeSpace(recorder.all()).contains([[2.0, 4.74], [2.1, 4.72]], body=False)
        assert inside_wall.any() == freed


def test_free_space_is_inside_some_horizon_and_frontiers_lie_beside_it():
    ranges = np.full(72, np.nan)
    ranges[:18] = 4.0  # a quarter of the view, 4 m deep, nothing blocks it
    space = FreeSpace([Horizon(np.zeros(2), ranges)])
    assert space.contains([[1.0, 1.0], [3.0, 0.5]]).all()
    assert not space.contains([[-1.0, 1.0], [5.0, 0.5]]).any()
    fronts = space.frontiers(lambda xy: np.zeros(len(xy), bool))
    assert fronts and all(space.contains(f.goal[None])[0] for f in fronts)
    # Walls all round the view: nothing is left to explore.
    assert space.frontiers(lambda xy: ~space.contains(xy, shrink=0.2)) == []


def test_a_frontier_is_open_only_where_unknown_space_lies_behind_it():
    """A gap between two seen discs hides nothing; the rim facing the unseen does."""
    full = np.full(72, 1.0)
    space = FreeSpace([Horizon(np.zeros(2), full), Horizon(np.array([2.6, 0.0]), full)])
    wall_north = lambda xy: np.asarray(xy)[:, 1] > 1.6  # noqa: E731
    probes = np.array([[1.3, 0.0], [-1.3, 0.0], [0.0, 1.3], [0.0, -1.3]])
    targets = 0.7 * probes
    assert space._open(probes, targets, wall_north).tolist() == [False, True, False, True]
    fronts = space.frontiers(wall_north)
    assert sum(f.open for f in fronts) < sum(f.size for f in fronts)


def test_a_blocked_target_moves_back_along_its_line_only_as_far_as_clears_it():
    """A surface across the line to a far frontier's target (a door jamb seen at a slant)
    moves the target back towards the viewpoint by the least step that clears it: from
    nearer, the robot could not see past the opening."""
    ranges = np.full(72, np.nan)
    ranges[:9] = 8.0  # 45° of view, 8 m deep: the far frontier's target lies at 7.6 m
    space = FreeSpace([Horizon(np.zeros(2), ranges)])

    def far_target(ring: tuple[float, float]) -> float:
        def blocked(xy):
            r = np.hypot(*np.asarray(xy).T)
            return (r > ring[0]) & (r < ring[1])

        fronts = space.frontiers(blocked)
        far = max(fronts, key=lambda f: np.hypot(*f.goal))
        assert not blocked(far.goal[None])[0]
        return float(np.hypot(*far.goal))

    assert far_target((0.0, 0.0)) == pytest.approx(7.6, abs=0.05)
    assert far_target((7.5, 7.7)) == pytest.approx(7.35, abs=0.05)  # back 0.25 m
    assert far_target((7.0, 7.7)) == pytest.approx(6.6, abs=0.05)  # back 1 m, not a quarter


def corridor_explorer() -> tuple[Explorer, OccupancyField]:
    """A robot in the middle of a corridor it saw 7.6 m down either way, and its walls."""
    angle = (np.arange(72) + 0.5) * 2 * np.pi / 72
    explorer = Explorer("robot_0", config("corridor", 1))
    explorer.recorder.closed = [
        Horizon(np.zeros(2), np.minimum(8.0, 0.7 / np.maximum(np.abs(np.sin(angle)), 1e-9)))
    ]
    along = np.arange(-9.0, 9.0, 0.1)
    pts = np.vstack(
        [np.c_[along, np.full_like(along, y), np.full_like(along, 0.5)] for y in (-0.8, 0.8)]
    )
    seen = Gmm(np.full(len(pts), 1 / len(pts)), pts, np.tile(np.eye(3) * 0.05**2, (len(pts), 1, 1)))
    return explorer, OccupancyField(seen, explorer.planner_options)


def test_a_given_up_goal_comes_back_once_nothing_else_is_left():
    """Goals the planner gave up on come last, are tried again once no other is left, and
    are left for good after ``TRIES``; a goal the robot stands on is left at once."""
    explorer, live = corridor_explorer()

    def goal(failed: list, at=(0.0, 0.0)):
        explorer.failed, explorer.route = list(failed), None
        explorer.position = np.array(at)
        explorer._choose(0.0, live)
        return None if explorer.route is None else explorer.route.goal

    east = goal([])  # the corridor's two ends, 7.6 m either way
    west = goal([east])
    assert abs(east[0]) > 7.0 and west[0] == pytest.approx(-east[0], abs=0.1)
    np.testing.assert_allclose(goal([east, west]), east)  # both failed once: back to the first
    assert goal([east, west] * TRIES) is None
    assert explorer.status == "done: no frontier left that it can reach"
    # Standing on one end while it stays a frontier: the other, then nothing.
    np.testing.assert_allclose(goal([], at=east), west)
    assert len(explorer.failed) == TRIES and goal(explorer.failed + [west] * TRIES) is None


def test_a_robot_takes_what_peers_leave_it_and_keeps_its_goal_whatever_its_kind(monkeypatch):
    """The one frontier with unknown space behind it is a nearer peer's goal: the robot takes
    the other rather than wait. Once the peer's goal has gone, it keeps that goal, though it
    is not the kind it would choose first; alone, it would not."""
    explorer, live = corridor_explorer()
    frontiers = FreeSpace.frontiers

    def east_open(space, blocked):
        return [replace(f, open=f.size * (f.goal[0] > 0)) for f in frontiers(space, blocked)]

    monkeypatch.setattr(FreeSpace, "frontiers", east_open)
    explorer._choose(0.0, live)
    east = explorer.route.goal
    assert east[0] > 7.0
    peers = [(east - [1.0, 0.0], east)]
    monkeypatch.setattr(explorer, "_joined_peers", lambda: peers)
    explorer.route = None
    explorer._choose(0.0, live)
    assert explorer.status == "exploring" and explorer.route.goal[0] < -7.0
    peers[0] = (east - [1.0, 0.0], None)  # the peer's goal is gone
    explorer._choose(4.0, live)
    assert explorer.route.goal[0] < -7.0
    # A lone robot drops a goal of a lesser kind: what it sees itself changes kinds.
    peers.clear()
    explorer._choose(8.0, live)
    assert explorer.route.goal[0] > 7.0
    assert preferred(explorer.space().frontiers(explorer._blocked(live)), 3, None)[0].goal[0] > 7


def test_explore_options_are_checked():
    with pytest.raises(InvalidInputError):
        ExploreOptions(bins=4)
    with pytest.raises(InvalidInputError):
        ExploreOptions(time_budget=0)
    for bad in (-0.1, 1.5, math.nan):
        with pytest.raises(InvalidInputError, match="max_distortion"):
            ExploreOptions(max_distortion=bad)


# ---- coverage is measured against the true world --------------------------------------------


def test_coverage_counts_the_true_world_not_the_map():
    world = two_rooms()
    truth = Coverage(world, np.array([[6.0, 1.2]]))
    samples = truth.samples
    on_walls = Gmm(
        np.full(len(samples), 1 / len(samples)),
        samples,
        np.tile(np.eye(3) * 1e-4, (len(samples), 1, 1)),
    )
    moved = Coverage(world, np.array([[6.0, 1.2]]))
    moved.add_gmm(
        on_walls.transform(np.array([[1, 0, 0, 0.5], [0, 1, 0, 0.5], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    )
    truth.add_gmm(on_walls)
    assert truth.surface > 0.99
    assert moved.surface < 0.3  # a map half a metre off covers little of the world


# ---- joining on what a peer saw through -----------------------------------------------------


def walked(
    i: int, route: list, world: World, level_planes: bool = False
) -> tuple[Explorer, list, np.ndarray]:
    """Robot i's `Explorer` after walking ``route`` (floor points) through ``world`` with the
    tests' LiDAR, the submaps it shared, and its map frame in the world. ``level_planes``:
    search on the whole mixtures only (`RegisterOptions.level_planes`)."""
    base = config(world.name, 2)
    base = replace(base, register=replace(base.register, level_planes=level_planes))
    explorer = Explorer(f"robot_{i}", base)
    start = floor_pose(*route[0], np.pi / 2)
    sensor, shared, t = sim_sensor(explorer.config.sim), [], 0.0
    for a, b in zip(np.array(route[:-1]), np.array(route[1:]), strict=True):
        yaw = float(np.arctan2(*(b - a)[::-1]))
        for s in np.linspace(0, 1, 6, endpoint=False):
            frame = sensed(sensor, world, 0, i, t, floor_pose(*(a + s * (b - a)), yaw), start)
            shared.append(explorer.observe(frame))
            t += 0.2
    shared.append(explorer.flush())
    return explorer, [s for s in shared if s is not None], start


def test_a_join_that_puts_walls_where_a_peer_saw_free_space_is_refused():
    """Two robots leave the hall of `two_rooms` for opposite rooms: each submap's hall and
    room line up with the other's turned half round (over the whole mixtures, floor included,
    a higher C than the right alignment), and only the horizons tell: the flip puts walls
    where the other robot's rays went through. The same pair at its true alignment puts none
    there. The search ranks on the upright parts by default, where the flip does not win; it
    is searched on the whole mixtures here so that free space has a flip to refuse."""
    world = two_rooms()
    east, _, e_start = walked(0, [(6, 1.2), (6.2, 1.5), (7.8, 1.5), (9.3, 2.4)], world, True)
    _, shared, w_start = walked(1, [(6, 2.0), (5.8, 2.5), (4.4, 3.0), (3.5, 3.0)], world, True)
    for s in shared:
        east.receive(s)
    mapper = east.mapper
    truth = np.linalg.inv(e_start) @ w_start  # robot_1's map frame in robot_0's
    flips = []
    for m in mapper.matches:
        query = mapper.submaps[m.query]
        candidate = mapper.submaps[m.candidate.robot, m.candidate.seq]
        right = np.linalg.inv(candidate.anchor) @ truth @ query.anchor
        if np.linalg.norm(m.registration.transform[:3, 3] - right[:3, 3]) > 0.5:
            assert not m.accepted
            flips.append(m)
        aligned = replace(m, registration=replace(m.registration, transform=right), accepted=True)
        assert mapper._unseen(query, aligned).seen_through == 0.0
    limit = east.config.place.max_seen_through
    assert any(m.seen_through > limit and m.registration.confidence > 0.7 for m in flips)
    for bad in (-0.1, 1.5, math.nan):
        with pytest.raises(InvalidInputError, match="max_seen_through"):
            PlaceOptions(max_seen_through=bad)


# ---- simulated robots exploring -------------------------------------------------------------


def test_a_robot_in_a_corridor_reaches_one_end_and_turns_back_to_the_other(tmp_path):
    """A 5 m LiDAR sees an end wall from 5 m: the robot must go that near each end."""
    r = run_explore(config(saved(corridor(), tmp_path), 1))
    xs = np.array(r.paths[0])[:, 0]
    near_end = (xs < 5.0) | (xs > 11.0)
    assert near_end.any(), "it never reached an end"
    first = int(np.argmax(near_end))
    later = xs[first:]
    assert ((later > 11.0) if xs[first] < 8.0 else (later < 5.0)).any(), "it did not turn back"
    assert r.collisions == 0
    assert r.statuses[0].startswith("done")
    assert r.coverage > 0.9 and r.area > 0.9


def test_the_far_end_of_a_corridor_seen_lengthwise_is_still_a_goal(tmp_path):
    """A 10 m LiDAR down a 24 x 1.6 m corridor sees its far part across a few directions only:
    a frontier of one or two points, which must still be visited once nothing larger is left."""
    long = closed("long", 24.0, 1.6, [], (1.0, 0.8, 0.0))
    r = run_explore(config(saved(long, tmp_path), 1, reach=10.0))
    assert np.array(r.paths[0])[:, 0].max() > 12.0, "it stopped where it started"
    assert r.coverage > 0.9 and r.collisions == 0


def test_a_robot_heads_straight_for_a_frontier_it_has_a_free_line_to():
    """The far end of a corridor seen from a viewpoint the robot has since left behind it: the
    route goes on, not back to that viewpoint first."""
    angle = (np.arange(72) + 0.5) * 2 * np.pi / 72
    reach = np.minimum(8.0, 0.7 / np.maximum(np.abs(np.sin(angle)), 1e-9))
    reach[np.cos(angle) < 0] = np.minimum(reach[np.cos(angle) < 0], 0.8)  # a wall behind
    explorer = Explorer("robot_0", config("corridor", 1))
    explorer.recorder.closed = [Horizon(np.zeros(2), reach)]
    explorer.position = np.array([4.0, 0.0])
    along = np.arange(-0.9, 12.0, 0.1)
    across = np.arange(-0.8, 0.81, 0.1)
    walls = np.vstack([np.c_[along, np.full_like(along, y)] for y in (-0.8, 0.8)])
    walls = np.vstack([walls, np.c_[np.full_like(across, -0.9), across]])
    pts = np.c_[walls, np.full(len(walls), 0.5)]
    seen = Gmm(np.full(len(pts), 1 / len(pts)), pts, np.tile(np.eye(3) * 0.05**2, (len(pts), 1, 1)))
    explorer._choose(0.0, OccupancyField(seen, explorer.planner_options))
    route = explorer.route
    assert route is not None and route.goal[0] > 7.0
    assert len(route.waypoints) == 1, f"goes back through {route.waypoints[:-1]}"


def assert_in_different_rooms(r) -> None:
    """A two-room run (`two_rooms`) ended with no collision, one robot in each room and the
    world covered."""
    assert r.collisions == 0
    ends = [np.array(p[-1]) for p in r.paths]
    rooms = sorted("west" if e[0] < 5.0 else "east" if e[0] > 7.0 else "hall" for e in ends)
    assert rooms == ["east", "west"], f"ended at {ends}"
    assert r.coverage > 0.9


def test_two_robots_in_two_rooms_end_in_different_rooms(tmp_path):
    assert_in_different_rooms(run_explore(config(saved(two_rooms(), tmp_path), 2)))


def test_a_goal_behind_a_wall_is_reached_around_it():
    """The corner world's second arm is behind the wall the robot starts beside: it gets there
    by the corner, never through the wall."""
    r = run_explore(config("corner", 1))
    path = np.array(r.paths[0])
    assert r.collisions == 0
    assert (path[:, 1] > 3.0).any(), "it never entered the far arm"
    assert r.area > 0.9 and r.coverage > 0.75


def test_a_robot_boxed_in_stops_with_a_clear_status(tmp_path):
    box = closed("box", 2.0, 2.0, [], (1.0, 1.0, 0.0))
    r = run_explore(config(saved(box, tmp_path), 1, budget=60.0))
    assert r.sim_time_s < 30.0
    assert r.statuses == ["done: no frontier left that it can reach"]
    assert r.collisions == 0


def test_the_cli_reports_the_run_and_its_baselines(tmp_path):
    world = saved(closed("room", 4.0, 3.0, [], (2.0, 1.5, 0.0)), tmp_path)
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main,
        [
            "explore",
            "--world",
            world,
            "--robots",
            "2",
            "--time-budget",
            "40",
            "--json",
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout.strip().splitlines()[-1])
    keys = {"coverage", "time_to_90_s", "collisions", "bytes_per_robot", "robots", "world"}
    assert keys <= set(report)
    assert set(report["baselines"]) == {"alone", "no_sharing", "dense"}
    for run in (report, *report["baselines"].values()):
        assert keys <= set(run) and run["collisions"] == 0
    assert report["baselines"]["alone"]["robots"] == 1
    assert sum(report["baselines"]["dense"]["bytes_per_robot"]) > 20 * sum(
        report["bytes_per_robot"]
    )
    assert (out / "result.json").exists() and (out / "coverage.png").exists()


def test_the_demo_explores_when_asked(tmp_path):
    world = saved(closed("room", 4.0, 3.0, [], (2.0, 1.5, 0.0)), tmp_path)
    args = ["demo", "--explore", "--world", world, "--robots", "2", "--json"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["robots"] == 2 and "baselines" not in report and report["coverage"] > 0.8


def test_a_footprint_that_a_wall_cuts_between_its_test_points_is_not_known_free():
    """A horizon sees a wall 1 m out; a robot whose radius plus margin (0.25 m) reaches past
    it must not take its footprint for free, wherever the wall falls between test points."""
    normal = np.radians(22.5)  # halfway between two of 8 test directions
    lo = np.arange(360.0)
    nearest = np.radians(np.clip(22.5, lo, lo + 1) - 22.5)  # each 1° bin's nearest wall point
    ranges = np.where(np.cos(nearest) > 0.2, 1.0 / np.maximum(np.cos(nearest), 0.2), 5.0)
    space = FreeSpace([Horizon(np.zeros(2), np.minimum(ranges, 5.0))])
    n = np.array([np.cos(normal), np.sin(normal)])
    explorer = Explorer("a")
    assert explorer.roomy(0.74 * n[None], space)[0]  # 0.26 m from the wall
    assert not explorer.roomy(0.755 * n[None], space)[0]  # 0.245 m: the wall cuts it


def test_where_a_robot_stood_is_free_but_not_seen_through():
    """The disc about a viewpoint is free for routes, not for the planner's field: a depth
    camera never sees beside its robot, which may have passed a wall within that disc."""
    space = FreeSpace([Horizon(np.zeros(2), np.full(72, np.nan))])
    assert space.contains(np.array([[0.3, 0.0]]))[0]
    assert not Explorer("a").roomy(np.zeros((1, 2)), space)[0]
