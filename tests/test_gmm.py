import numpy as np
import pytest

import gmmap
from conftest import known_mixture_samples
from gmmap import FileFormatError, Gmm, InvalidGmmError, InvalidInputError


def rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def rigid(axis, angle, t):
    T = np.eye(4)
    T[:3, :3] = rotation(axis, angle)
    T[:3, 3] = t
    return T


@pytest.fixture
def g():
    _, w, mu, cov = known_mixture_samples(10)
    return Gmm(w, mu, cov)


def test_log_pdf_matches_direct_formula(g):
    x = np.array([[0.1, -0.2, 0.3], [2.0, 1.0, 0.0]])
    direct = np.zeros(len(x))
    for w, m, c in zip(g.weights, g.means, g.covariances, strict=True):
        d = x - m
        q = np.einsum("ni,ij,nj->n", d, np.linalg.inv(c), d)
        direct += w * np.exp(-0.5 * q) / np.sqrt((2 * np.pi) ** 3 * np.linalg.det(c))
    np.testing.assert_allclose(g.pdf(x), direct, rtol=1e-10)
    assert g.log_pdf(x[0]) == pytest.approx(np.log(direct[0]), rel=1e-10)
    assert g.score(x) == pytest.approx(np.log(direct).mean(), rel=1e-10)


def test_pdf_integrates_to_one(g):
    # Importance sampling from the mixture with covariances inflated 4x (bounded ratio p/q),
    # sampled and evaluated with plain numpy so no gmmap code appears on both sides.
    rng = np.random.default_rng(1)
    wide = 4.0 * g.covariances
    comp = rng.choice(len(g), size=200_000, p=g.weights)
    z = rng.standard_normal((200_000, 3))
    x = g.means[comp] + np.einsum("nij,nj->ni", np.linalg.cholesky(wide)[comp], z)
    q = np.zeros(len(x))
    for w, m, c in zip(g.weights, g.means, wide, strict=True):
        d = x - m
        maha = np.einsum("ni,ij,nj->n", d, np.linalg.inv(c), d)
        q += w * np.exp(-0.5 * maha) / np.sqrt((2 * np.pi) ** 3 * np.linalg.det(c))
    assert np.mean(g.pdf(x) / q) == pytest.approx(1.0, abs=0.01)


def test_gradient_matches_finite_differences(g):
    rng = np.random.default_rng(2)
    x = g.means[0] + rng.normal(size=(20, 3)) * 0.7
    h = 1e-6
    fd = np.stack([(g.pdf(x + h * e) - g.pdf(x - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(g.gradient(x), fd, rtol=1e-5, atol=1e-9)
    assert g.gradient(x[0]).shape == (3,)


def test_transform_then_inverse_is_identity_and_rotates_in_full(g):
    T = rigid([1, 2, 3], 0.7, [0.5, -1.0, 2.0])
    moved = g.transform(T)
    R = T[:3, :3]
    for c, c2 in zip(g.covariances, moved.covariances, strict=True):
        np.testing.assert_allclose(c2, R @ c @ R.T, atol=1e-12)
    # A diagonal covariance gets off-diagonal terms: nothing is re-diagonalised.
    d = Gmm.from_diagonal([1.0], [[0, 0, 0]], [[1.0, 0.01, 0.1]]).transform(T)
    assert not d.is_diagonal
    back = moved.transform(np.linalg.inv(T))
    np.testing.assert_allclose(back.means, g.means, atol=1e-12)
    np.testing.assert_allclose(back.covariances, g.covariances, atol=1e-12)
    x = np.array([[0.3, 0.1, -0.4]])
    xt = x @ R.T + T[:3, 3]
    np.testing.assert_allclose(moved.pdf(xt), g.pdf(x), rtol=1e-10)


def test_transform_rejects_non_rigid(g):
    with pytest.raises(InvalidInputError, match="orthonormal"):
        g.transform(np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(InvalidInputError, match="4x4"):
        g.transform(np.eye(3))


def test_sample_statistics_and_determinism(g):
    x = g.sample(200_000, seed=3)
    assert x.shape == (200_000, 3)
    np.testing.assert_allclose(x.mean(axis=0), g.weights @ g.means, atol=0.02)
    np.testing.assert_array_equal(x[:10], g.sample(200_000, seed=3)[:10])
    assert not np.array_equal(x[:10], g.sample(200_000, seed=4)[:10])


def test_save_load_roundtrip(g, tmp_path):
    path = tmp_path / "map.gmm"
    g.save(path)
    h = Gmm.load(path)
    for a, b in [(g.weights, h.weights), (g.means, h.means), (g.covariances, h.covariances)]:
        np.testing.assert_array_equal(a, b)


def test_load_rejects_truncated_and_foreign_files(g, tmp_path):
    path = tmp_path / "map.gmm"
    g.save(path)
    data = path.read_bytes()
    (tmp_path / "cut.gmm").write_bytes(data[: len(data) // 2])
    with pytest.raises(FileFormatError, match=r"cut\.gmm"):
        Gmm.load(tmp_path / "cut.gmm")
    (tmp_path / "junk.gmm").write_bytes(b"not a gmm at all")
    with pytest.raises(FileFormatError):
        Gmm.load(tmp_path / "junk.gmm")
    np.savez(tmp_path / "other.npz", weights=g.weights)
    with pytest.raises(FileFormatError, match="not a gmmap GMM"):
        Gmm.load(tmp_path / "other.npz")
    with pytest.raises(FileNotFoundError):
        Gmm.load(tmp_path / "missing.gmm")


@pytest.mark.parametrize(
    ("weights", "means", "covs", "message"),
    [
        ([0.5, 0.6], np.zeros((2, 3)), np.tile(np.eye(3), (2, 1, 1)), "sum to 1"),
        ([1.5, -0.5], np.zeros((2, 3)), np.tile(np.eye(3), (2, 1, 1)), "non-negative"),
        ([1.0], [[0, 0, np.nan]], [np.eye(3)], "NaN"),
        ([1.0], [[0, 0, 0]], [np.diag([1.0, 0.0, 1.0])], "positive-definite"),
        ([1.0], [[0, 0, 0]], [[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]], "symmetric"),
        ([1.0], [[0, 0]], [np.eye(3)], "expected weights"),
        ([], np.zeros((0, 3)), np.zeros((0, 3, 3)), "K >= 1"),
    ],
)
def test_validation_errors(weights, means, covs, message):
    with pytest.raises(InvalidGmmError, match=message):
        Gmm(weights, means, covs)


def test_arrays_are_read_only_and_sizes(g):
    with pytest.raises(ValueError):
        g.means[0, 0] = 1.0
    assert g.float32_bytes == 3 * 4 * 10
    assert gmmap.Gmm.from_diagonal([1.0], [[0, 0, 0]], [[1, 1, 1]]).float32_bytes == 28


def test_evaluation_rejects_bad_points(g):
    with pytest.raises(InvalidInputError, match="NaN"):
        g.pdf([[0.0, np.nan, 0.0]])
    with pytest.raises(InvalidInputError, match="shape"):
        g.score(np.zeros((4, 2)))


def test_ellipsoids_rebuild_each_covariance_from_a_proper_rotation():
    from gmmap.math.geometry import make_poses

    rng = np.random.default_rng(3)
    A = rng.normal(size=(5, 3, 3))
    covs = A @ A.transpose(0, 2, 1) + 0.01 * np.eye(3)
    g = Gmm(np.full(5, 0.2), rng.normal(size=(5, 3)), covs)
    quats, half = g.ellipsoids(sigma=2.0)
    R = make_poses(np.zeros((5, 3)), quats)[:, :3, :3]
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(R @ (np.eye(3) * (half / 2.0)[:, None, :] ** 2) @ R.transpose(0, 2, 1), covs)
