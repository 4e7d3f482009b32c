"""The global map and the offline merge pipeline."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import BUNDLED_TUM_SLICE
from gmmap.cli import main
from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.merge import ate, merge
from gmmap.io.datasets.tum import TumRgbd
from gmmap.mapping.backend import BackendOptions
from gmmap.mapping.globalmap import GlobalMap, build_global_map
from gmmap.mapping.submap import BuildOptions, Submap, build_submaps
from gmmap.math.em import fit_gmm


def submap_of(robot: str, gmm, anchor=None, n_points=1000) -> Submap:
    anchor = np.eye(4) if anchor is None else anchor
    return Submap(robot, 0, anchor, np.zeros(1), n_points, gmm)


def test_two_identical_submaps_merge_to_one(slice_points):
    gmm = fit_gmm(slice_points, 40, covariance="full", seed=0)
    subs = [submap_of("a", gmm), submap_of("b", gmm)]
    poses = {("a", 0): np.eye(4), ("b", 0): np.eye(4)}
    merged = build_global_map(subs, poses, "a")
    alone = build_global_map(subs[:1], poses, "a")  # the same selection on one copy
    assert len(merged.gmm) <= 1.1 * len(alone.gmm) < 1.1 * len(gmm)
    score = merged.gmm.score(slice_points)
    assert score == pytest.approx(alone.gmm.score(slice_points), abs=0.05)


def test_global_map_moves_submaps_and_answers_occupancy(slice_points):
    gmm = fit_gmm(slice_points, 30, covariance="full", seed=0)
    T = np.eye(4)
    T[:3, 3] = [10.0, 0.0, 0.0]
    gmap = build_global_map([submap_of("a", gmm)], {("a", 0): T}, "a")
    surface = slice_points[:50] + T[:3, 3]
    assert gmap.is_occupied(surface, sigmas=3.0).mean() > 0.9
    assert gmap.is_free(surface + np.array([0.0, 0.0, 20.0])).all()
    assert gmap.trajectories["a"].tolist() == [[10.0, 0.0, 0.0]]


def test_global_map_needs_a_placed_submap(slice_points):
    gmm = fit_gmm(slice_points, 5, seed=0)
    with pytest.raises(InvalidInputError):
        build_global_map([submap_of("a", gmm)], {}, "a")


def test_global_map_exports(tmp_path, slice_points):
    gmap = build_global_map(
        [submap_of("a", fit_gmm(slice_points, 10, seed=0))], {("a", 0): np.eye(4)}, "a"
    )
    gmap.save(tmp_path / "map.npz")
    gmap.save_png(tmp_path / "map.png", n=5000)
    assert all((tmp_path / f).stat().st_size > 0 for f in ("map.npz", "map.png"))


@pytest.fixture(scope="module")
def slice_robots():
    """The bundled slice as two robots: frames 0-3 and 4-7 (the same desk, poses from the
    same mocap frame, so the true relative frame is the identity)."""
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)
    options = BuildOptions(frames_per_submap=2, covariance="full", n_components=60)
    return {
        name: list(build_submaps(frames[part], name, options))
        for name, part in (("a", slice(0, 4)), ("b", slice(4, 8)))
    }


# The bundled slice's two-frame submaps give one or two matches per robot pair: let one join.
SLICE_CONFIG = Config(backend=BackendOptions(min_matches=1))


def test_merge_recovers_the_relative_frame(slice_robots):
    mapper, report = merge(slice_robots, SLICE_CONFIG)
    assert report["groups"] == [["a", "b"]]
    assert report["accepted_edges"] >= 1
    (pair,) = report["pairs"]
    assert pair["t_error"] < 0.05 and pair["r_error_deg"] < 2.0
    assert set(mapper.global_maps()) == {"a"}


def test_merge_cli_json(tmp_path, slice_robots):
    from gmmap.mapping.submap import write_submaps

    for name, subs in slice_robots.items():
        write_submaps(subs, tmp_path / name)
    out = tmp_path / "out"
    args = [str(tmp_path / "a"), str(tmp_path / "b"), "--json", "--min-matches", "1"]
    r = CliRunner().invoke(main, ["merge", *args, "--out", str(out)])
    assert r.exit_code == 0, r.output
    report = json.loads(r.stdout)
    assert report["reference"] == "a"
    assert {x["name"] for x in report["robots"]} == {"a", "b"}
    assert np.array(report["robots"][1]["to_reference"]).shape == (4, 4)
    assert {"groups", "accepted_edges", "rejected_edges"} <= set(report)
    assert (out / "globalmap_a.png").is_file() and (out / "merge.json").is_file()
    # --min-matches reaches the pose graph: more than the robots share keeps them apart.
    r = CliRunner().invoke(main, ["merge", *args, "--min-matches", "99"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["groups"] == [["a"], ["b"]]


@pytest.fixture(scope="module")
def sim_robots():
    """Two simulated LiDAR robots in the office with drifting odometry; they meet in room B."""
    from gmmap.io.sim import UP, Lidar, get_world, simulate
    from gmmap.math.drift import Drift

    drift = Drift(seed=0, up=UP)
    run = simulate(get_world("office"), 2, seed=0, sensor=Lidar(), odometry=drift)
    options = BuildOptions(frames_per_submap=20, covariance="full")
    return {r.name: list(build_submaps(r, r.name, options)) for r in run}


def test_injected_wrong_matches_are_rejected_and_change_nothing(sim_robots):
    _, clean = merge(sim_robots)
    assert clean["groups"] == [["robot_0", "robot_1"]]
    kept = clean["match_errors"]
    assert kept["n"] >= 3 and kept["t_median"] < 0.05 and kept["r_median_deg"] < 1.0
    # Rigidly aligned (the reference robot's own drift taken out), optimising does not hurt.
    assert clean["ate_aligned_after_m"] < clean["ate_aligned_before_m"] + 1e-3
    assert clean["ate_aligned_before_m"] < clean["ate_before_m"]
    # One of the verified matches replaced by a wrong one: rejected, and nothing changes.
    _, report = merge(sim_robots, wrong_matches=0.2, seed=2)
    wrong = report["injected_wrong"]
    assert wrong["n"] >= 1 and wrong["rejected"] == wrong["n"]
    assert report["groups"] == clean["groups"]
    (before,), (after,) = clean["pairs"], report["pairs"]
    assert after["t_error"] < 0.05 and after["r_error_deg"] < 1.0, after
    for key, tol in (("t_error", 0.02), ("r_error_deg", 0.5), ("frame_t_error", 0.02)):
        assert abs(after[key] - before[key]) < tol, key


def test_fr1_xyz_halves_merge_to_three_centimetres(shared_data):
    """The issue's real-data figure: fr1_xyz split at frame 398 into two robots (TUM's poses
    are motion capture, hence the tight odometry noise)."""
    frames = TumRgbd(shared_data / "tum_fr1_xyz")
    options = BuildOptions(frames_per_submap=20, covariance="full")
    halves = {
        name: list(build_submaps(frames[part], name, options))
        for name, part in (("first", slice(0, 398)), ("second", slice(398, None)))
    }
    _, report = merge(halves, Config(backend=BackendOptions.for_drift(0.002)))
    (pair,) = report["pairs"]
    # Both halves' map frame is the motion-capture frame: the frame relation is the figure.
    assert pair["frame_t_error"] <= 0.03 and pair["frame_r_error_deg"] <= 1.0, pair
    # Where they met the frame's rotation error acts over the 1-2 m to the desk as well.
    assert pair["t_error"] <= 0.04 and pair["r_error_deg"] <= 1.0, pair


def test_merge_writes_tum_trajectories_that_evo_reads(tmp_path, slice_robots):
    """Each robot's optimised anchors in the reference frame and, where the data has it, the
    ground truth in the reference robot's true map frame: evo's own CLI compares them."""
    import subprocess
    import sys
    from pathlib import Path

    from gmmap.io.datasets.trajectory import read_trajectory
    from gmmap.mapping.submap import write_submaps

    for name, subs in slice_robots.items():
        write_submaps(subs, tmp_path / name)
    out = tmp_path / "out"
    args = ["merge", str(tmp_path / "a"), str(tmp_path / "b"), "--min-matches", "1"]
    r = CliRunner().invoke(main, [*args, "--out", str(out)])
    assert r.exit_code == 0, r.output
    for name, subs in slice_robots.items():
        stamps, poses = read_trajectory(out / f"trajectory_{name}.txt")
        assert len(stamps) == len(subs) and poses.shape == (len(subs), 4, 4)
        np.testing.assert_allclose(stamps, [s.stamps[0] for s in subs], atol=1e-6)
    evo_ape = Path(sys.executable).with_name("evo_ape")
    if not evo_ape.exists():
        pytest.skip("evo's CLI (the eval extra) is not installed")
    cmd = [str(evo_ape), "tum", str(out / "truth_b.txt"), str(out / "trajectory_b.txt")]
    ran = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    rmse = float(next(x for x in ran.stdout.splitlines() if "rmse" in x).split()[-1])
    assert rmse < 0.05  # the merged frame is right to a few centimetres (the test above)


def test_global_map_rerun_recording(tmp_path, slice_points):
    from gmmap.io import viz

    if not viz.available():
        pytest.skip("rerun-sdk (the viz extra) is not installed")
    g = fit_gmm(slice_points, 20, covariance="full", seed=0)
    gmap = GlobalMap("a", g, {"a": np.zeros((3, 3)), "b": np.ones((2, 3))})
    path = viz.save_rerun(gmap, tmp_path / "map.rrd", n_points=2_000)
    data = path.read_bytes()
    assert data[:4] == b"RRF2" and len(data) > 2_000 * 12


SESSION_KEYS = {"joined", "frame_t_error", "frame_r_error_deg", "precision", "recall"}


def test_eval_merge_reports_sessions_against_truth():
    """Two slices of the bundled recording as two sessions: joined, and every key outside
    checks read."""
    s = str(BUNDLED_TUM_SLICE)
    args = ["eval", "merge", f"{s}@0:4", f"{s}@4:8", "--stride", "2", "--json"]
    r = CliRunner().invoke(main, [*args, "--frames-per-submap", "2", "--min-matches", "1"])
    assert r.exit_code == 0, r.output
    report = json.loads(r.stdout)
    assert SESSION_KEYS | {"gicp", "floor", "no_guess"} <= set(report)
    assert report["joined"] and report["precision"] == 1.0
    assert report["frame_t_error"] < 0.05 and report["frame_r_error_deg"] < 2.0
    assert report["floor"]["n"] >= 1 and report["gicp"]["candidates_registered_right"] >= 1
    assert 0.0 <= report["probability_brier"] < 0.25  # better than a coin on right matches
    no_guess = report["no_guess"]
    assert no_guess["pairs"] >= 1 and no_guess["gmmap"]["right"] >= 1
    assert no_guess["gmmap_free_space"]["right"] >= 1
    assert no_guess["from_truth"]["right"] >= 1  # started at the truth, it stays there
    baseline = no_guess["kiss_matcher"]
    assert "right" in baseline or "not installed" in baseline["skipped"]
    bad = CliRunner().invoke(main, ["eval", "merge", f"{s}@a:b"])
    assert bad.exit_code == 2 and "PATH@START:STOP" in bad.output


def test_fr1_xyz_as_a_second_session_joins(shared_data):
    """fr1_xyz's first 400 frames against the whole recording re-sampled at 10 Hz from another
    start: the maps join, and every verified match (10 with the default submaps by space) is
    within the 0.2 m / 3° of `is_correct`. Against one submap a few end 3.7-4° off (the GMM
    objective's optimum sits there); refined against the candidate's neighbours, none does."""
    from gmmap.eval.sessions import evaluate_sessions

    frames = TumRgbd(shared_data / "tum_fr1_xyz")
    build = BuildOptions()
    sessions = {
        "a": list(build_submaps(frames[0:400], "a", build)),
        "b": list(build_submaps([frames[i] for i in range(201, len(frames), 3)], "b", build)),
    }
    r = evaluate_sessions(sessions, gicp=False)
    assert r["joined"] and r["precision"] == 1.0 and r["verified"] >= 8
    assert r["kept_precision"] == 1.0
    assert r["frame_t_error"] < 0.04 and r["frame_r_error_deg"] < 1.5


def test_fr3_cabinet_loop_verifies_no_wrong_match(shared_data):
    """fr3 cabinet's loop (keyframes 0-14 against 43-57): a box whose sides look alike. One
    candidate verifies 0.57 m / 27° off against its single submap; its neighbours pull it
    0.28 m farther (`place.max_refine_shift`), so it is refused."""
    from gmmap.eval.sessions import evaluate_sessions
    from gmmap.io import datasets

    frames = datasets.open(shared_data / "tum_fr3_cabinet_keyframes")
    config = Config(
        build=BuildOptions(frames_per_submap=3), backend=BackendOptions.for_drift(0.002)
    )
    sessions = {
        robot: list(build_submaps(part, robot, config.build, config.select))
        for robot, part in (("a", frames[0:15]), ("b", frames[43:]))
    }
    r = evaluate_sessions(sessions, config, gicp=False)
    assert r["candidates"] >= 10 and r["precision"] in (None, 1.0), r
    assert not r["joined"] or r["frame_t_error"] < 0.1, r


def test_the_aligned_ate_of_anchors_in_a_line_is_none_not_a_crash():
    """A short recording's few submaps can have anchors in a line: no rigid fit exists."""
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, 0, 3] = [0.0, 1.0, 2.0]
    assert ate(poses, poses, align=True) is None
    assert ate(poses, poses) == 0.0
