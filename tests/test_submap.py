import json

import numpy as np
import pytest
from click.testing import CliRunner

from gmmap import Gmm, InvalidInputError, fit_gmm
from gmmap.cli import main
from gmmap.io.datasets import Frame
from gmmap.io.sim import DepthCamera, Lidar, get_world, simulate
from gmmap.io.sim.robots import Motion
from gmmap.mapping.submap import (
    BuildOptions,
    Submap,
    SubmapBuilder,
    build_submaps,
    level,
    read_submaps,
    write_submaps,
)
from gmmap.math.select import SelectOptions, select_components

MERGE_ALL = SelectOptions(kl_threshold=1e12, max_distance=100.0)
FLOOR = np.diag([0.04, 0.04, 1e-4])
WALL = np.diag([1e-4, 0.04, 0.04])


def test_moment_matching_preserves_weight_mean_and_covariance():
    rng = np.random.default_rng(0)
    w = np.array([0.2, 0.5, 0.3])
    mu = rng.normal(size=(3, 3)) * 0.1
    covs = np.stack([FLOOR * s for s in (1.0, 1.5, 0.7)])
    merged, labels = select_components(Gmm(w, mu, covs), MERGE_ALL, return_labels=True)
    assert len(merged) == 1 and list(labels) == [0, 0, 0]
    mean = w @ mu
    second = sum(wk * (c + np.outer(m, m)) for wk, m, c in zip(w, mu, covs, strict=True))
    np.testing.assert_allclose(merged.weights, [1.0], atol=1e-15)
    np.testing.assert_allclose(merged.means[0], mean, atol=1e-15)
    np.testing.assert_allclose(merged.covariances[0], second - np.outer(mean, mean), atol=1e-15)


def test_merging_copies_of_one_component_returns_it():
    g = Gmm(np.full(5, 0.2), np.tile([1.0, 2.0, 0.5], (5, 1)), np.tile(FLOOR, (5, 1, 1)))
    merged = select_components(g)
    assert len(merged) == 1
    np.testing.assert_allclose(merged.means[0], [1.0, 2.0, 0.5])
    np.testing.assert_allclose(merged.covariances[0], FLOOR, atol=1e-15)


def test_nothing_merges_across_classes():
    g = Gmm([0.25] * 4, np.zeros((4, 3)), np.stack([FLOOR, WALL, FLOOR, WALL]))
    merged, labels = select_components(g, MERGE_ALL, return_labels=True)
    assert len(merged) == 2
    assert labels[0] == labels[2] != labels[1] == labels[3]
    with pytest.raises(InvalidInputError):
        SelectOptions(max_distance=0.0)


def test_selection_then_refit_shrinks_a_real_submap(slice_points):
    from gmmap.mapping.submap import select_and_refine

    fitted = fit_gmm(slice_points, 100)
    merged = select_components(fitted)
    assert len(merged) < 0.8 * len(fitted) and merged.float32_bytes < fitted.float32_bytes
    refit = fit_gmm(slice_points, covariance="full", max_iter=10, init=merged)
    assert len(refit) == len(merged) and refit.score(slice_points) > merged.score(slice_points)
    # The builder keeps the refit only when it is no larger than the fitted mixture.
    chosen = select_and_refine(fitted, slice_points, BuildOptions())
    assert chosen.float32_bytes <= fitted.float32_bytes
    assert chosen.score(slice_points) >= merged.score(slice_points)


def pose(yaw: float, t) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = t
    return T


def test_a_point_seen_from_two_poses_lands_in_one_voxel():
    world_point = np.array([2.025, 1.025, 0.525])  # a voxel centre
    poses = [pose(0.3, [0.1, 0.2, 0.0]), pose(-1.2, [1.0, -0.5, 0.0])]
    frames = [
        Frame(
            float(i), (np.linalg.inv(T) @ np.append(world_point, 1))[None, :3].astype(np.float32), T
        )
        for i, T in enumerate(poses)
    ]
    b = SubmapBuilder(options=BuildOptions(frames_per_submap=2, min_novelty=0.0, select=False))
    assert b.add(frames[0]) is None
    s = b.add(frames[1])
    assert s.n_points == 1
    np.testing.assert_allclose(s.anchor, poses[0])  # already upright
    anchor_point = np.linalg.inv(s.anchor) @ np.append(world_point, 1)
    np.testing.assert_allclose(s.points[0], anchor_point[:3], atol=1e-6)


def test_anchor_is_levelled_for_a_camera():
    cam = np.eye(4)
    cam[:3, :3] = DepthCamera().mount()[:3, :3] @ pose(0.4, [0, 0, 0])[:3, :3]
    a = level(cam, (0, 0, 1))
    np.testing.assert_allclose(a[:3, 2], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(a[:3, :3].T @ a[:3, :3], np.eye(3), atol=1e-12)
    assert a[:3, 0] @ cam[:3, 2] > 0.99  # x follows the camera's viewing direction


@pytest.fixture(scope="module")
def sim_frames():
    cam = DepthCamera(width=160, height=120, fx=131.25, fy=131.25, cx=79.5, cy=59.5)
    robot = simulate(get_world("office"), 1, sensor=cam)[0]
    return [robot[i] for i in range(0, 48, 4)]


@pytest.mark.parametrize(
    ("strategy", "count", "frames"), [("points", 3, 4), ("gmm-merge", 3, 4), ("per-frame", 12, 1)]
)
def test_each_strategy_makes_its_submaps(sim_frames, strategy, count, frames):
    opts = BuildOptions(strategy=strategy, n_components=40, min_novelty=0.0, holdout=0.1).by_frames(
        4
    )
    submaps = list(build_submaps(sim_frames, "r1", opts))
    assert len(submaps) == count
    assert [s.seq for s in submaps] == list(range(count))
    for s in submaps:
        assert s.stats["frames"] == frames and s.robot == "r1"
        assert s.stats["components_after"] == len(s.gmm) <= s.stats["components_before"]
        assert np.isfinite(s.stats["heldout_ll_after"])
        assert s.gmm.float32_bytes <= 4 * 10 * s.stats["components_before"]
        if strategy == "gmm-merge":
            assert s.stats["components_before"] == 4 * 10  # K / F components per frame
        # The ground-truth anchor and the odometry anchor are the same physical frame.
        np.testing.assert_allclose(
            s.gt_anchor @ np.linalg.inv(s.anchor) @ sim_frames[0].pose,
            sim_frames[0].gt_pose,
            atol=1e-9,
        )


def test_novelty_check_skips_repeated_frames(sim_frames):
    b = SubmapBuilder(options=BuildOptions(frames_per_submap=3, min_novelty=0.05))
    assert b.add(sim_frames[0]) is None
    assert b.add(sim_frames[0]) is None
    assert b.frames_skipped == 1


def test_submaps_round_trip_through_files(sim_frames, tmp_path):
    opts = BuildOptions(n_components=20, holdout=0.1).by_frames(6)
    submaps = list(build_submaps(sim_frames, "r2", opts))
    index = write_submaps(submaps, tmp_path, source="sim", options=opts)
    assert index["robot"] == "r2" and index["options"]["frames_per_submap"] == 6
    back = read_submaps(tmp_path)
    assert len(back) == len(submaps)
    for a, b in zip(submaps, back, strict=True):
        np.testing.assert_array_equal(a.gmm.means, b.gmm.means)
        np.testing.assert_array_equal(a.anchor, b.anchor)
        np.testing.assert_allclose(a.points, b.points, atol=1e-6)
        assert a.stats == b.stats
    assert isinstance(Submap.load(tmp_path / "submap_000000.npz"), Submap)


def test_build_command_json(tmp_path):
    from gmmap.io.datasets import BUNDLED_TUM_SLICE

    r = CliRunner().invoke(
        main,
        [
            "build",
            str(BUNDLED_TUM_SLICE),
            "--out",
            str(tmp_path),
            "--frames-per-submap",
            "4",
            "--components",
            "30",
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout.strip().splitlines()[-1])
    keys = {
        "seq",
        "frames",
        "points",
        "components_before",
        "components_after",
        "bytes_float32",
        "heldout_ll_before",
        "heldout_ll_after",
        "time_s",
    }
    assert len(out["submaps"]) >= 1 and all(keys <= set(s) for s in out["submaps"])
    assert len(read_submaps(tmp_path)) == len(out["submaps"])


def test_submaps_by_space_close_at_the_same_places_at_any_rate():
    """The same route sampled at 2, 10 and 30 Hz: submaps close where the robot has driven 1.9 m
    or turned 100°, so they begin at the same stamps to within two 2 Hz frames (the one that
    crosses the limit, the one that begins the next submap) and their count differs by at most
    the last, partial one."""
    lidar = Lidar(beams=4, azimuth_steps=128)
    opts = BuildOptions(
        frames_per_submap=1000,
        submap_distance=1.9,
        submap_angle=100.0,
        n_components=6,
        max_iter=5,
        refine_iter=0,
    )
    starts = {}
    for rate in (2.0, 10.0, 30.0):
        robot = simulate(get_world("corner"), 1, sensor=lidar, motion=Motion(rate=rate))[0]
        starts[rate] = np.array([s.stamps[0] for s in build_submaps(robot, "r", opts)])
    assert len(starts[2.0]) >= 8  # a 360° spin, 12.8 m of driving and a 90° turn
    for rate in (10.0, 30.0):
        # The last, partial submap may end on either side of the route's last frame.
        n = len(starts[2.0])
        assert abs(len(starts[rate]) - n) <= 1
        assert np.abs(starts[rate][:n] - starts[2.0][: len(starts[rate])]).max() <= 1.0 + 1e-9


def test_the_frame_count_caps_a_submap_by_space(sim_frames):
    opts = BuildOptions(
        frames_per_submap=3,
        submap_distance=100.0,
        submap_angle=None,
        n_components=10,
        min_novelty=0.0,
    )
    assert [s.stats["frames"] for s in build_submaps(sim_frames, "r", opts)] == [3, 3, 3, 3]
    with pytest.raises(InvalidInputError):
        BuildOptions(submap_distance=-1.0)
