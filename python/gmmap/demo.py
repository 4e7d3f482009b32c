"""``gmmap demo``: fit one GMM to a bundled slice of real TUM fr1_xyz depth frames.

(The multi-robot demo replaces this once the runtime lands; this one shows the core at work.)
"""

from __future__ import annotations

import time

import numpy as np

from gmmap.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.em import fit_gmm
from gmmap.points import voxel_filter


def run_demo(
    components: int = 100, voxel: float = 0.02, covariance: str = "diag", log=print
) -> dict:
    seq = TumRgbd(BUNDLED_TUM_SLICE)
    log(f"loading {len(seq)} depth frames of TUM fr1_xyz (bundled slice)")
    start = time.perf_counter()
    raw = np.concatenate([f.world_points() for f in seq])
    pts = voxel_filter(raw, voxel)
    t_load = time.perf_counter() - start
    log(
        f"{len(raw):,} points, {len(pts):,} after a {voxel} m voxel filter; fitting {components} "
        f"{covariance} components"
    )
    gmm = fit_gmm(pts, components, covariance)
    info = gmm.fit_info
    return {
        "frames": len(seq),
        "raw_points": len(raw),
        "points": len(pts),
        "voxel_size": voxel,
        "components": len(gmm),
        "covariance": covariance,
        "iterations": info.n_iter,
        "converged": info.converged,
        "log_likelihood": gmm.score(pts),
        "gmm_float32_bytes": gmm.float32_bytes,
        "points_float32_bytes": 12 * len(pts),
        "compression": 12 * len(pts) / gmm.float32_bytes,
        "load_time_s": t_load,
        "fit_time_s": info.time_s,
    }
