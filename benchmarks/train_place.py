"""Trains the learned place descriptor and writes the weights gmmap ships.

Builds (or reads from ``--cache``) the training parts of `gmmap.eval.placedata.RECIPE`:
procedural offices with LiDAR and depth, and the TUM recordings in ``../shared/data`` where
they are; trains `gmmap.mapping.learned`'s PointNetVLAD with `gmmap.eval.train_place` for
``--minutes`` (or ``--steps``); sets the candidate distance (``max_distance``) from the
training queries' nearest positives; writes the weights with their provenance (recipe, seeds,
options, steps, final loss) to ``--out`` and the per-step log beside them. Prints one JSON
object. Needs the dev extra (JAX).

    .venv/bin/python benchmarks/train_place.py [--minutes 45] [--cache DIR] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np

from gmmap.eval.placedata import RECIPE, load_all
from gmmap.eval.train_place import TrainOptions, train
from gmmap.mapping.learned import WEIGHTS, LearnedDescriptor, reference_cloud, save

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("GMMAP_SHARED_DATA", ROOT.parent / "shared" / "data"))
KEEP_QUANTILE = 0.95  # of the training queries' nearest-positive distances


def max_distance(parts, weights: Path) -> float:
    """The distance under which KEEP_QUANTILE of training queries' nearest positive lies."""
    d = LearnedDescriptor(str(weights))
    nearest = []
    for c in parts:
        v = np.array([d.describe_points(p) for p in c.gmm])
        for i in np.flatnonzero(c.positives.any(axis=1)):
            nearest.append(float((1.0 - v[c.positives[i]] @ v[i]).min()))
    return float(np.quantile(nearest, KEEP_QUANTILE))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=45.0)
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="Data builders.")
    parser.add_argument("--cache", type=Path, default=ROOT / "target" / "place-clouds")
    parser.add_argument("--out", type=Path, default=WEIGHTS)
    args = parser.parse_args()
    say = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731
    parts = load_all("train", args.cache, DATA, say, args.jobs)
    options = TrainOptions(seed=args.seed)
    params, log = train(parts, options, args.steps, args.minutes, say)
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    meta = {
        "trained_by": "benchmarks/train_place.py",
        "commit": commit.stdout.strip(),
        "recipe": {k: [p.name for p in v] for k, v in RECIPE.items()},
        "parts_used": [c.name for c in parts],
        "submaps": int(sum(len(c.gmm) for c in parts)),
        "options": {**asdict(options), "arch": asdict(options.arch)},
        "steps": len(log),
        "seconds": log[-1]["seconds"],
        "final_loss": float(np.mean([e["loss"] for e in log[-100:]])),
        "max_distance": 1.0,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    save(args.out, params, options.arch, meta)
    say("setting max_distance from the training queries")
    meta["max_distance"] = max_distance(parts, args.out)
    out = LearnedDescriptor(str(args.out)).describe_points(reference_cloud(0))
    meta["reference"] = {"seed": 0, "output": [round(float(x), 6) for x in out[:16]]}
    save(args.out, params, options.arch, meta)
    args.out.with_name("train_log.json").write_text(json.dumps(log) + "\n")
    print(json.dumps({k: v for k, v in meta.items() if k != "recipe"}))


if __name__ == "__main__":
    main()
