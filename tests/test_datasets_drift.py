import numpy as np
import pytest

from gmmap import InvalidInputError
from gmmap.math.drift import Drift, apply_drift
from gmmap.math.geometry import invert, rotation_angle, so3_exp


def straight_line(n: int, step: float = 0.1) -> np.ndarray:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = step * np.arange(n)
    return poses


def turning_in_place(n: int, step: float = 0.05) -> np.ndarray:
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = so3_exp(np.outer(step * np.arange(n), [0.0, 0.0, 1.0]))
    return poses


def test_deterministic_for_a_seed_and_first_pose_unchanged():
    truth = straight_line(50)
    truth[0, :3, 3] = [1.0, 2.0, 3.0]
    a = apply_drift(truth, Drift(seed=7))
    np.testing.assert_array_equal(a, apply_drift(truth, Drift(seed=7)))
    np.testing.assert_array_equal(a, Drift(seed=7)(truth))
    np.testing.assert_array_equal(a[0], truth[0])
    assert not np.allclose(a, apply_drift(truth, Drift(seed=8)))
    # The simulator's odometry-model signature: a generator overrides the seed.
    b = Drift(seed=7)(truth, np.random.default_rng(123))
    np.testing.assert_array_equal(b, apply_drift(truth, Drift(), np.random.default_rng(123)))
    np.testing.assert_allclose(
        a[:, :3, :3] @ a[:, :3, :3].transpose(0, 2, 1), np.eye(3)[None].repeat(50, 0), atol=1e-12
    )


def test_error_grows_with_distance():
    truth = straight_line(201)
    drifted = np.array([apply_drift(truth, Drift(seed=s)) for s in range(200)])
    errors = np.linalg.norm(drifted[:, :, :3, 3] - truth[:, :3, 3], axis=2)
    rms = np.sqrt((errors**2).mean(axis=0))
    assert 0 < rms[25] < rms[50] < rms[100] < rms[200]
    # Translation noise alone is a random walk: rms ∝ sqrt(distance); with heading noise
    # the lateral error grows faster, so the end error is at least the walk's.
    walk = 0.02 * 0.1 * np.sqrt(3 * 200)
    assert rms[200] > 0.8 * walk


def test_no_motion_no_drift_unless_a_floor_is_set():
    still = np.tile(np.eye(4), (30, 1, 1))
    np.testing.assert_allclose(apply_drift(still, Drift(seed=1)), still, atol=1e-15)
    moved = apply_drift(still, Drift(translation_floor=0.01, rotation_floor=0.001, seed=1))
    assert np.linalg.norm(moved[-1, :3, 3]) > 1e-3


def test_rotation_noise_follows_the_angle_turned():
    truth = turning_in_place(100)
    quiet = apply_drift(truth, Drift(rotation_per_rad=0.0, rotation_per_m=0.0, seed=2))
    np.testing.assert_allclose(quiet, truth, atol=1e-12)  # no translation, no turn noise
    noisy = apply_drift(truth, Drift(rotation_per_rad=0.05, seed=2))
    err = rotation_angle((invert(truth[-1:]) @ noisy[-1:])[:, :3, :3])[0]
    assert 1e-3 < err < 0.2


def test_gravity_referenced_drift_keeps_roll_and_pitch():
    # A camera (z forward, y down: tilted against the world's +z) driving and turning.
    camera = so3_exp(np.array([-np.pi / 2, 0.0, 0.0]))
    truth = turning_in_place(60) @ straight_line(60)
    truth[:, :3, :3] = truth[:, :3, :3] @ camera
    up = (0.0, 0.0, 1.0)
    drifted = apply_drift(truth, Drift(rotation_per_rad=0.05, rotation_per_m=0.05, seed=3, up=up))
    seen = np.einsum("mji,j->mi", truth[:, :3, :3], up)  # the world's up in each sensor frame
    np.testing.assert_allclose(np.einsum("mji,j->mi", drifted[:, :3, :3], up), seen, atol=1e-12)
    assert rotation_angle((invert(truth[-1:]) @ drifted[-1:])[:, :3, :3])[0] > 1e-3  # heading
    with pytest.raises(InvalidInputError, match="up"):
        Drift(up=(0.0, 0.0, 0.0))


def test_bad_parameters_and_shapes():
    with pytest.raises(InvalidInputError, match="translation"):
        Drift(translation=-0.1)
    with pytest.raises(InvalidInputError, match="rotation_per_m"):
        Drift(rotation_per_m=float("nan"))
    with pytest.raises(InvalidInputError, match=r"\(M, 4, 4\)"):
        apply_drift(np.eye(4))
    one = np.eye(4)[None]
    np.testing.assert_array_equal(apply_drift(one), one)
