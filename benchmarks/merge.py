"""Merge: issue 7's figures from the offline pipeline (`gmmap.eval.merge.merge`), in one run.

Prints one JSON object. Each case builds submaps per robot with the defaults (by space) and merges
them; against ground truth: every robot pair's relative pose where they met and of their map
frames (`gmmap.eval.pairs`), the kept matches as registered and optimised, the ATE (evo) of all
anchors before and after optimisation, as they are and rigidly aligned, and with injected wrong
matches how many were rejected:

- TUM fr1_xyz split at frame 398 into two robots (when ``../shared/data`` is there), with the
  default odometry noise and with 0.002 (its poses are motion capture);
- the simulated office, 3 LiDAR robots with drifting odometry, clean and with 20 % of the
  verified matches replaced by wrong ones;
- cross-session cases (`gmmap.eval.sessions`, the defaults; joined or not, frame errors,
  verified precision and recall, points + GICP on the same candidates, the data's floor):
  fr1_xyz's first 400 frames against the recording re-sampled at 10 and 5 Hz from frame 201
  (faster motion per frame), and
  fr3 cabinet's loop (keyframes 0-14 against 43-57, which see the same side; 3 keyframes per
  submap, motion-capture odometry noise).

    .venv/bin/python benchmarks/merge.py
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from gmmap.config import Config
from gmmap.eval.merge import merge
from gmmap.eval.sessions import evaluate_sessions
from gmmap.io import datasets
from gmmap.io.sim import UP, get_world, sim_sensor, simulate
from gmmap.mapping.backend import BackendOptions
from gmmap.mapping.submap import BuildOptions, build_submaps
from gmmap.math.drift import Drift
from gmmap.options import SimOptions

DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
BUILD = BuildOptions()  # the defaults: submaps by space
KEYS = ("groups", "candidates", "verified", "accepted_edges", "rejected_edges", "pairs",
        "match_errors", "ate_before_m", "ate_after_m", "ate_aligned_before_m",
        "ate_aligned_after_m", "injected_wrong", "time_s")  # fmt: skip


def run(submaps: dict, config: Config | None = None, wrong_matches: float = 0.0) -> dict:
    _, report = merge(submaps, config, wrong_matches=wrong_matches)
    return {k: report[k] for k in KEYS if k in report}


def main() -> None:
    out: dict = {}
    fr1 = DATA / "tum_fr1_xyz"
    if fr1.exists():
        print("fr1_xyz halves", file=sys.stderr)
        frames = datasets.open(fr1)
        halves = {
            name: list(build_submaps(frames[part], name, BUILD))
            for name, part in (("first", slice(0, 398)), ("second", slice(398, None)))
        }
        for drift in (0.02, 0.002):
            config = Config(backend=BackendOptions.for_drift(drift))
            out[f"tum_fr1_xyz_halves_odometry_drift_{drift}"] = run(halves, config)
    else:
        out["tum_fr1_xyz_halves"] = {"skipped": f"{fr1} not found"}
    print("simulated office, 3 robots", file=sys.stderr)
    odometry = Drift(seed=0, up=UP)
    run_ = simulate(get_world("office"), 3, 0, sim_sensor(SimOptions()), odometry=odometry)
    robots = {r.name: list(build_submaps(r, r.name, BUILD)) for r in run_}
    out["office_3_robots"] = run(robots)
    out["office_3_robots_wrong_0.2"] = run(robots, wrong_matches=0.2)
    out.update(cross_sessions())
    print(json.dumps(out, indent=1))


SESSION_KEYS = ("sessions", "joined", "frame_t_error", "frame_r_error_deg", "positives",
                "candidates", "verified", "precision", "kept_precision", "recall",
                "candidates_registered_right",
                "gicp", "floor")  # fmt: skip


def cross_sessions() -> dict:
    """The cross-session cases of the module docstring (skipped without the shared data)."""
    fr1, cabinet = DATA / "tum_fr1_xyz", DATA / "tum_fr3_cabinet_keyframes"
    if not (fr1.exists() and cabinet.exists()):
        return {"cross_session": {"skipped": f"{DATA} lacks fr1_xyz or fr3 cabinet"}}
    cases = {}
    frames = datasets.open(fr1)
    for step, rate in ((3, 10), (6, 5)):
        resampled = [frames[i] for i in range(201, len(frames), step)]
        cases[f"tum_fr1_xyz_second_session_{rate}hz"] = (frames[0:400], resampled, Config())
    frames = datasets.open(cabinet)
    config = Config(
        build=Config().build.by_frames(3),
        backend=BackendOptions.for_drift(0.002),
    )
    cases["tum_fr3_cabinet_loop"] = (frames[0:15], frames[43:], config)
    out = {}
    for name, (a, b, config) in cases.items():
        print(name, file=sys.stderr)
        sessions = {
            robot: list(build_submaps(part, robot, config.build, config.select))
            for robot, part in (("a", a), ("b", b))
        }
        r = evaluate_sessions(sessions, config)
        out[name] = {k: r[k] for k in SESSION_KEYS}
    return out


if __name__ == "__main__":
    main()
