from pathlib import Path

import numpy as np
import pytest

import gmmap
from gmmap import Gmm, InvalidInputError, fit_gmm, register
from gmmap.math.geometry import pose_distance
from gmmap.math.register import confidence


def rigid(yaw: float, t, roll: float = 0.0) -> np.ndarray:
    cz, sz, cx, sx = np.cos(yaw), np.sin(yaw), np.cos(roll), np.sin(roll)
    T = np.eye(4)
    T[:3, :3] = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, cx, -sx], [0, sx, cx]]
    )
    T[:3, 3] = t
    return T


@pytest.fixture(scope="module")
def scene(slice_points):
    return fit_gmm(slice_points, 60, "full")


def test_recovers_a_known_transform(scene):
    truth = rigid(0.2, [0.1, -0.08, 0.05], roll=0.05)
    source = scene.transform(np.linalg.inv(truth))
    r = register(source, scene, np.eye(4))
    np.testing.assert_allclose(r.transform, truth, atol=1e-4)
    assert r.confidence > 0.999
    assert r.information.shape == (6, 6)
    np.testing.assert_allclose(r.information, r.information.T, atol=1e-9)
    assert np.all(np.linalg.eigvalsh(r.information) > 0)


def test_coarse_scales_on_merged_mixtures_end_where_the_whole_ones_do(scene):
    """From a guess 15° off, the coarse scales may see the mixtures merged into fewer
    components (moment matched: weight, mean and spread kept); the end point is the same."""
    merged = scene.coarsened(0.4)
    assert len(merged) < len(scene) and np.isclose(merged.weights.sum(), 1.0)
    mean = scene.weights @ scene.means
    np.testing.assert_allclose(merged.weights @ merged.means, mean, atol=1e-12)

    def second_moment(g):
        return np.einsum(
            "k,kij->ij", g.weights, g.covariances + g.means[:, :, None] * g.means[:, None]
        )

    np.testing.assert_allclose(second_moment(merged), second_moment(scene), atol=1e-12)
    truth = rigid(0.26, [0.03, -0.02, 0.01], roll=0.05)
    source = scene.transform(np.linalg.inv(truth))
    whole = register(source, scene, np.eye(4), coarse_cell=0.0)
    fast = register(source, scene, np.eye(4))
    np.testing.assert_allclose(fast.transform, whole.transform, atol=1e-5)
    np.testing.assert_allclose(fast.transform, truth, atol=1e-4)
    with pytest.raises(InvalidInputError):
        scene.coarsened(0.0)


def test_finds_the_pose_without_a_guess_and_in_4dof(scene):
    truth = rigid(2.3, [0.4, -0.3, 0.0])  # 132°: far from any local basin of the identity
    source = scene.transform(np.linalg.inv(truth))
    np.testing.assert_allclose(register(source, scene).transform, truth, atol=1e-4)
    r4 = register(source, scene, dof=4, yaw_hint=2.0)
    np.testing.assert_allclose(r4.transform, truth, atol=1e-4)


def test_confidence_is_one_for_itself_and_falls_with_misalignment(scene):
    assert confidence(scene, scene) == pytest.approx(1.0, abs=1e-12)
    values = [confidence(scene, scene, rigid(0.0, [d, 0, 0])) for d in (0.02, 0.05, 0.1, 0.2)]
    assert all(a > b for a, b in zip([1.0, *values], values, strict=False))


def test_the_returned_basin_is_the_better_refined_one():
    """Two simulated LiDAR submaps (tests/data/basin_*.npz) whose yaw start ranked first at
    the coarse scale refines to C 0.17 and the runner-up to 0.34: the better one is returned,
    the other is the alternative."""
    data = Path(__file__).parent / "data"
    source, target = (Gmm.load(data / f"basin_{k}.npz") for k in ("source", "target"))
    r = register(source, target)
    assert r.confidence > 0.3 and r.alternative_confidence < r.confidence


def test_level_planes_do_not_rank_the_solutions():
    """Two simulated 16-beam LiDAR submaps of the office (tests/data/level_*: seed 0, robots 0
    and 2, turned half round and 3.9 m apart). Over the whole mixtures a wrong solution lays
    more floor on floor and wins; ranked on the upright parts, the right one does, reports
    its C on the whole mixtures and keeps the floor's solution as a lower basin."""
    data = Path(__file__).parent / "data"
    source, target = (Gmm.load(data / f"level_{k}.npz") for k in ("source", "target"))
    truth = np.loadtxt(data / "level_truth.txt")
    whole = register(source, target, level_planes=True)
    assert pose_distance(whole.transform, truth)[0] > 1.0
    r = register(source, target)
    t, angle = pose_distance(r.transform, truth)
    assert t < 0.2 and angle < 3.0
    assert r.confidence == pytest.approx(confidence(source, target, r.transform), abs=0.02)
    assert type(r.upright_confidence) is float  # a numpy scalar breaks the reports' JSON
    floor = [c for T, c in r.basins[1:] if pose_distance(T, whole.transform)[0] < 0.5]
    assert floor and floor[0] < r.confidence and r.alternative_confidence < r.confidence


def test_a_floor_alone_is_searched_whole():
    """With fewer than three components left once level planes are set aside, the search runs
    on the whole mixtures as before."""
    flat = np.diag([1.0, 1.0, 1e-4])
    floor = Gmm(np.full(4, 0.25), [[0, 0, 0], [2, 0, 0], [0, 2, 0], [2, 2, 0]], [flat] * 4)
    r = register(floor, floor)
    assert r.confidence == pytest.approx(1.0, abs=0.01)
    assert r.confidence == register(floor, floor, level_planes=True).confidence


def test_confidence_does_not_depend_on_component_count(slice_points):
    few, many = fit_gmm(slice_points, 50, "full"), fit_gmm(slice_points, 150, "full")
    assert confidence(few, many) == pytest.approx(1.0, abs=0.05)
    assert register(few, many, np.eye(4)).confidence == pytest.approx(1.0, abs=0.05)


def test_bad_input_raises_clear_errors(scene):
    with pytest.raises(InvalidInputError, match=r"gmmap\.Gmm"):
        register(np.zeros((3, 3)), scene)
    with pytest.raises(InvalidInputError, match="dof"):
        register(scene, scene, dof=5)
    with pytest.raises(InvalidInputError, match="4x4"):
        register(scene, scene, np.eye(3))
    with pytest.raises(InvalidInputError, match="finite"):
        register(scene, scene, yaw_hint=float("nan"))
    with pytest.raises(gmmap.InvalidGmmError):
        Gmm([], np.zeros((0, 3)), np.zeros((0, 3, 3)))  # an empty mixture cannot even exist


def test_eval_registration_command_prints_table_one(tmp_path):
    import json

    from click.testing import CliRunner

    from gmmap.cli import main
    from gmmap.io.datasets import BUNDLED_TUM_SLICE

    args = [
        "eval",
        "registration",
        str(BUNDLED_TUM_SLICE),
        "--frames-per-submap",
        "2",
        "--stride",
        "4",
        "--json",
    ]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["pairs"] == 3
    keys = {
        "t_error_mean",
        "t_error_median",
        "t_rmse",
        "r_error_mean",
        "r_error_median",
        "r_rmse",
        "success_rate",
        "time_per_pair_s",
        "t_error_quantiles",
        "r_error_quantiles",
    }
    assert set(out["methods"]) == {"points", "gmm-merge", "per-frame", "gicp"}
    gmm_keys = keys | {"confidence_failed_max", "confidence_succeeded_min"}
    for name, m in out["methods"].items():
        assert set(m) == (keys if name == "gicp" else gmm_keys)
        assert 0.0 <= m["success_rate"] <= 1.0
        q = m["t_error_quantiles"]  # 5th … 95th percentiles, the median among them
        assert len(q) == 5 and q == sorted(q) and np.isclose(q[2], m["t_error_median"])
    # The slice's frames are 1.3 s apart (up to 20 cm): errors stay well under that motion.
    assert all(m["t_error_mean"] < 0.3 for m in out["methods"].values())


def test_global_mode_recovers_random_perturbations(slice_points):
    from gmmap.eval.registration import pose_errors, random_perturbation

    g = fit_gmm(slice_points, 60, "full")
    rng = np.random.default_rng(1)
    for _ in range(3):
        P = random_perturbation(rng)
        r = register(g.transform(P), g)
        t, deg = pose_errors(r.transform, np.linalg.inv(P))
        assert t < 1e-3 and deg < 0.05


def test_table_one_on_fr3_cabinet_beats_gicp_from_odometry(shared_data):
    """From odometry the harness registers at the mixtures' own resolution: a widened first
    step let the floor's camera-fixed footprint pull every pair 10–13 cm / 5–7° off."""
    from gmmap.eval.registration import evaluate_registration
    from gmmap.io import datasets

    frames = datasets.open(
        shared_data / "tum_fr3_cabinet_keyframes", stride=4, drift=datasets.Drift(translation=0.05)
    )[:20]
    r = evaluate_registration(frames, 1, ("points", "gicp"), odometry_guess=True)
    gmm, gicp = r["methods"]["points"], r["methods"]["gicp"]
    assert r["pairs"] == 19
    assert gmm["t_error_mean"] < 0.06 and gmm["r_error_mean"] < 2.0
    assert gmm["t_rmse"] <= gicp["t_rmse"] and gmm["r_rmse"] <= gicp["r_rmse"]


def test_guess_mode_rejects_bad_ranges_and_other_modes():
    from click.testing import CliRunner

    from gmmap.cli import main
    from gmmap.io.datasets import BUNDLED_TUM_SLICE

    base = ["eval", "registration", str(BUNDLED_TUM_SLICE), "--frames-per-submap", "2"]
    for extra, message in (
        (["--guess-error", "abc"], "LOW-HIGH"),
        (["--guess-error", "20-10"], "LOW <= HIGH"),
        (["--guess-error", "10-20", "--global"], "excludes the global mode"),
    ):
        r = CliRunner().invoke(main, [*base, *extra])
        assert r.exit_code != 0 and message in r.output, (extra, r.output)


def test_repeats_pool_pairs_built_with_other_seeds():
    """``repeats`` builds the same frame groups again with the next EM and guess seeds: as
    many pairs again, other fits, the same truths."""
    from gmmap.eval.registration import evaluate_registration
    from gmmap.io import datasets

    frames = datasets.open(datasets.BUNDLED_TUM_SLICE, stride=4)[:6]
    once = evaluate_registration(frames, 2, ("points",), guess_deg=(10, 20))
    twice = evaluate_registration(frames, 2, ("points",), guess_deg=(10, 20), repeats=2)
    assert twice["pairs"] == 2 * once["pairs"] and twice["repeats"] == 2
    assert twice["methods"]["points"] != once["methods"]["points"]
    with pytest.raises(InvalidInputError, match="repeats"):
        evaluate_registration(frames, 2, ("points",), repeats=0)


def test_the_vote_finds_a_part_far_from_the_whole_centroid():
    """A corner of a 12 m room-sized scene, its centroid 4 m from the whole's: the translation
    votes find it where starts with the centroids aligned do not; every distinct basin comes
    back, the best first, and refining more distinct coarse solutions never returns a worse
    one."""
    from gmmap.eval.registration import pose_errors

    rng = np.random.default_rng(3)
    n = 120
    axes = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    spread = np.array([0.3, 0.15, 0.02]) ** 2
    scene = Gmm(np.full(n, 1 / n), rng.uniform([0, 0, 0], [12, 12, 2], (n, 3)),
                np.einsum("nij,j,nkj->nik", axes, spread, axes))  # fmt: skip
    part = (scene.means[:, 0] > 7) & (scene.means[:, 1] > 7)
    piece = Gmm(scene.weights[part] / part.sum() * n, scene.means[part], scene.covariances[part])
    truth = rigid(2.0, [0.3, -0.2, 0.0])
    source = piece.transform(np.linalg.inv(truth))
    r = register(source, scene, refine_starts=4)
    t, deg = pose_errors(r.transform, truth)
    assert t < 0.01 and deg < 0.5
    assert np.allclose(r.basins[0][0], r.transform) and r.basins[0][1] == r.confidence
    assert [c for _, c in r.basins] == sorted((c for _, c in r.basins), reverse=True)
    assert len(r.basins) == 1 or r.alternative_confidence == r.basins[1][1]
    centroids = register(source, scene, search_cell=0.0, refine_starts=4)
    assert pose_errors(centroids.transform, truth)[0] > 0.5
    previous = 0.0
    for k in (1, 2, 3, 5):
        c = register(source, scene, refine_starts=k).confidence
        assert c >= previous - 1e-9
        previous = c
    with pytest.raises(InvalidInputError):
        register(source, scene, refine_starts=0)
    with pytest.raises(InvalidInputError):
        register(source, scene, search_cell=-1.0)
