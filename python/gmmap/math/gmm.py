"""The Gaussian mixture model type: the unit every gmmap stage produces, sends and consumes."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from gmmap import _core
from gmmap.errors import FileFormatError, InvalidGmmError, InvalidInputError
from gmmap.math.fileio import load_npz, save_npz
from gmmap.math.geometry import matrix_to_quaternion
from gmmap.math.points import as_points

FILE_FORMAT = "gmmap GMM"
FILE_VERSION = 1


@dataclass(frozen=True)
class FitInfo:
    """How an EM fit went."""

    n_iter: int
    converged: bool
    log_likelihood: float  # mean per point, last E-step (truncated evaluation)
    time_s: float


class Gmm:
    """A 3-D Gaussian mixture: weights (K,), means (K, 3), full covariances (K, 3, 3).

    Arrays are float64 and read-only; operations return new mixtures. Construction validates:
    finite values, non-negative weights summing to 1, symmetric positive-definite covariances.
    """

    def __init__(
        self,
        weights: object,
        means: object,
        covariances: object,
        *,
        fit_info: FitInfo | None = None,
    ) -> None:
        self.weights, self.means, self.covariances = _validated(weights, means, covariances)
        self.fit_info = fit_info

    @classmethod
    def from_diagonal(cls, weights: object, means: object, variances: object) -> Gmm:
        """A mixture with axis-aligned covariances given by their (K, 3) variances."""
        var = np.asarray(variances, dtype=np.float64)
        if var.ndim != 2 or var.shape[1] != 3:
            raise InvalidGmmError(f"variances must have shape (K, 3), got {var.shape}")
        covs = np.zeros((var.shape[0], 3, 3))
        covs[:, [0, 1, 2], [0, 1, 2]] = var
        return cls(weights, means, covs)

    def __len__(self) -> int:
        return len(self.weights)

    @property
    def n_components(self) -> int:
        return len(self.weights)

    @property
    def is_diagonal(self) -> bool:
        """True when every covariance is axis-aligned (off-diagonal entries exactly zero)."""
        off = self.covariances[:, [0, 0, 1], [1, 2, 2]]
        return bool(np.all(off == 0.0))

    @property
    def float32_bytes(self) -> int:
        """Size as float32: per component a weight, a mean, and 3 variances when its covariance
        is axis-aligned or 6 covariance entries otherwise."""
        off = self.covariances[:, [0, 0, 1], [1, 2, 2]]
        full = int(np.count_nonzero(np.any(off != 0.0, axis=1)))
        return 4 * (7 * len(self) + 3 * full)

    def __repr__(self) -> str:
        kind = "diagonal" if self.is_diagonal else "full"
        return f"Gmm(n_components={len(self)}, covariance={kind!r})"

    def _eval_points(self, x: object) -> tuple[np.ndarray, bool]:
        arr = np.asarray(x, dtype=np.float64)
        single = arr.shape == (3,)
        return as_points(arr, name="x", allow_empty=True), single

    def log_pdf(self, x: object) -> np.ndarray | float:
        """log p(x) for one point (3,) or many (N, 3), over all components (exact)."""
        pts, single = self._eval_points(x)
        out = _core.log_pdf(self.weights, self.means, self.covariances, pts)
        return float(out[0]) if single else out

    def pdf(self, x: object) -> np.ndarray | float:
        """Density p(x) for one point (3,) or many (N, 3)."""
        return np.exp(self.log_pdf(x))

    def score(self, x: object) -> float:
        """Mean log-likelihood per point of (N, 3) points (as scikit-learn's ``score``)."""
        pts, _ = self._eval_points(x)
        if len(pts) == 0:
            raise InvalidInputError("score needs at least one point")
        return float(np.mean(_core.log_pdf(self.weights, self.means, self.covariances, pts)))

    def gradient(self, x: object) -> np.ndarray:
        """Gradient of the density, ∇p(x), shape (3,) or (N, 3)."""
        pts, single = self._eval_points(x)
        out = _core.gradient(self.weights, self.means, self.covariances, pts)
        return out[0] if single else out

    def sample(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` points drawn from the mixture, (n, 3), deterministic for ``seed``."""
        if int(n) < 0:
            raise InvalidInputError(f"n must be >= 0, got {n}")
        rng = np.random.default_rng(seed)
        comp = rng.choice(len(self), size=int(n), p=self.weights)
        chol = np.linalg.cholesky(self.covariances)
        z = rng.standard_normal((int(n), 3))
        return self.means[comp] + np.einsum("nij,nj->ni", chol[comp], z)

    def transform(self, T: object) -> Gmm:
        """The mixture moved by the rigid transform T (4x4): μ' = Rμ + t, Σ' = R Σ Rᵀ in full."""
        R, t = _rigid(T)
        covs = np.einsum("ij,kjl,ml->kim", R, self.covariances, R)
        covs = 0.5 * (covs + covs.transpose(0, 2, 1))  # exact symmetry despite rounding
        return Gmm(self.weights, self.means @ R.T + t, covs)

    def ellipsoids(self, sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
        """(K, 4) orientations (qx qy qz qw) and (K, 3) half sizes of each component's
        ``sigma`` ellipsoid: the covariance's eigenvectors (made a proper rotation, which a
        quaternion needs and eigh need not return) and sigma·√eigenvalue."""
        values, vectors = np.linalg.eigh(self.covariances)
        vectors[np.linalg.det(vectors) < 0, :, 2] *= -1
        return matrix_to_quaternion(vectors), sigma * np.sqrt(np.clip(values, 0.0, None))

    def coarsened(self, cell: float) -> Gmm:
        """Components whose means share a ``cell``-sized voxel merged into one with the same
        weight, mean and covariance (moment matching): the mixture as seen at that scale."""
        if not cell > 0:
            raise InvalidInputError(f"cell must be > 0, got {cell}")
        return Gmm(*_core.coarsen_gmm(self.weights, self.means, self.covariances, float(cell)))

    def l2_inner(self, other: Gmm) -> float:
        """∫ f g dx with the other mixture, in closed form."""
        return float(
            _core.l2_inner(
                self.weights,
                self.means,
                self.covariances,
                other.weights,
                other.means,
                other.covariances,
            )
        )

    def l2_correlation(self, other: Gmm) -> float:
        """Normalised L2 correlation ∫fg / sqrt(∫f² ∫g²) in [0, 1] (1 only for f = g): how
        well two mixtures agree, independent of their component counts."""
        return self.l2_inner(other) / np.sqrt(self.l2_inner(self) * other.l2_inner(other))

    def arrays(self) -> dict[str, np.ndarray]:
        return {"weights": self.weights, "means": self.means, "covariances": self.covariances}

    def save(self, path: str | os.PathLike) -> None:
        """Writes the mixture to ``path`` (npz); atomic, so a crash never leaves half a file."""
        save_npz(path, FILE_FORMAT, FILE_VERSION, self.arrays())

    @classmethod
    def load(cls, path: str | os.PathLike) -> Gmm:
        """Reads a mixture written by ``save``; raises FileFormatError on anything else."""
        return cls.from_arrays(load_npz(path, FILE_FORMAT, FILE_VERSION), path)

    @classmethod
    def from_arrays(cls, data: dict, source: object = "data") -> Gmm:
        """The mixture in ``data``'s weights/means/covariances; FileFormatError if invalid."""
        try:
            return cls(data["weights"], data["means"], data["covariances"])
        except (KeyError, InvalidGmmError) as exc:
            raise FileFormatError(f"{source}: {exc}") from exc


def _validated(weights: object, means: object, covariances: object):
    try:
        w = np.array(weights, dtype=np.float64)
        mu = np.array(means, dtype=np.float64)
        cov = np.array(covariances, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidGmmError(f"mixture parameters must be numeric arrays: {exc}") from exc
    k = w.shape[0] if w.ndim == 1 else -1
    if k < 1 or mu.shape != (k, 3) or cov.shape != (k, 3, 3):
        raise InvalidGmmError(
            "expected weights (K,), means (K, 3), covariances (K, 3, 3) with K >= 1; got "
            f"{w.shape}, {mu.shape}, {cov.shape}"
        )
    for name, arr in (("weights", w), ("means", mu), ("covariances", cov)):
        if not np.isfinite(arr).all():
            raise InvalidGmmError(f"{name} contain NaN or infinite values")
    if (w < 0).any():
        raise InvalidGmmError(f"weights must be non-negative (component {int(np.argmin(w))})")
    if abs(w.sum() - 1.0) > 1e-6:
        raise InvalidGmmError(f"weights must sum to 1, they sum to {w.sum():.9g}")
    w = w / w.sum()
    scale = np.abs(cov).max(axis=(1, 2), keepdims=True)
    asym = np.abs(cov - cov.transpose(0, 2, 1)) > 1e-9 * scale + 1e-300
    if asym.any():
        bad = int(np.argmax(asym.any(axis=(1, 2))))
        raise InvalidGmmError(f"covariance of component {bad} is not symmetric")
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    eig_min = np.linalg.eigvalsh(cov)[:, 0]
    if (eig_min <= 0).any():
        bad = int(np.argmin(eig_min))
        raise InvalidGmmError(
            f"covariance of component {bad} is not positive-definite "
            f"(smallest eigenvalue {eig_min[bad]:.3g})"
        )
    for arr in (w, mu, cov):
        arr.setflags(write=False)
    return w, mu, cov


def _rigid(T: object) -> tuple[np.ndarray, np.ndarray]:
    """Splits a 4x4 rigid transform into (R, t), rejecting anything that is not one."""
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise InvalidInputError(f"T must be a finite 4x4 matrix, got shape {M.shape}")
    R, t = M[:3, :3], M[:3, 3]
    # Plain max-abs checks: np.allclose costs more than a small registration.
    if np.abs(M[3] - (0.0, 0.0, 0.0, 1.0)).max() > 1e-8:
        raise InvalidInputError("T's last row must be [0, 0, 0, 1]")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-5 or np.linalg.det(R) <= 0:
        raise InvalidInputError("T's rotation block must be orthonormal with determinant +1")
    return R, t
