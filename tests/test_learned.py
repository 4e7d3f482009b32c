"""The learned place descriptor (PointNetVLAD, `gmmap.mapping.learned`): invariances, the
shipped weights, the place database and CLI on it, and a short training run."""

import json
import math

import numpy as np
import pytest

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.eval.placedata import Clouds
from gmmap.mapping.learned import (
    WEIGHTS,
    Architecture,
    LearnedDescriptor,
    init_params,
    load,
    reference_cloud,
    save,
)
from gmmap.mapping.place import PlaceDatabase, ShapeDescriptor, descriptor_for
from gmmap.options import PlaceOptions


def room(seed: int, n: int = 4096) -> np.ndarray:
    """Points on the walls, floor and a box of a random room (metres)."""
    rng = np.random.default_rng(seed)
    w, d = rng.uniform(3, 8, 2)
    u = rng.uniform(0, 1, (n, 3))
    side = rng.integers(0, 5, n)
    p = np.column_stack([u[:, 0] * w, u[:, 1] * d, u[:, 2] * 2.5])
    p[side == 0, 0], p[side == 1, 0], p[side == 2, 1], p[side == 3, 1] = 0, w, 0, d
    p[side == 4, 2] = 0
    box = rng.uniform(0, 1, (n // 8, 3)) * [1.0, 0.6, 1.1] + [w / 3, d / 3, 0]
    return np.vstack([p, box])[:n] + rng.normal(0, 0.01, (n, 3))


def turned(points: np.ndarray, yaw: float, shift) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return points @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + np.asarray(shift)


@pytest.fixture(scope="module")
def shipped() -> LearnedDescriptor:
    return LearnedDescriptor()


def test_the_output_ignores_the_order_of_the_points(shipped):
    p = room(0)
    order = np.random.default_rng(1).permutation(len(p))
    a, b = shipped.describe_points(p), shipped.describe_points(p[order])
    assert np.abs(a - b).max() < 1e-5
    assert a.shape == (shipped.model[1].output,) and abs(np.linalg.norm(a) - 1) < 1e-6


@pytest.mark.parametrize("yaw", [0.3, math.pi / 2, 2.0, math.pi, -2.7])
def test_a_turned_and_moved_copy_keeps_its_descriptor(shipped, yaw):
    p = room(2)
    a = shipped.describe_points(p)
    b = shipped.describe_points(turned(p, yaw, [12.0, -3.0, 0.0]))
    assert 1.0 - a @ b < 1e-4


def test_a_turned_copy_is_nearer_than_another_room(shipped):
    a = shipped.describe_points(room(3))
    b = shipped.describe_points(turned(room(3), 1.1, [1, 2, 0]))
    other = shipped.describe_points(room(4))
    assert 1.0 - a @ b < 1.0 - a @ other


def test_the_shipped_weights_give_their_recorded_outputs(shipped):
    _, _, meta = shipped.model
    ref = meta["reference"]
    out = shipped.describe_points(reference_cloud(ref["seed"]))
    assert np.abs(out[: len(ref["output"])] - np.array(ref["output"])).max() < 1e-4
    assert WEIGHTS.stat().st_size <= 5_000_000
    assert 0 < shipped.candidate_distance < 2
    assert meta["trained_by"] == "benchmarks/train_place.py"
    held_out = set(meta["recipe"]["held_out"])
    assert held_out and not held_out & set(meta["parts_used"])


def test_weights_that_are_not_weights_are_refused(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not an npz")
    with pytest.raises(FileFormatError):
        LearnedDescriptor(str(bad)).describe_points(room(0))
    arch = Architecture((8,), 2, 4)
    params = init_params(arch)
    params["out_w"] = params["out_w"][:1]
    save(tmp_path / "short.npz", params, arch, {"max_distance": 0.1})
    with pytest.raises(FileFormatError, match="out_w"):
        load(str(tmp_path / "short.npz"))


def test_too_few_or_bad_points_are_refused(shipped):
    with pytest.raises(InvalidInputError):
        shipped.describe_points(np.zeros((2, 3)))
    with pytest.raises(InvalidInputError):
        shipped.describe_points(np.full((10, 3), np.nan))


def test_the_place_options_name_the_descriptor():
    assert isinstance(descriptor_for(PlaceOptions(descriptor="learned")), LearnedDescriptor)
    with pytest.raises(InvalidInputError, match="descriptor"):
        PlaceOptions(descriptor="pointnet")
    db = PlaceDatabase(descriptor_for(PlaceOptions(descriptor="learned")))
    assert db.max_distance == LearnedDescriptor().candidate_distance
    assert PlaceDatabase(options=PlaceOptions(max_distance=0.3)).max_distance == 0.3
    assert PlaceDatabase().max_distance == 0.1 and ShapeDescriptor().max_distance == 8.0


def test_a_robots_config_picks_the_learned_descriptor(tmp_path):
    from gmmap.config import Config, load_config
    from gmmap.mapping.mapper import Mapper

    (tmp_path / "robot.yaml").write_text("place:\n  descriptor: learned\n")
    mapper = Mapper(load_config(tmp_path / "robot.yaml"))
    assert isinstance(mapper.db.descriptor, LearnedDescriptor)
    assert not isinstance(Mapper(Config()).db.descriptor, LearnedDescriptor)


def test_the_place_database_finds_a_turned_copy_with_the_learned_descriptor():
    from gmmap.math.em import fit_gmm

    db = PlaceDatabase(descriptor_for(PlaceOptions(descriptor="learned", max_distance=2.0)))
    gmms = [fit_gmm(room(s, 3000), n_components=40, covariance="full", seed=0) for s in range(4)]
    for i, g in enumerate(gmms):
        db.add("a", i, g)
    T = np.eye(4)
    T[:3, :3] = turned(np.eye(3), 0.8, [0, 0, 0]).T
    found = db.query("b", 0, gmms[2].transform(T))
    assert found[0].robot == "a" and found[0].seq == 2


def synthetic_parts() -> list[Clouds]:
    """Two parts of four rooms each, two views per room (positives), far apart."""
    parts = []
    for k in range(2):
        rng = np.random.default_rng(k)
        clouds, centres = [], []
        for r in range(4):
            base = room(10 * k + r)
            for _ in range(2):
                view = turned(base, rng.uniform(-3, 3), rng.uniform(-1, 1, 3) * [1, 1, 0])
                clouds.append(view[rng.permutation(len(view))])
                centres.append([30.0 * r, 0, 0])
        c = np.asarray(clouds, np.float32)
        pos = np.zeros((8, 8), bool)
        for r in range(4):
            pos[2 * r, 2 * r + 1] = pos[2 * r + 1, 2 * r] = True
        parts.append(Clouds(c, c, pos, np.array(centres), f"synthetic{k}"))
    return parts


def test_a_short_training_run_lowers_its_loss():
    pytest.importorskip("jax", reason="training needs the dev extra's JAX")
    from gmmap.eval.train_place import Sampler, TrainOptions, train

    options = TrainOptions(Architecture((16, 32), 4, 16), queries=4, negatives=3, points=256)
    batch = Sampler(synthetic_parts(), options).batch()
    params, log = train(synthetic_parts(), options, steps=25, batches=lambda: batch)
    losses = [e["loss"] for e in log]
    assert len(losses) == 25 and all(np.isfinite(losses))
    assert np.mean(losses[-3:]) < 0.8 * losses[0]
    assert set(params) == set(options.arch.shapes())


def test_eval_place_takes_the_learned_descriptor(tmp_path):
    from click.testing import CliRunner

    from gmmap.cli import main

    args = ["eval", "place", "--descriptor", "learned", "--robots", "2", "--no-gicp", "--json"]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    out = json.loads(r.output.strip().splitlines()[-1])
    assert out["descriptor"] == "learned"
    for key in ("queries", "submaps", "gmm", "points", "verified", "describe_time_s"):
        assert key in out
    assert 0 <= out["gmm"]["recall_at_1pct"] <= 1
