"""Place recognition: the paper's Fig. 7/8 figures against the point-cloud baselines, in one run.

Prints one JSON object. For each place set (``gmmap.eval.place``): the shape descriptor on
resampled GMMs against the same descriptor on the raw submap points (recall@1 and recall@top-1 %),
recall at 100 % precision after verification by GMM registration against points + small_gicp's
GICP, and the query time against databases of 1,000 and 10,000 submaps:

- TUM fr1_xyz split into two robots (first and second half), when ``../shared/data`` is there;
- the simulated office with 3 and 5 LiDAR robots and drifting odometry, seeds ``--seeds``.

    .venv/bin/python benchmarks/place.py [--seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from gmmap.eval.place import evaluate_place, sim_place_set, split_place_set
from gmmap.io import datasets

DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)


def summary(result: dict) -> dict:
    v = result["verified"]
    return {
        "queries": result["queries"],
        "recall_at_1": {k: result[k]["recall_at_n"][0] for k in ("gmm", "points")},
        "recall_at_1pct": {k: result[k]["recall_at_1pct"] for k in ("gmm", "points")},
        "verified_at_full_precision": {
            "gmm": v["gmm_recall_at_full_precision"],
            "points_gicp": v["points_gicp_recall_at_full_precision"],
        },
        "query_time_s": result["query_time_s"],
        "describe_time_s": result["describe_time_s"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0", help="Simulator seeds, comma-separated.")
    args = parser.parse_args()
    out: dict = {}
    fr1 = DATA / "tum_fr1_xyz"
    if fr1.exists():
        print("fr1_xyz halves", file=sys.stderr)
        out["tum_fr1_xyz_halves"] = summary(evaluate_place(split_place_set(datasets.open(fr1))))
    else:
        out["tum_fr1_xyz_halves"] = {"skipped": f"{fr1} not found"}
    for seed in (int(s) for s in args.seeds.split(",")):
        for robots in (3, 5):
            print(f"office, {robots} robots, seed {seed}", file=sys.stderr)
            place_set = sim_place_set(robots=robots, seed=seed)
            out[f"office_{robots}_robots_seed_{seed}"] = summary(evaluate_place(place_set))
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
