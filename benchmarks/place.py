"""Place recognition: the paper's Fig. 7/8 figures against the point-cloud baselines, in one run.

Prints one JSON object. For each place set (``gmmap.eval.place``) and each descriptor, the
training-free ``shape`` descriptor and the ``learned`` PointNetVLAD (`gmmap.mapping.learned`):
recall@1 and recall@top-1 % on resampled GMMs against the same descriptor on the raw submap
points (the paper's Fig. 7 compares these two for PointNetVLAD: 87.4 % against 88.3 %), recall
at 100 % precision after verification by GMM registration (and, for the shape descriptor,
points + small_gicp's GICP), the time to describe one submap, and the query time against
databases of 1,000 and 10,000 submaps. The place sets, none used in training
(`gmmap.eval.placedata.RECIPE`):

- the held-out simulated worlds (procedural offices and the demo office, LiDAR and depth),
  pooled into one database, robots of different worlds never positives: recall@top-1 % then
  means the top 1 % of a few hundred submaps, as in the paper, not the top one;
- TUM fr1_xyz split into two robots (first and second half), when ``../shared/data`` is there;
- the demo office with 3 and 5 LiDAR robots, seeds ``--seeds``.

    .venv/bin/python benchmarks/place.py [--seeds 0,1,2] [--descriptors shape,learned]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from gmmap.eval.place import PlaceSet, evaluate_place, sim_place_set, split_place_set
from gmmap.eval.placedata import RECIPE, build
from gmmap.io import datasets
from gmmap.mapping.learned import LearnedDescriptor
from gmmap.options import PlaceOptions

DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
say = lambda s: print(s, file=sys.stderr, flush=True)  # noqa: E731


def summary(result: dict) -> dict:
    v = result["verified"]
    verified = {"gmm": v["gmm_recall_at_full_precision"]}
    if "points_gicp_recall_at_full_precision" in v:
        verified["points_gicp"] = v["points_gicp_recall_at_full_precision"]
    return {
        "queries": result["queries"],
        "submaps": result["submaps"],
        "recall_at_1": {k: result[k]["recall_at_n"][0] for k in ("gmm", "points")},
        "recall_at_1pct": {k: result[k]["recall_at_1pct"] for k in ("gmm", "points")},
        # Recall@N for N = 1 … 25: the curves of docs/benchmarks.md.
        "recall_at_n": {k: result[k]["recall_at_n"][:25] for k in ("gmm", "points")},
        "verified_at_full_precision": verified,
        "query_time_s": result["query_time_s"],
        "describe_time_s": result["describe_time_s"],
    }


def pooled(sets: dict[str, PlaceSet]) -> PlaceSet:
    """One place set of several worlds' submaps, robots renamed per world."""
    submaps, blocks = [], []
    for name, s in sets.items():
        submaps += [replace(m, robot=f"{name}/{m.robot}") for m in s.submaps]
        blocks.append(s.positives)
    n = sum(len(b) for b in blocks)
    positives, at = np.zeros((n, n), bool), 0
    for b in blocks:
        positives[at : at + len(b), at : at + len(b)] = b
        at += len(b)
    return PlaceSet(submaps, positives)


def both(place_set: PlaceSet, descriptors: list[str]) -> dict:
    out = {}
    for d in descriptors:
        say(f"  {d} descriptor")
        r = evaluate_place(place_set, PlaceOptions(descriptor=d), gicp=d == "shape", progress=say)
        out[d] = summary(r)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0", help="Simulator seeds, comma-separated.")
    parser.add_argument("--descriptors", default="shape,learned")
    args = parser.parse_args()
    descriptors = args.descriptors.split(",")
    out: dict = {}
    held = {p.name: p for p in RECIPE["held_out"] if not p.recording}
    sets = {}
    for name, p in held.items():
        say(f"held out: {name}")
        sets[name] = build(p, DATA)
    say("held-out worlds, pooled")
    out["held_out_sim_pooled"] = {"parts": sorted(held), **both(pooled(sets), descriptors)}
    fr1 = DATA / "tum_fr1_xyz"
    if fr1.exists():
        say("fr1_xyz halves")
        out["tum_fr1_xyz_halves"] = both(split_place_set(datasets.open(fr1)), descriptors)
    else:
        out["tum_fr1_xyz_halves"] = {"skipped": f"{fr1} not found"}
    for seed in (int(s) for s in args.seeds.split(",")):
        for robots in (3, 5):
            say(f"office, {robots} robots, seed {seed}")
            place_set = sim_place_set(robots=robots, seed=seed)
            out[f"office_{robots}_robots_seed_{seed}"] = both(place_set, descriptors)
    if "learned" in descriptors:
        meta = LearnedDescriptor().model[2]
        keys = ("steps", "seconds", "final_loss", "submaps", "max_distance")
        out["learned_training"] = {k: meta[k] for k in keys}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
