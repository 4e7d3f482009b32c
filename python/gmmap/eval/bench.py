"""Benchmarks shared by ``gmmap bench`` and the scripts in ``benchmarks/``.

Every comparison times gmmap and its named baseline in the same process and reports a ratio:
absolute times on shared machines are noise, ratios are the figure.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.math.em import fit_gmm
from gmmap.math.points import voxel_filter

SHARED_FR1_XYZ = Path(__file__).resolve().parents[4] / "shared" / "data" / "tum_fr1_xyz"


def default_scene() -> Path:
    """The full fr1_xyz recording when ../shared/data is beside the checkout, else the slice."""
    env = os.environ.get("GMMAP_SHARED_DATA")
    full = Path(env) / "tum_fr1_xyz" if env else SHARED_FR1_XYZ
    return full if (full / "depth.txt").is_file() else BUNDLED_TUM_SLICE


def scene_points(
    n: int, root: Path | None = None, voxel: float | None = 0.01, frames: int = 40, seed: int = 0
) -> np.ndarray:
    """``n`` points of a real indoor scene: TUM depth frames in the world frame, voxelised.

    Uses ``frames`` frames spread over the recording; when voxelising leaves fewer than ``n``
    points (or ``voxel`` is None) raw points are used. Subsampled to ``n`` with a fixed seed.
    """
    seq = TumRgbd(root or default_scene(), stride=2)
    picks = np.linspace(0, len(seq) - 1, min(frames, len(seq))).round().astype(int)
    raw = np.concatenate([seq[int(i)].world_points() for i in np.unique(picks)])
    pts = voxel_filter(raw, voxel) if voxel else raw
    if len(pts) < n:
        pts = raw
    rng = np.random.default_rng(seed)
    return pts[rng.choice(len(pts), size=min(n, len(pts)), replace=False)]


def _best_time(fn, repeats: int):
    best, result = float("inf"), None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return best, result


def em_comparison(
    points: np.ndarray,
    k: int = 100,
    iterations: int = 30,
    covariance: str = "diag",
    repeats: int = 3,
    seed: int = 0,
) -> dict:
    """gmmap's EM against scikit-learn's GaussianMixture: same K, covariance type, k-means++
    initialisation and a fixed iteration count (tol = 0). Best time of ``repeats``; both final
    models scored exactly on the same points."""
    ours_t, ours = _best_time(
        lambda: fit_gmm(points, k, covariance, max_iter=iterations, tol=0.0, seed=seed), repeats
    )
    result = {
        "points": len(points),
        "components": k,
        "covariance": covariance,
        "iterations": iterations,
        "cpus": os.cpu_count(),
        "gmmap": {
            "time_s": ours_t,
            "log_likelihood": ours.score(points),
            "n_components": len(ours),
        },
    }
    try:
        import warnings

        from sklearn.exceptions import ConvergenceWarning
        from sklearn.mixture import GaussianMixture
    except ImportError:
        result["sklearn"] = None
        return result

    def sklearn_fit():
        gm = GaussianMixture(
            k,
            covariance_type=covariance,
            max_iter=iterations,
            tol=0.0,
            init_params="k-means++",
            random_state=seed,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            return gm.fit(points)

    base_t, base = _best_time(sklearn_fit, repeats)
    result["sklearn"] = {"time_s": base_t, "log_likelihood": float(base.score(points))}
    result["speedup"] = base_t / ours_t
    result["log_likelihood_diff"] = (
        result["gmmap"]["log_likelihood"] - result["sklearn"]["log_likelihood"]
    )
    return result


_CHILD = """
import json, sys, time
import numpy as np
import gmmap
pts = np.load(sys.argv[1]); k = int(sys.argv[2]); cov = sys.argv[3]; iters = int(sys.argv[4])
def status_kb(field):  # VmHWM is the peak of this process image (ru_maxrss survives exec)
    with open('/proc/self/status') as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field))
before = status_kb('VmRSS:')
t = time.perf_counter()
g = gmmap.fit_gmm(pts, k, cov, max_iter=iters, tol=0.0)
t = time.perf_counter() - t
print(json.dumps({"time_s": t, "peak_extra_mb": max(0, status_kb('VmHWM:') - before) / 1024}))
"""


def em_scaling(
    ns: list[int],
    ks: list[int],
    points: np.ndarray,
    iterations: int = 10,
    covariance: str = "diag",
    progress=None,
) -> list[dict]:
    """Time and peak extra memory of one fit per (N, K), each in a fresh process."""
    import tempfile

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            path = Path(tmp) / f"pts{n}.npy"
            np.save(path, points[:n])
            for k in ks:
                if progress:
                    progress(f"scaling: N={n} K={k}")
                out = subprocess.run(
                    [sys.executable, "-c", _CHILD, str(path), str(k), covariance, str(iterations)],
                    check=True,
                    capture_output=True,
                    text=True,
                )
                rows.append(
                    {
                        "points": min(n, len(points)),
                        "components": k,
                        "iterations": iterations,
                        **json.loads(out.stdout),
                    }
                )
    return rows
