"""Submaps and adaptive model selection: figures of the paper's section IV.

Prints one JSON object with
- per dataset (TUM fr1_xyz, TUM fr3 cabinet, KITTI 00, the simulated office): per submap the
  components and float32 bytes before/after selection and the held-out log-likelihood (10 % of
  the points withheld from fitting) before/after, with the defaults (merge, then refine), and
  with the paper's merge alone; and a sweep of the KL threshold with and without refinement
  (the trade-off curve: fewer components and bytes vs likelihood);
- the time to build, fit and select one submap of 40 640x480 depth frames (5 cm voxels) on one
  core, against the 1.33 s the camera takes to deliver them at 30 Hz;
- the paper's Fig. 2 argument: two simulated robots crossing the same room on different paths;
  the normalised L2 correlation of their Point-to-GMM submaps vs their GMM-merge submaps.

    .venv/bin/python benchmarks/selection.py
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
THRESHOLDS = [4.0, 8.0, 16.0, 24.0, 32.0]


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def datasets() -> dict:
    from gmmap.io import datasets as ds
    from gmmap.io.sim import DepthCamera, get_world, simulate

    cam = DepthCamera(width=320, height=240, fx=262.5, fy=262.5, cx=159.5, cy=119.5)
    out = {"sim_office": (simulate(get_world("office"), 1, sensor=cam)[0], 20)}
    sources = {
        "tum_fr1_xyz": ("tum_fr1_xyz", 40, {}),
        "tum_fr3_cabinet": ("tum_fr3_cabinet_keyframes", 10, {}),
        "kitti_00": ("kitti_odometry_mini/sequences/00", 5, {}),
    }
    for name, (folder, f, opts) in sources.items():
        try:
            out[name] = (ds.open(DATA / folder, **opts), f)
        except Exception as exc:  # report what could not be read, go on
            out[name] = (None, f"{type(exc).__name__}: {exc}")
    return out


def selection_figures(frames, frames_per_submap: int) -> dict:
    from gmmap.mapping.submap import BuildOptions, build_submaps, select_and_refine
    from gmmap.math.select import SelectOptions, select_components

    opts = BuildOptions(covariance="diag", select=False, holdout=0.1).by_frames(frames_per_submap)
    submaps = list(build_submaps(frames, "bench", opts))[:6]
    rows, sweep = [], {(t, r): [] for t in THRESHOLDS for r in (False, True)}
    for s in submaps:
        mask = np.random.default_rng([opts.seed, s.seq]).random(len(s.points)) < 0.1
        held, train = s.points[mask], s.points[~mask]
        before = s.gmm.score(held)
        for t, refined in sweep:
            o = BuildOptions(covariance="diag", refine_iter=10 * refined)
            g = select_and_refine(s.gmm, train, o, SelectOptions(kl_threshold=t))
            sweep[t, refined].append(
                (
                    1 - len(g) / len(s.gmm),
                    1 - g.float32_bytes / s.gmm.float32_bytes,
                    g.score(held) - before,
                )
            )
        paper = select_components(s.gmm)
        g = select_and_refine(s.gmm, train, BuildOptions(covariance="diag"))
        rows.append(
            {
                "seq": s.seq,
                "points": s.n_points,
                "components_before": len(s.gmm),
                "components_after": len(g),
                "bytes_before": s.gmm.float32_bytes,
                "bytes_after": g.float32_bytes,
                "heldout_ll_before": before,
                "heldout_ll_after": g.score(held),
                "merge_only_components": len(paper),
                "merge_only_heldout_ll": paper.score(held),
            }
        )
    mean = lambda key: float(np.mean([r[key] for r in rows]))  # noqa: E731
    dll = mean("heldout_ll_after") - mean("heldout_ll_before")
    return {
        "submaps": rows,
        "fewer_components": 1 - mean("components_after") / mean("components_before"),
        "fewer_bytes": 1 - mean("bytes_after") / mean("bytes_before"),
        "heldout_ll_change": dll,
        "likelihood_loss": 1 - math.exp(dll),
        "merge_only_fewer_components": 1
        - mean("merge_only_components") / mean("components_before"),
        "merge_only_heldout_ll_change": mean("merge_only_heldout_ll") - mean("heldout_ll_before"),
        "sweep": [
            {
                "kl_threshold": t,
                "refine": r,
                **dict(
                    zip(
                        ("fewer_components", "fewer_bytes", "heldout_ll_change"),
                        np.mean(v, axis=0).tolist(),
                        strict=True,
                    )
                ),
            }
            for (t, r), v in sweep.items()
        ],
    }


TIMING_CHILD = """
import json, sys, time
import numpy as np
from gmmap.io.datasets import open as open_data
from gmmap.mapping.submap import BuildOptions, SubmapBuilder
frames = open_data(sys.argv[1], stride=int(sys.argv[2]))[:40]
times = []
for rep in range(3):
    b = SubmapBuilder(
        options=BuildOptions(covariance="diag", min_novelty=0.0).by_frames(40)
    )
    start = time.perf_counter()
    for f in frames:
        s = b.add(f)
    times.append(time.perf_counter() - start)
print(json.dumps({"best_s": min(times), "mean_s": sum(times) / len(times),
                  "points_per_frame": float(np.mean([len(f.points) for f in frames])),
                  "submap_points": s.n_points, "components": len(s.gmm)}))
"""


def timing() -> dict:
    from gmmap.io.datasets import BUNDLED_TUM_SLICE

    root = DATA / "tum_fr1_xyz"
    root = root if root.is_dir() else BUNDLED_TUM_SLICE
    env = dict(os.environ, RAYON_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    out = {"data": str(root), "frames": 40, "camera_time_s": 40 / 30}
    for stride in (1, 2):
        r = subprocess.run(
            [sys.executable, "-c", TIMING_CHILD, str(root), str(stride)],
            env=env,
            check=True,
            capture_output=True,
            text=True,
        )
        out[f"stride_{stride}"] = json.loads(r.stdout)
    return out


def fig2() -> dict:
    """Two robots cross room D of the office on different paths; one submap each."""
    from gmmap.io.sim import DepthCamera, Motion, World, get_world, simulate
    from gmmap.mapping.submap import BuildOptions, build_submaps

    office = get_world("office")
    routes = [[(2.0, 7.0), (6.5, 7.0), (8.5, 8.8)], [(8.5, 9.2), (4.0, 9.3), (1.2, 8.0)]]
    world = World("office-room-d", office.shapes, routes)
    cam = DepthCamera(width=320, height=240, fx=262.5, fy=262.5, cx=159.5, cy=119.5)
    run = simulate(world, 2, sensor=cam, motion=Motion(rate=3.0))
    out = {"frames": [len(r) for r in run]}
    for strategy in ("points", "gmm-merge"):
        gmms = []
        for robot in run:
            opts = BuildOptions(
                strategy=strategy, covariance="diag", min_novelty=0.0, select=False
            ).by_frames(len(robot))
            (s,) = build_submaps([robot[i] for i in range(len(robot))], robot.name, opts)
            gmms.append(s.gmm.transform(s.gt_anchor))
        out[strategy] = {
            "l2_correlation": gmms[0].l2_correlation(gmms[1]),
            "components": [len(g) for g in gmms],
        }
    return out


def main() -> None:
    start = time.perf_counter()
    result: dict = {"datasets": {}}
    for name, (frames, f) in datasets().items():
        if frames is None:
            result["datasets"][name] = {"skipped": f}
            continue
        log(f"selection on {name} ({len(frames)} frames, F={f})")
        result["datasets"][name] = {"frames_per_submap": f, **selection_figures(frames, f)}
    log("one-core submap timing")
    result["timing_one_core"] = timing()
    log("Fig. 2: two robots, one room")
    result["fig2"] = fig2()
    result["elapsed_s"] = time.perf_counter() - start
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
