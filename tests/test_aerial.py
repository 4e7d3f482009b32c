"""Exploration in 3D: spherical horizons, the 3D field and planner, an aerial robot's run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from gmmap.cli import main
from gmmap.config import Config
from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.eval.explore.aerial import run_aerial
from gmmap.io.sim import Box, Lidar, World
from gmmap.io.sim.world import slab, wall
from gmmap.io.sim.worlds import two_storey
from gmmap.mapping.aerial.explorer import AerialExplorer
from gmmap.mapping.aerial.field import Field3D, Steering
from gmmap.mapping.aerial.space import (
    AZIMUTHS,
    ELEVATIONS,
    SphereHorizon,
    SphereSpace,
    decode_spheres,
    encode_spheres,
    sphere_horizon,
    swept_cells,
)
from gmmap.mapping.frame import Frame
from gmmap.math.gmm import Gmm
from gmmap.options import PlannerOptions


def _tower(void: bool = True) -> World:
    """A 5 m x 4 m building of two 2.5 m storeys joined by a 2 m x 2 m void (or sealed)."""
    s = [slab(0, 0, 5, 4, -0.025), slab(0, 0, 5, 4, 5.025)]
    for a, b in [((0, 0), (5, 0)), ((5, 0), (5, 4)), ((5, 4), (0, 4)), ((0, 4), (0, 0))]:
        s += wall(*a, *b, height=5.0)
    s += [slab(0, 0, 5, 2, 2.5, 0.1), slab(0, 2, 3, 4, 2.5, 0.1)]
    s += [slab(3, 2, 5, 4, 2.5, 0.1)] if not void else []
    s += wall(0, 1.2, 1.6, 1.2, base=2.55, height=2.4)  # a low wall upstairs
    return World("tower", s, start=(1.0, 3.0, 0.0))


def _config(world: str, budget: float) -> Config:
    return Config.from_dict({"sim": {"world": world}, "explore": {"time_budget": budget}})


def test_the_world_distance_is_signed_in_3d():
    w = World("box", [Box((0, 0, 1), (2, 2, 2))])
    d = w.distance([[0, 0, 1], [0, 0, 3], [2, 0, 1], [2, 0, 3]])
    assert d == pytest.approx([-1.0, 1.0, 1.0, math.sqrt(2)])


def test_a_sphere_horizon_sees_free_space_to_the_walls_and_not_past_them():
    w = World("room", [*wall(-2, -2, 2, -2), *wall(2, -2, 2, 2), slab(-2, -2, 2, 2, -0.025)])
    lidar = Lidar(32, 45.0, -45.0, max_range=10.0, noise_std=0.0)
    pose = np.eye(4)
    pose[2, 3] = 1.0
    pts = lidar.scan(w, pose, np.random.default_rng(0))
    h = sphere_horizon(pts, pose[:3, 3], swept_cells(-45, 45), 10.0)
    space = SphereSpace([h])
    assert space.contains([[1.5, 0.0, 1.0], [0.0, -1.5, 1.0]]).all()
    assert not space.contains([[2.5, 0.0, 1.0], [0.0, -2.5, 1.0]]).any()
    assert not space.contains([[0.0, 0.0, 2.9]]).any()  # straight up: never swept
    assert space.blind([[0.0, 0.0, 2.9]]).all()


def test_sphere_horizons_round_trip_and_refuse_garbage():
    rng = np.random.default_rng(1)
    ranges = np.where(rng.random((ELEVATIONS, AZIMUTHS)) < 0.5, np.nan, rng.uniform(0.1, 20, 1))
    far = np.where(rng.random(ranges.shape) < 0.9, np.nan, ranges + 3.0)
    h = SphereHorizon(np.array([1.234, -5.0, 2.5]), ranges, far)
    (back,) = decode_spheres(encode_spheres([h]))
    assert back.origin == pytest.approx(h.origin, abs=0.006)
    for got, sent in ((back.ranges, ranges), (back.far, far)):
        assert np.array_equal(np.isnan(got), np.isnan(sent))
        assert np.nanmax(np.abs(got - sent)) <= 0.1 + 1e-9
    with pytest.raises(FileFormatError):
        decode_spheres(b"not deflated")
    with pytest.raises(FileFormatError):
        decode_spheres(encode_spheres([h])[:-3])
    with pytest.raises(InvalidInputError):
        encode_spheres([SphereHorizon(h.origin, ranges[:3])])


def _corridor(door: float | None) -> World:
    """A 2 m x 14 m corridor with a 5 m x 4 m room off its north wall through a 1 m door
    from x = ``door`` (or none, the room sealed, at x = 9)."""
    x = 9.0 if door is None else door - 2.0
    s = [slab(-1, -3, 15, 8, -0.025), slab(-1, -3, 15, 8, 2.525)]
    s += wall(0, 0, 14, 0) + wall(0, 0, 0, 2) + wall(14, 0, 14, 2)
    s += wall(0, 2, 14, 2) if door is None else wall(0, 2, door, 2) + wall(door + 1, 2, 14, 2)
    s += wall(x, 2, x, 6) + wall(x, 6, x + 5, 6) + wall(x + 5, 2, x + 5, 6)
    return World("corridor", s)


def test_a_doorway_seen_down_a_corridor_is_glimpsed_and_looked_at_from_the_corridor():
    lidar = Lidar(32, 45.0, -45.0, max_range=20.0, noise_std=0.0)
    world, horizons = _corridor(11.0), []
    for x in (1.0, 5.0):
        pose = np.eye(4)
        pose[:3, 3] = [x, 1.0, 1.2]
        pts = lidar.scan(world, pose, np.random.default_rng(0)) + pose[:3, 3]
        horizons.append(sphere_horizon(pts, pose[:3, 3], swept_cells(-45, 45), 0.3))
    g = np.stack(np.meshgrid(np.arange(2, 14, 0.2), np.arange(-2.5, 5.8, 0.2), [1.0, 1.4]), -1)
    g = g.reshape(-1, 3)
    room, behind = g[g[:, 1] > 2.2], g[(g[:, 1] < -0.3) & (g[:, 0] > 4) & (g[:, 0] < 6)]
    space = SphereSpace(horizons)
    assert not space.contains(room).any()  # the 10° cells hold the wall beside the door
    seer = space.glimpsed(room)
    look = space.look_outs(room[seer >= 0], seer[seer >= 0])
    assert (seer >= 0).sum() > 5 and not np.isnan(look).any()
    assert space.contains(look).all()
    assert ((look[:, 1] > 0.0) & (look[:, 1] < 1.9)).all()  # in the corridor, short of the wall
    # A cell of the far viewpoint grazing the south wall holds space behind it; the nearer
    # viewpoint abeam of it saw the wall and nothing past.
    assert (SphereSpace(horizons[:1]).glimpsed(behind) >= 0).any()
    assert (space.glimpsed(behind) < 0).all()


@pytest.mark.parametrize("door", [7.0, None])
def test_walls_seen_through_a_doorway_are_looked_at_from_the_corridor(door: float | None):
    lidar = Lidar(32, 45.0, -45.0, max_range=20.0, noise_std=0.0)
    explorer = AerialExplorer("r", swept_cells(-45, 45), 0.3)
    world = _corridor(door)
    for k, x in enumerate(np.arange(1.0, 6.0, 0.25)):
        pose = np.eye(4)
        pose[:3, 3] = [x, 1.0, 1.2]
        pts = lidar.scan(world, pose, np.random.default_rng(k))
        explorer.observe(Frame(float(k), pts, pose, pose))
    explorer.flush()
    space = explorer.space()
    lost, by = explorer.unsighted(space)
    in_room = lost[:, 1] > 2.1
    assert in_room.any() == (door is not None)  # seen through the door, or not at all
    if door is not None:
        look = space.look_outs(lost[in_room], by[in_room])
        look = look[~np.isnan(look[:, 0])]
        assert len(look) and space.contains(look).all()
        assert ((look[:, 1] > 0.0) & (look[:, 1] < 2.0)).all()  # in the corridor


def test_a_yawed_horizon_turns_with_its_frame():
    ranges = np.full((ELEVATIONS, AZIMUTHS), 1.0)
    ranges[8:11, 0] = 5.0  # level, towards +x
    T = np.eye(4)
    T[:2, :2] = [[0, -1], [1, 0]]  # 90° about z
    moved = SphereSpace([SphereHorizon(np.zeros(3), ranges).moved(T)])
    assert moved.contains([[-0.25, 3.0, 0.05]]).all()  # 95°: the cell of 0° turned by 90°
    assert not moved.contains([[3.0, 0.25, 0.05]]).any()


def _wall_gmm() -> Gmm:
    """A 4 m x 2 m wall in the plane x = 1 as 8 flat components."""
    means = np.array([[1.0, y, z] for y in (-1.5, -0.5, 0.5, 1.5) for z in (0.5, 1.5)])
    covs = np.tile(np.diag([0.01**2, 0.29**2, 0.29**2]), (len(means), 1, 1))
    return Gmm(np.full(len(means), 1 / len(means)), means, covs)


def test_the_3d_field_is_high_at_a_surface_and_the_same_however_it_is_evaluated():
    field = Field3D(_wall_gmm())
    occ = field.occupancy([[1.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 3.5]])
    assert occ[0] > PlannerOptions().max_occupancy and occ[1] < 0.05 and occ[2] < 0.05
    grid = np.random.default_rng(2).uniform(-1, 3, (1000, 3))
    small = np.concatenate([field.occupancy(grid[i : i + 100]) for i in range(0, 1000, 100)])
    assert field.occupancy(grid) == pytest.approx(small, abs=1e-9)


def test_the_3d_planner_flies_round_a_wall_to_a_goal_behind_it():
    field, options = Field3D(_wall_gmm()), PlannerOptions()
    position, goal, steering = np.array([0.0, 0.3, 1.0]), np.array([2.0, 0.0, 1.0]), None
    steering = Steering(options)
    for _ in range(100):
        direction = steering.next(field.occupancy, position, goal, 0.1)
        assert direction is not None
        position = position + 0.1 * direction
        assert field.occupancy(position[None])[0] < options.max_occupancy
        if np.linalg.norm(position - goal) < 0.15:
            break
    assert np.linalg.norm(position - goal) < 0.15


def test_an_aerial_robot_flies_up_through_a_void_and_covers_both_storeys(tmp_path):
    path, out = tmp_path / "tower.json", tmp_path / "out"
    _tower().save(path)
    args = ["explore", "--aerial", "--world", str(path), "--time-budget", "120", "--json"]
    result = CliRunner().invoke(main, [*args, "--out", str(out)])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["coverage"] >= 0.9 and report["collisions"] == 0 and report["robots"] == 1
    assert report["statuses"] == ["done: no frontier left that it can reach"]
    assert report["bytes_per_robot"][0] > 0 and "baselines" not in report
    z = np.array(json.loads((out / "result.json").read_text())["runs"]["aerial"]["paths"][0])
    assert z[:, 2].max() > 2.6 and z[:, 2].min() < 2.4  # both storeys


def test_a_sealed_storey_is_never_reached_and_coverage_is_against_the_true_world(tmp_path):
    path = tmp_path / "sealed.json"
    _tower(void=False).save(path)
    r = run_aerial(_config(str(path), 120.0))
    assert max(p[2] for p in r.paths[0]) < 2.5
    # The upper storey cannot be reached: its surfaces are not counted, so the robot that
    # explored all it could reach is done with its reachable world covered.
    assert r.statuses == ["done: no frontier left that it can reach"] and r.coverage >= 0.9


def test_the_aerial_robot_needs_its_lidar():
    cfg = Config.from_dict({"sim": {"world": "two-storey", "sensor": "depth"}})
    with pytest.raises(InvalidInputError):
        run_aerial(cfg)


def test_the_two_storey_world_joins_its_storeys_only_through_the_void():
    from gmmap.eval.explore.coverage import volume_samples

    w = two_storey()
    space = volume_samples(w, np.array([2.5, 5.5, 1.2]), 0.25)
    upper = space[space[:, 2] > 3.2]
    assert len(upper) and (space[:, 2] < 2.8).any()
    through = space[(space[:, 2] > 2.9) & (space[:, 2] < 3.1)]
    assert ((through[:, 0] > 8.5) & (through[:, 0] < 11.5) & (through[:, 1] > 5)).all()


def test_the_half_of_a_cell_next_to_a_nearer_one_claims_no_farther_than_it():
    ranges = np.full((ELEVATIONS, AZIMUTHS), np.nan)
    ranges[9], ranges[10] = 9.0, 3.0  # 0-10° free to 9 m; 10-20°: a ceiling at 3 m
    space = SphereSpace([SphereHorizon(np.zeros(3), ranges)])
    at = [5 * np.array([math.cos(math.radians(d)), 0, math.sin(math.radians(d))]) for d in (2, 8)]
    assert space.contains(at).tolist() == [True, False]
