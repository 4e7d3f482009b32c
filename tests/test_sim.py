import itertools
import json

import numpy as np
import pytest
from click.testing import CliRunner

import gmmap.io.datasets as datasets
from gmmap import FileFormatError, InvalidInputError, _core
from gmmap.cli import main
from gmmap.io.sim import (
    WORLDS,
    Box,
    Cylinder,
    DepthCamera,
    Lidar,
    Motion,
    World,
    get_world,
    simulate,
    simulate_options,
    write_pointfiles,
    write_run,
)
from gmmap.math.drift import Drift
from gmmap.options import SimOptions

SMALL_CAMERA = DepthCamera(width=160, height=120, fx=131.25, fy=131.25, cx=79.5, cy=59.5)
SMALL_LIDAR = Lidar(beams=8, azimuth_steps=256)


def scene(*shapes):
    return World("test", list(shapes)).scene


def test_ray_against_a_known_wall_returns_the_analytic_distance():
    wall = Box((3.05, 0.0, 1.0), (0.1, 20.0, 2.0))
    origin = np.eye(4)
    origin[2, 3] = 1.0
    angles = np.radians([0.0, 20.0, -45.0, 60.0])
    dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros(4)], axis=1)
    np.testing.assert_allclose(
        scene(wall).ranges(origin, dirs, 50.0), 3.0 / np.cos(angles), rtol=1e-12
    )
    assert np.isnan(scene(wall).ranges(origin, -dirs[:1], 50.0)[0])


def test_depth_camera_sees_a_wall_at_its_z_depth():
    cam = DepthCamera(noise=False)
    pose = cam.mount()  # camera 1 m up, looking along +x
    depth = cam.render(
        World("w", [Box((2.55, 0, 1.0), (0.1, 40, 40))]), pose, np.random.default_rng(0)
    )
    assert depth.shape == (480, 640)
    np.testing.assert_allclose(depth, 2.5, atol=1e-4)  # z-depth, not the ray length


def test_cylinder_and_yawed_box():
    s = scene(Cylinder(4.0, 0.0, 0.5, 0.0, 2.0), Box((-3.0, 0.0, 1.0), (1.0, 1.0, 2.0), np.pi / 4))
    T = np.eye(4)
    T[2, 3] = 1.0
    r = s.ranges(T, np.array([[1.0, 0, 0], [-1.0, 0, 0]]), 50.0)
    np.testing.assert_allclose(r, [3.5, 3.0 - np.sqrt(0.5)], rtol=1e-12)


def test_same_seed_same_data_other_seed_differs():
    world = get_world("office")
    a = simulate(world, 2, seed=3, sensor=SMALL_CAMERA, max_frames=5, odometry=Drift())
    b = simulate(world, 2, seed=3, sensor=SMALL_CAMERA, max_frames=5, odometry=Drift())
    c = simulate(world, 2, seed=4, sensor=SMALL_CAMERA, max_frames=5, odometry=Drift())
    np.testing.assert_array_equal(a[1].depth_raw(4), b[1].depth_raw(4))
    np.testing.assert_array_equal(a[1].odom_poses, b[1].odom_poses)
    assert not np.array_equal(a[1].depth_raw(4), c[1].depth_raw(4))
    assert not np.array_equal(a[1].odom_poses, c[1].odom_poses)
    np.testing.assert_array_equal(a[1].gt_poses, c[1].gt_poses)


def test_sim_to_open_round_trip_is_lossless(tmp_path):
    run = simulate(
        get_world("office"), 2, seed=1, sensor=SMALL_CAMERA, max_frames=6, odometry=Drift()
    )
    write_run(run, tmp_path, seed=1)
    for robot in run:
        seq = datasets.open(tmp_path / robot.name)
        assert len(seq) == len(robot)
        for i in (0, 5):
            got, want = seq[i], robot[i]
            assert got.stamp == pytest.approx(want.stamp, abs=1e-6)
            # Points come from the same uint16 depth image: identical.
            np.testing.assert_array_equal(got.points, want.points)
            np.testing.assert_allclose(got.pose, want.pose, atol=1e-8)
            np.testing.assert_allclose(got.gt_pose, want.gt_pose, atol=1e-8)
    meta = json.loads((tmp_path / "sim.json").read_text())
    T = np.array(meta["robots"][1]["map_to_world"])
    np.testing.assert_allclose(T @ run[1].odom_poses[0], run[1].gt_poses[0], atol=1e-9)


def test_robots_start_in_unknown_frames_and_their_routes_overlap():
    run = simulate(get_world("office"), 3, sensor=SMALL_CAMERA)
    for r in run:
        np.testing.assert_allclose(r.odom_poses[0], r.sensor.mount(), atol=1e-12)
    starts = [r.map_to_world[:2, 3] for r in run]
    assert min(np.linalg.norm(a - b) for a in starts for b in starts if a is not b) > 3.0
    for a in range(3):
        for b in range(a + 1, 3):
            pa, pb = run[a].gt_poses[:, :2, 3], run[b].gt_poses[:, :2, 3]
            gap = np.linalg.norm(pa[:, None] - pb[None], axis=2).min()
            assert gap < 0.3, f"robots {a} and {b} never come close"


@pytest.mark.parametrize("name", sorted(WORLDS))
def test_builtin_worlds_are_drivable(name):
    world = get_world(name)
    for robot in simulate(world, len(world.routes), sensor=SMALL_CAMERA):
        assert world.clearance(robot.gt_poses[:, :2, 3]).min() > 0.3
    if name != "office":
        assert world.clearance([world.start[:2], world.goal]).min() > 0.3


@pytest.mark.parametrize("seed", [0, 7, 1000, 4242])
def test_procedural_offices_are_drivable_and_shared(seed):
    world = get_world(f"random-office:{seed}")
    assert world.to_dict() == get_world(f"random-office:{seed}").to_dict()
    assert world.to_dict() != get_world(f"random-office:{seed + 1}").to_dict()
    run = simulate(world, len(world.routes), sensor=SMALL_CAMERA)
    for robot in run:
        assert world.clearance(robot.gt_poses[:, :2, 3]).min() > 0.3
    for a, b in itertools.pairwise(run):  # robot i ends where robot i + 1 starts
        pa, pb = a.gt_poses[:, :2, 3], b.gt_poses[:, :2, 3]
        assert np.linalg.norm(pa[:, None] - pb[None], axis=2).min() < 0.3


def test_a_procedural_office_needs_an_integer_seed():
    with pytest.raises(InvalidInputError, match="integer"):
        get_world("random-office:x")


def test_world_file_round_trip_and_errors(tmp_path):
    world = get_world("clutter")
    world.save(tmp_path / "w.json")
    again = World.load(tmp_path / "w.json")
    assert again.shapes == world.shapes and again.goal == world.goal
    (tmp_path / "bad.json").write_text('{"name": "x", "shapes": [{"type": "cone"}]}')
    with pytest.raises(FileFormatError, match=r"bad\.json"):
        World.load(tmp_path / "bad.json")
    (tmp_path / "cut.json").write_text((tmp_path / "w.json").read_text()[:100])
    with pytest.raises(FileFormatError):
        World.load(tmp_path / "cut.json")
    with pytest.raises(InvalidInputError, match="unknown world"):
        get_world("moon")


def test_lidar_points_lie_on_the_room_walls():
    world = World(
        "room",
        [
            Box((0, 0, -0.05), (10, 10, 0.1)),
            Box((5.05, 0, 1), (0.1, 10, 2)),
            Box((-5.05, 0, 1), (0.1, 10, 2)),
            Box((0, 5.05, 1), (10, 0.1, 2)),
            Box((0, -5.05, 1), (10, 0.1, 2)),
        ],
    )
    lidar = Lidar(noise_std=0.0)
    pts = lidar.scan(world, lidar.mount(), np.random.default_rng(0))
    assert len(pts) > 0.5 * lidar.beams * lidar.azimuth_steps
    on_wall = np.isclose(np.abs(pts[:, :2]).max(axis=1), 5.0, atol=1e-4)
    on_floor = np.isclose(pts[:, 2], -lidar.mount_height, atol=1e-4)
    assert np.all(on_wall | on_floor)


def test_too_many_robots_is_a_clear_error():
    with pytest.raises(InvalidInputError, match="routes for 1 to"):
        simulate(get_world("corner"), 5)


def test_sim_command(tmp_path):
    result = CliRunner().invoke(
        main,
        [
            "sim",
            "--robots",
            "2",
            "--max-frames",
            "3",
            "--sensor",
            "depth",
            "--sim-width",
            "80",
            "--out",
            str(tmp_path),
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    meta = json.loads(result.stdout.strip().splitlines()[-1])
    assert [r["frames"] for r in meta["robots"]] == [3, 3]
    assert len(datasets.open(tmp_path / "robot_1")) == 3
    assert isinstance(World.load(tmp_path / "world.json").scene, _core.RayScene)


def test_lidar_sim_to_open_round_trip(tmp_path):
    run = simulate(
        get_world("office"), 2, seed=2, sensor=SMALL_LIDAR, max_frames=5, odometry=Drift()
    )
    meta = write_run(run, tmp_path, seed=2)
    assert meta["sensor"] == "Lidar"
    for robot in run:
        seq = datasets.open(tmp_path / robot.name)
        assert isinstance(seq, datasets.PointFiles) and seq.match == "stamp"
        assert seq.gt_path == tmp_path / robot.name / "groundtruth.txt"
        assert len(seq) == len(robot)
        for i in (0, 4):
            got, want = seq[i], robot[i]
            assert got.stamp == pytest.approx(want.stamp, abs=1e-6)
            # Written as float32 and read back as float32: the very same numbers.
            assert got.points.dtype == np.float32 and len(got.points) > 1000
            np.testing.assert_array_equal(got.points, want.points)
            np.testing.assert_allclose(got.pose, want.pose, atol=1e-8)
            np.testing.assert_allclose(got.gt_pose, want.gt_pose, atol=1e-8)
        assert not np.allclose(seq.poses[-1], seq.gt_poses[-1])  # odometry is not the truth
    first = sorted((tmp_path / "robot_0").glob("*.ply"))[0]
    assert first.name == f"{run[0].stamps[0]:.6f}.ply"
    assert first.read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")


def test_writers_refuse_the_other_sensor(tmp_path):
    camera_robot = simulate(get_world("corner"), 1, sensor=SMALL_CAMERA, max_frames=1)[0]
    with pytest.raises(InvalidInputError, match="use a Lidar"):
        write_pointfiles(camera_robot, tmp_path)


def route_length(world_name, robot):
    """Length of the waypoint polyline a robot drives (the routes, then the routes reversed)."""
    world = get_world(world_name)
    route = np.array([*world.routes, *(list(reversed(r)) for r in world.routes)][robot])
    return float(np.linalg.norm(np.diff(route, axis=0), axis=1).sum())


@pytest.mark.parametrize(
    ("sensor", "options"),
    [("depth", ["--sim-width", "80"]), ("lidar", ["--beams", "4"])],
)
def test_info_on_a_sim_run(tmp_path, sensor, options):
    rate = 1.0  # one frame a second: a whole route in ~40 frames
    args = ["sim", "--robots", "2", "--rate", str(rate), "--sensor", sensor, *options]
    result = CliRunner().invoke(main, [*args, "--out", str(tmp_path), "--json"])
    assert result.exit_code == 0, result.output
    meta = json.loads(result.stdout.strip().splitlines()[-1])
    for robot, (frames, name) in enumerate((r["frames"], r["name"]) for r in meta["robots"]):
        result = CliRunner().invoke(main, ["info", str(tmp_path / name), "--json", "--sample", "3"])
        assert result.exit_code == 0, result.output
        r = json.loads(result.stdout)
        assert r["format"] == ("tum" if sensor == "depth" else "pointfiles")
        assert r["frames"] == frames > 30
        assert r["duration_s"] == pytest.approx((frames - 1) / rate)
        # The last frame falls up to one frame's drive short of the route's end.
        route = route_length("office", robot)
        assert route - Motion().speed / rate <= r["gt_path_length_m"] <= route + 1e-6
        assert r["path_length_m"] == pytest.approx(route, rel=0.05)  # odometry, with drift
        assert r["points_per_frame"] > 1000


def test_lidar_options_reach_the_sensor(tmp_path):
    args = ["sim", "--sensor", "lidar", "--robots", "1", "--max-frames", "2", "--no-noise"]
    result = CliRunner().invoke(
        main, [*args, "--beams", "3", "--lidar-range", "4", "--out", str(tmp_path)]
    )
    assert result.exit_code == 0, result.output
    points = datasets.open(tmp_path / "robot_0")[1].points.astype(np.float64)
    r = np.linalg.norm(points, axis=1)
    assert len(points) > 0 and r.max() < 4.0
    # Three beams spread over ±15°: every point lies at one of three elevations.
    elevation = np.degrees(np.arcsin(points[:, 2] / r))
    np.testing.assert_allclose(np.unique(elevation.round(2)), [-15.0, 0.0, 15.0], atol=0.01)


def test_a_swaying_handheld_lidar_keeps_a_level_map_frame():
    options = SimOptions(sensor="lidar", beams=32, lidar_fov=45.0, sway=10.0, rate=2.0)
    robot = simulate_options(options, max_frames=12)[0]
    tilt = np.degrees(np.arccos(np.clip(robot.gt_poses[:, 2, 2], -1, 1)))
    assert 3.0 < tilt.max() <= 10.0 * np.sqrt(2) + 1e-6  # roll and pitch together
    np.testing.assert_allclose(robot.map_to_world[2, :3], [0, 0, 1], atol=1e-12)
    elevation = np.degrees(np.arcsin(robot.sensor.directions()[:, 2]))
    assert elevation.min() == pytest.approx(-45.0) and elevation.max() == pytest.approx(45.0)
    assert len(robot.points(0)) > 1000
