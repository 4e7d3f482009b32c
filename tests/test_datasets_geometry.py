import numpy as np

from gmmap.math.geometry import (
    interpolate_poses,
    invert,
    make_poses,
    matrix_to_quaternion,
    path_length,
    quaternion_to_matrix,
    rotation_angle,
    slerp,
    so3_exp,
)


def axis_angle_quaternion(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.append(axis * np.sin(angle / 2), np.cos(angle / 2))


def test_so3_exp_matches_quaternions_and_angles():
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    for angle in (0.0, 1e-10, 0.3, 2.5):
        R = so3_exp((axis * angle)[None])[0]
        q = axis_angle_quaternion(axis, angle)
        np.testing.assert_allclose(R, quaternion_to_matrix(q[None])[0], atol=1e-12)
        np.testing.assert_allclose(rotation_angle(R[None])[0], angle, atol=1e-7)


def test_slerp_follows_the_great_circle_and_the_short_way():
    axis = [0.0, 1.0, 1.0]
    q0 = axis_angle_quaternion(axis, 0.0)[None]
    q1 = axis_angle_quaternion(axis, 2.0)[None]
    for a in (0.0, 0.25, 0.5, 1.0):
        q = slerp(q0, q1, np.array([a]))
        np.testing.assert_allclose(q[0], axis_angle_quaternion(axis, 2.0 * a), atol=1e-12)
    # -q1 is the same rotation: the result must still be the 0.5 rad one, not the long way.
    q = slerp(q0, -q1, np.array([0.25]))
    R = quaternion_to_matrix(q)[0]
    np.testing.assert_allclose(rotation_angle(R[None])[0], 0.5, atol=1e-12)


def test_interpolate_poses_between_and_on_samples():
    stamps = np.array([10.0, 11.0, 13.0])
    trans = np.array([[0.0, 0, 0], [1.0, 2.0, 0], [3.0, 2.0, 4.0]])
    quats = np.array([axis_angle_quaternion([0, 0, 1], a) for a in (0.0, 1.0, 3.0)])
    got = interpolate_poses(stamps, trans, quats, np.array([10.0, 10.5, 12.5, 13.0]))
    np.testing.assert_allclose(got[0], make_poses(trans[:1], quats[:1])[0], atol=1e-12)
    np.testing.assert_allclose(got[1][:3, 3], [0.5, 1.0, 0.0])
    np.testing.assert_allclose(got[2][:3, 3], [2.5, 2.0, 3.0])
    np.testing.assert_allclose(rotation_angle(got[:, :3, :3]), [0.0, 0.5, 2.5, 3.0], atol=1e-9)


def test_invert_and_path_length():
    T = make_poses(np.array([[1.0, 2.0, 3.0]]), axis_angle_quaternion([1, 1, 0], 0.7)[None])
    np.testing.assert_allclose(invert(T) @ T, np.eye(4)[None], atol=1e-12)
    poses = make_poses(
        np.array([[0.0, 0, 0], [3.0, 4.0, 0], [3.0, 4.0, 1.0]]), np.tile([0, 0, 0, 1.0], (3, 1))
    )
    assert path_length(poses) == 6.0 and path_length(poses[:1]) == 0.0


def random_rotations(n, seed=0):
    """Uniform random rotations (normalised Gaussian quaternions), plus the hard cases: the
    identity and half turns about each axis (qw = 0, where the trace pivot fails)."""
    q = np.random.default_rng(seed).normal(size=(n, 4))
    half_turns = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    near_half = axis_angle_quaternion([1, -2, 3], np.pi - 1e-7)[None]
    return quaternion_to_matrix(np.concatenate([q, half_turns, near_half]))


def test_matrix_quaternion_round_trip():
    R = random_rotations(500)
    q = matrix_to_quaternion(R)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    assert (q[:, 3] >= 0).all()  # one quaternion per rotation
    np.testing.assert_allclose(quaternion_to_matrix(q), R, atol=1e-12)
    # Back to the same quaternion up to sign, and a (3, 3) input is one rotation.
    again = matrix_to_quaternion(quaternion_to_matrix(q))
    np.testing.assert_allclose(np.abs(np.sum(again * q, axis=1)), 1.0, atol=1e-12)
    np.testing.assert_allclose(matrix_to_quaternion(R[7]), q[7:8])
    expected = axis_angle_quaternion([0.0, 0.0, 1.0], 1.0)
    got = matrix_to_quaternion(quaternion_to_matrix(expected[None]))[0]
    np.testing.assert_allclose(got, expected, atol=1e-15)
