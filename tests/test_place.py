"""Place recognition: descriptor invariances, database queries, verification."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gmmap.errors import InvalidInputError
from gmmap.eval.place import positives, pr_curve, recall_curve
from gmmap.io.sim import DepthCamera, Lidar, World, sense, simulate
from gmmap.io.sim.world import Box, cabinet, chair, pillar, shelf, slab, table, wall
from gmmap.mapping.frame import Frame
from gmmap.mapping.place import (
    PlaceDatabase,
    PlaceOptions,
    ShapeDescriptor,
    half_turned,
    resample,
    turned,
)
from gmmap.mapping.submap import BuildOptions, build_submaps
from gmmap.math.em import fit_gmm
from gmmap.math.gmm import Gmm
from gmmap.math.register import register
from gmmap.options import RegisterOptions


def yaw_matrix(yaw: float, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = t
    return T


def two_rooms() -> World:
    """A 6 m square room and a 9 m x 4 m hall, furnished differently, 8 m apart; robots 0 and
    1 cross the room along nearby paths, robot 2 crosses the hall."""
    shapes = wall(0, 0, 6, 0) + wall(0, 6, 6, 6) + wall(0, 0, 0, 6) + wall(6, 0, 6, 6)
    shapes += wall(14, 1, 23, 1) + wall(14, 5, 23, 5) + wall(14, 1, 14, 5) + wall(23, 1, 23, 5)
    shapes += table(4.5, 2.0) + chair(4.5, 2.8) + shelf(5.7, 4.5, yaw=math.pi / 2)
    shapes += pillar(3.0, 4.5) + cabinet(1.0, 5.6)
    shapes += table(18.0, 4.5, w=2.5, yaw=0.4) + pillar(16.5, 1.5, 0.35)
    shapes += cabinet(19.6, 1.0, yaw=math.pi / 2) + cabinet(19.6, 2.0, yaw=math.pi / 2)
    routes = [
        [(1.0, 1.5), (2.5, 2.0)],
        [(1.2, 2.3), (2.7, 2.6)],
        [(15.0, 3.0), (16.5, 3.5)],
    ]
    return World("two-rooms", shapes, routes)


@pytest.fixture(scope="module")
def small_gmm(slice_points):
    return fit_gmm(slice_points, 30, seed=0)


@pytest.fixture(scope="module")
def room_submaps():
    run = simulate(two_rooms(), robots=3, seed=0, max_frames=15)
    options = BuildOptions(frames_per_submap=15, voxel_size=0.08, n_components=60)
    return [next(iter(build_submaps(r, r.name, options))) for r in run]


def test_resample_is_seeded_and_sized(small_gmm):
    a, b = resample(small_gmm, 500, seed=3), resample(small_gmm, 500, seed=3)
    assert a.shape == (500, 3) and np.array_equal(a, b)


def test_yawed_copy_same_key_and_yaw_within_one_sector(room_submaps):
    descriptor = ShapeDescriptor()
    gmm = room_submaps[0].gmm
    points = resample(gmm)
    sector = 2 * math.pi / descriptor.sectors
    for yaw in (0.7, -2.0, 3.0):
        turned = gmm.transform(yaw_matrix(yaw, (1.5, -0.4, 0.0)))
        key_a = descriptor.describe_points(points)
        key_b = descriptor.describe_points(resample(turned))
        assert 1 - key_a @ key_b < 0.01
        estimate = descriptor.yaw(points, resample(turned))
        error = (estimate - yaw + math.pi) % (2 * math.pi) - math.pi
        assert abs(error) <= sector


def test_same_place_is_top1_and_distant_place_is_not(room_submaps):
    a, b, far = room_submaps
    db = PlaceDatabase()
    for s in (a, far):
        db.add(s.robot, s.seq, s.gmm)
    candidates = db.query(b.robot, b.seq, b.gmm, k=2)
    assert candidates[0].robot == a.robot
    assert all(c.robot != far.robot or c.distance > 5 * candidates[0].distance for c in candidates)


def test_verification_accepts_true_and_rejects_wrong_candidate(room_submaps):
    a, b, far = room_submaps
    db = PlaceDatabase(options=PlaceOptions(max_distance=2.0))
    for s in (a, far):
        db.add(s.robot, s.seq, s.gmm)
    matches = {m.candidate.robot: m for m in db.match(b.robot, b.seq, b.gmm)}
    assert matches[a.robot].accepted
    assert not matches[far.robot].accepted
    truth = np.linalg.inv(a.gt_anchor) @ b.gt_anchor
    T = matches[a.robot].registration.transform
    assert np.linalg.norm(T[:3, 3] - truth[:3, 3]) < 0.1


def corridor_with_shelves() -> Gmm:
    """An 8 m corridor (walls at y = ±1), shelves along the far half of one wall."""
    flat = np.diag([0.15**2, 0.01**2, 0.2**2])
    means = [[x, y, z] for x in np.arange(0.25, 8, 0.5) for y in (-1, 1) for z in (0.4, 1.2)]
    means += [[x, 0.6, z] for x in np.arange(5.25, 8, 0.5) for z in (0.4, 1.2)]
    return Gmm(
        np.full(len(means), 1 / len(means)), np.array(means), np.tile(flat, (len(means), 1, 1))
    )


def test_a_corridor_end_for_end_is_refused_and_its_right_twin_accepted():
    """The corridor seen from elsewhere lines up both ways; only the shelves tell which way
    round. Turned half round, the right alignment scores clearly less (accepted under the
    default ``max_turned``); the end-for-end one turned back scores more than itself."""
    candidate = corridor_with_shelves()
    truth = yaw_matrix(0.5, (1.0, -2.0, 0.0))
    query = candidate.transform(np.linalg.inv(truth))
    options, limit = RegisterOptions(), PlaceOptions().max_turned
    right = register(query, candidate, truth, options=options)
    wrong = register(query, candidate, half_turned(query, truth), options=options)
    assert wrong.confidence > 0.8  # plausible: the walls line up
    assert turned(query, candidate, right, options) < limit
    assert turned(query, candidate, wrong, options) > 1.0
    assert np.allclose(register(query, candidate, options=options).transform, truth, atol=0.05)


def sensed_corridor(sensor, path: list[tuple[float, float, float]], start) -> Gmm:
    """One submap of ``sensor``'s frames along ``path`` (x, y, yaw) in an 8 x 2 m corridor
    with a ceiling and 3 m of shelves along one wall's far end; its anchor is ``start``."""
    shapes = [
        slab(0, -1, 8, 1, -0.025),
        slab(0, -1, 8, 1, 2.5),
        Box((6.5, 0.8, 0.75), (3, 0.4, 1.5)),
    ]
    for a, b in (((0, -1), (8, -1)), ((8, -1), (8, 1)), ((8, 1), (0, 1)), ((0, 1), (0, -1))):
        shapes += wall(*a, *b)
    world, rng = World("corridor", shapes), np.random.default_rng(0)
    frames = []
    for k, (x, y, yaw) in enumerate(path):
        gt = yaw_matrix(yaw, (x, y, 0.0)) @ sensor.mount()
        pose = np.linalg.inv(yaw_matrix(path[0][2], (*path[0][:2], 0.0))) @ gt
        frames.append(Frame(k * 0.1, sense(sensor, world, gt, rng), start @ pose, gt))
    (submap,) = build_submaps(frames, options=BuildOptions(frames_per_submap=len(frames)))
    return submap


@pytest.mark.parametrize("sensor", ["lidar360", "depth"])
def test_a_sensed_corridor_end_for_end_is_refused_and_its_right_twin_accepted(sensor):
    """The same, on a simulated handheld 360° LiDAR (32 beams, ±45°) in the corridor's
    shelved half, and on the depth camera looking down its bare half: two robots over the
    same stretch, their map frames apart."""
    if sensor == "lidar360":
        device = Lidar(beams=32, fov_up=45, fov_down=-45, max_range=30)
        xs, ys = np.arange(4.0, 6.01, 0.25), (0.0, -0.2)
    else:
        device = DepthCamera.scaled(320, 240, True)
        xs, ys = np.arange(0.5, 2.01, 0.1), (0.0, -0.2)
    a = sensed_corridor(device, [(x, ys[0], 0.0) for x in xs], np.eye(4))
    b = sensed_corridor(device, [(x + 0.2, ys[1], 0.3) for x in xs], yaw_matrix(1.0, (3, 2, 0)))
    truth = np.linalg.inv(a.gt_anchor) @ b.gt_anchor
    options, limit = RegisterOptions(), PlaceOptions().max_turned
    right = register(b.gmm, a.gmm, truth, options=options)
    wrong = register(b.gmm, a.gmm, half_turned(b.gmm, truth), options=options)
    assert wrong.confidence > 0.4  # the walls line up end for end
    assert turned(b.gmm, a.gmm, right, options) < limit
    assert turned(b.gmm, a.gmm, wrong, options) > limit
    found = register(b.gmm, a.gmm, options=options).transform
    assert np.linalg.norm(found[:3, 3] - truth[:3, 3]) < 0.1


def test_a_match_free_to_slide_along_a_bare_corridor_is_refused():
    """Looking down the bare half of the corridor, the depth camera's right alignment is
    pinned across the corridor but hardly along it: any place along it fits as well, so its
    `conditioning` stays under the default and the Mapper refuses it. The 360° LiDAR among
    the shelves sees their ends and the far walls, which pin every direction."""
    limit = PlaceOptions().min_conditioning
    pinned = {}
    lidar = Lidar(beams=32, fov_up=45, fov_down=-45, max_range=30)
    for sensor, device, xs in (
        ("depth", DepthCamera.scaled(320, 240, True), np.arange(0.5, 2.01, 0.1)),
        ("lidar360", lidar, np.arange(4.0, 6.01, 0.25)),
    ):
        a = sensed_corridor(device, [(x, 0.0, 0.0) for x in xs], np.eye(4))
        b = sensed_corridor(device, [(x + 0.2, -0.2, 0.3) for x in xs], yaw_matrix(1.0, (3, 2, 0)))
        truth = np.linalg.inv(a.gt_anchor) @ b.gt_anchor
        right = register(b.gmm, a.gmm, truth, options=RegisterOptions())
        assert right.confidence > 0.8  # the surfaces coincide: C alone would accept it
        pinned[sensor] = right.conditioning
    assert pinned["depth"] < limit / 10
    assert pinned["lidar360"] > limit * 10


def test_own_recent_submaps_are_skipped(small_gmm):
    db = PlaceDatabase(options=PlaceOptions(skip_recent=2, max_distance=2.0))
    for seq in range(4):
        db.add("a", seq, small_gmm)
    keys = {(c.robot, c.seq) for c in db.query("a", 3, small_gmm, k=4)}
    assert keys == {("a", 0)}


def test_positives_need_overlap_and_other_robot(room_submaps):
    pos = positives(room_submaps)
    assert pos[0, 1] and pos[1, 0]
    assert not pos[0, 2] and not pos[1, 2] and not pos.diagonal().any()


def test_recall_and_pr_curves():
    sim = np.array([[-np.inf, 0.9, 0.1], [0.9, -np.inf, 0.5], [0.1, 0.5, -np.inf]])
    pos = np.array([[0, 0, 1], [0, 0, 1], [1, 1, 0]], dtype=bool)
    curve = recall_curve(sim, pos, np.array([0, 1]))
    assert curve[0] == 0.0 and curve[1] == 1.0
    pr = pr_curve(np.array([0.9, 0.8, 0.3]), np.array([True, True, False]), 3)
    assert pr["recall_at_full_precision"] == pytest.approx(2 / 3)
    assert pr_curve(np.array([0.9]), np.array([False]), 1)["recall_at_full_precision"] == 0.0


def test_bad_input_is_rejected(small_gmm):
    with pytest.raises(InvalidInputError):
        ShapeDescriptor().describe_points(np.zeros((1, 3)))
    with pytest.raises(InvalidInputError):
        ShapeDescriptor().describe_points(np.full((10, 3), np.nan))
    with pytest.raises(InvalidInputError):
        ShapeDescriptor(pairs=0)
    with pytest.raises(InvalidInputError):
        PlaceOptions(min_confidence=2.0)
    with pytest.raises(InvalidInputError):
        PlaceDatabase().add("a", 0, None)


def test_the_half_turned_twin_is_told_on_the_upright_parts():
    """The right match of two simulated office submaps (tests/data/level_*): turned half
    round, the floor lines up as well as before, and over the whole mixtures the twin scores
    above the match. On the upright parts it scores less."""
    data = Path(__file__).parent / "data"
    source, target = (Gmm.load(data / f"level_{k}.npz") for k in ("source", "target"))
    truth = np.loadtxt(data / "level_truth.txt")
    options = RegisterOptions()
    whole = replace(options, level_planes=True)
    upright = turned(source, target, register(source, target, truth, options=options), options)
    plain = turned(source, target, register(source, target, truth, options=whole), whole)
    assert plain > 1.0 > upright
