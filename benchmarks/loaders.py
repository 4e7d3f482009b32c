"""Loader throughput: frames per second of the dataset loaders, with a baseline in the same run.

TUM fr1_xyz (../shared/data/tum_fr1_xyz; the bundled 8-frame slice when absent) with the
default options (stride 1: every pixel back-projected), iterated end to end; the baseline is
decoding the same PNGs alone (PIL), the floor any TUM loader pays. KITTI sequence 00's ten
scans are timed too when present, against numpy reading the same .bin files.
Prints one JSON object.

    .venv/bin/python benchmarks/loaders.py [--frames N] [--repeats R]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from PIL import Image

from gmmap.io.datasets import BUNDLED_TUM_SLICE, KittiOdometry, TumRgbd

SHARED = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)


def best_rate(work: Callable[[], int], repeats: int) -> float:
    """Items per second of the fastest of ``repeats`` runs (the least disturbed one)."""
    best = 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        n = work()
        best = max(best, n / (time.perf_counter() - start))
    return best


def tum(root: Path, frames: int | None, repeats: int) -> dict:
    seq = TumRgbd(root)
    n = min(len(seq), frames or len(seq))
    files = seq.files[:n]
    points = []

    def load() -> int:
        points[:] = [len(seq[i].points) for i in range(n)]
        return n

    def decode() -> int:
        for f in files:
            with Image.open(f) as img:
                np.asarray(img)
        return n

    fps = best_rate(load, repeats)
    base = best_rate(decode, repeats)
    return {
        "data": str(root),
        "frames": n,
        "stride": 1,
        "points_per_frame": round(float(np.mean(points)), 1),
        "frames_per_s": round(fps, 1),
        "baseline_png_decode_frames_per_s": round(base, 1),
        "loader_over_decode_time": round(base / fps, 2),
    }


def kitti(root: Path, repeats: int) -> dict:
    seq = KittiOdometry(root)

    def load() -> int:
        for f in seq:
            f.points.shape  # noqa: B018 - the frame is built; nothing else to do
        return len(seq)

    def raw() -> int:
        for f in seq.files:
            np.fromfile(f, dtype=np.float32).reshape(-1, 4)
        return len(seq)

    fps, base = best_rate(load, repeats), best_rate(raw, repeats)
    return {
        "data": str(root),
        "frames": len(seq),
        "frames_per_s": round(fps, 1),
        "baseline_numpy_fromfile_frames_per_s": round(base, 1),
    }


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, help="TUM frames to time (default: all)")
    ap.add_argument("--repeats", type=int, default=2, help="best of this many passes")
    args = ap.parse_args(argv)
    full = SHARED / "tum_fr1_xyz"
    root = full if (full / "depth.txt").is_file() else BUNDLED_TUM_SLICE
    result = {"cpus": os.cpu_count(), "tum": tum(root, args.frames, args.repeats)}
    seq00 = SHARED / "kitti_odometry_mini" / "sequences" / "00"
    if (seq00 / "velodyne").is_dir():
        result["kitti"] = kitti(seq00, args.repeats)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
