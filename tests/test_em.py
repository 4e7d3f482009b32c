import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import known_mixture_samples
from gmmap import InvalidInputError, fit_gmm


def match_components(fitted_means, true_means):
    return [int(np.argmin(np.linalg.norm(fitted_means - m, axis=1))) for m in true_means]


@pytest.mark.parametrize("covariance", ["full", "diag"])
def test_recovers_known_mixture(covariance):
    pts, w, mu, cov = known_mixture_samples(30_000)
    g = fit_gmm(pts, 3, covariance, max_iter=300, tol=1e-6)
    idx = match_components(g.means, mu)
    assert sorted(idx) == [0, 1, 2]
    np.testing.assert_allclose(g.weights[idx], w, atol=0.01)
    np.testing.assert_allclose(g.means[idx], mu, atol=0.03)
    if covariance == "full":
        np.testing.assert_allclose(g.covariances[idx], cov, atol=0.02)
    else:
        np.testing.assert_allclose(
            np.diagonal(g.covariances[idx], axis1=1, axis2=2),
            np.diagonal(cov, axis1=1, axis2=2),
            atol=0.02,
        )
        assert g.is_diagonal


def numpy_em_step(pts, g, covariance, reg=1e-6):
    """One textbook EM iteration on all N x K pairs, the reference for the core."""
    log_r = np.log(g.weights) + np.stack(
        [
            -0.5 * np.einsum("ni,ij,nj->n", pts - m, np.linalg.inv(c), pts - m)
            - 0.5 * np.log((2 * np.pi) ** 3 * np.linalg.det(c))
            for m, c in zip(g.means, g.covariances, strict=True)
        ],
        axis=1,
    )
    r = np.exp(log_r - log_r.max(axis=1, keepdims=True))
    r /= r.sum(axis=1, keepdims=True)
    nk = r.sum(axis=0)
    means = (r.T @ pts) / nk[:, None]
    covs = np.stack([((pts - m).T * r[:, k]) @ (pts - m) / nk[k] for k, m in enumerate(means)])
    if covariance == "diag":
        covs = covs * np.eye(3)
    return nk / len(pts), means, covs + reg * np.eye(3)


@pytest.mark.parametrize("covariance", ["diag", "full"])
def test_one_exact_iteration_matches_textbook_em(covariance, slice_points):
    pts = slice_points[:5000]
    init = fit_gmm(pts, 12, covariance, max_iter=0, truncation=np.inf)
    one = fit_gmm(pts, 12, covariance, max_iter=1, truncation=np.inf)
    w, m, c = numpy_em_step(pts, init, covariance)
    np.testing.assert_allclose(one.weights, w, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(one.means, m, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(one.covariances, c, rtol=1e-6, atol=1e-10)


def test_truncation_costs_no_likelihood(slice_points):
    exact = fit_gmm(slice_points, 50, max_iter=20, tol=0, truncation=np.inf)
    fast = fit_gmm(slice_points, 50, max_iter=20, tol=0)
    assert fast.score(slice_points) == pytest.approx(exact.score(slice_points), abs=2e-3)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_real_scene_likelihood_not_worse_than_sklearn(slice_points):
    from sklearn.mixture import GaussianMixture

    ours = fit_gmm(slice_points, 50, max_iter=30, tol=0)
    ref = GaussianMixture(
        50, covariance_type="diag", max_iter=30, tol=0, init_params="k-means++", random_state=0
    ).fit(slice_points)
    assert ours.score(slice_points) >= ref.score(slice_points) - 0.02


def test_same_seed_same_fit_on_any_thread_count(slice_points, tmp_path):
    a = fit_gmm(slice_points, 30, seed=5)
    b = fit_gmm(slice_points, 30, seed=5)
    np.testing.assert_array_equal(a.means, b.means)
    assert not np.array_equal(a.means, fit_gmm(slice_points, 30, seed=6).means)
    np.save(tmp_path / "p.npy", slice_points)
    code = (
        "import sys, numpy as np, gmmap;"
        "g = gmmap.fit_gmm(np.load(sys.argv[1]), 30, seed=5); np.save(sys.argv[2], g.means)"
    )
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    subprocess.run(
        [sys.executable, "-c", code, tmp_path / "p.npy", tmp_path / "m.npy"], check=True, env=env
    )
    np.testing.assert_array_equal(np.load(tmp_path / "m.npy"), a.means)


def test_fewer_points_than_components_and_duplicates():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [1, 0, 0]], float)
    g = fit_gmm(pts, 10)
    assert len(g) == 3
    assert g.weights.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(sorted(g.weights), [0.2, 0.2, 0.6])
    single = fit_gmm(np.ones((50, 3)), 5)
    assert len(single) == 1 and np.allclose(single.means, 1.0)


def test_flat_data_keeps_positive_definite_covariances():
    rng = np.random.default_rng(0)
    plane = np.c_[rng.uniform(0, 2, (4000, 2)), np.full(4000, 1.5)]
    for covariance in ("diag", "full"):
        g = fit_gmm(plane, 8, covariance, reg_covar=1e-5)
        assert np.all(np.linalg.eigvalsh(g.covariances) > 0)
        assert np.allclose(g.covariances[:, 2, 2], 1e-5)


def test_fit_info(slice_points):
    g = fit_gmm(slice_points, 20, tol=1e-3)
    assert g.fit_info.converged and 1 <= g.fit_info.n_iter <= 100
    g = fit_gmm(slice_points, 20, max_iter=3, tol=0)
    assert g.fit_info.n_iter == 3 and not g.fit_info.converged


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"points": [[0, 0, np.nan]]}, "NaN"),
        ({"points": [[0, 0, np.inf], [1, 1, 1]]}, "row 0"),
        ({"points": np.zeros((0, 3))}, "empty"),
        ({"points": np.zeros((5, 2))}, "shape"),
        ({"points": "abc"}, "numeric"),
        ({"n_components": 0}, "n_components"),
        ({"covariance": "spherical"}, "covariance"),
        ({"init": "magic"}, "init"),
        ({"tol": -1.0}, "tol"),
        ({"reg_covar": 0.0}, "reg_covar"),
        ({"seed": -1}, "seed"),
        ({"max_iter": 1.5}, "max_iter"),
    ],
)
def test_bad_input_raises_clear_errors(kwargs, message):
    args = {"points": np.random.default_rng(0).normal(size=(50, 3)), **kwargs}
    with pytest.raises(InvalidInputError, match=message):
        fit_gmm(**args)


def test_random_init_and_float32_input(slice_points):
    g = fit_gmm(slice_points.astype(np.float32), 20, init="random", seed=np.int64(2))
    assert len(g) == 20 and np.isfinite(g.score(slice_points))
