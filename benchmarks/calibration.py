"""The probability that a verified match is right, fitted on some merges and checked on others.

Prints one JSON object. The fit (`gmmap.eval.calibration.fit`) uses the simulated office with
every setup of benchmarks/sensors.py, 3 robots, seeds ``--fit-seeds`` (never those sensors.py
reports), and TUM fr3 cabinet's two halves. The check uses seeds ``--check-seeds``
(sensors.py's) and TUM fr1_xyz's two sessions. Per case: the labelled matches
(`gmmap.eval.calibration.labelled`), the calibration's Brier score beside the base rate's
(always saying the share right) and the matches it never saw the like of. For the checked
cases also the verified and right matches with the defaults (``min_conditioning``, no
probability) beside the same with ``min_probability`` 0.5 added; ``check_pooled``: all checked
matches together, with reliability bins (the mean probability beside the share right).
``--write`` stores the fit as the one gmmap ships (python/gmmap/data/place/calibration.json).
About 10 minutes on 2 cores with the defaults, so `make bench` leaves it out.

    .venv/bin/python benchmarks/calibration.py [--fit-seeds 100,101,102] [--check-seeds 0,1,2]
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np
from sensors import SETUPS, real_sessions, simulated_sessions

from gmmap.config import Config
from gmmap.eval.calibration import check, fit, labelled
from gmmap.mapping.calibration import FEATURES, SHIPPED

FIT_REAL, CHECK_REAL = "tum_fr3_cabinet_halves", "tum_fr1_xyz_second_session_10hz"


def cases(seeds: list[int], real: str, config: Config) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for setup in SETUPS:
        for seed in seeds:
            print(f"{setup}, seed {seed}", file=sys.stderr, flush=True)
            out[f"{setup}_{seed}"] = labelled(simulated_sessions(setup, 3, seed, config)[0], config)
    built = real_sessions(real, config)
    if built is not None:
        print(real, file=sys.stderr, flush=True)
        out[real] = labelled(built[0], config)
    return out


def gated(calibration, X: np.ndarray, y: np.ndarray, config: Config) -> dict:
    """Verified and right, with the defaults and with min_probability 0.5 added."""
    pinned = X[:, FEATURES.index("conditioning")] >= math.log10(config.place.min_conditioning)
    p = np.array([calibration.probability(x) or 0.0 for x in X])
    out = {}
    for name, keep in (("defaults", pinned), ("with_probability_0.5", pinned & (p >= 0.5))):
        out[name] = {"verified": int(keep.sum()), "right": int((keep & y).sum())}
    return out


def summary(report: dict) -> dict:
    """A case's `check` without its reliability bins (too few matches each)."""
    return {k: v for k, v in report.items() if k != "reliability"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fit-seeds", default="100,101,102")
    parser.add_argument("--check-seeds", default="0,1,2")
    parser.add_argument("--write", action="store_true", help=f"store the fit as {SHIPPED}")
    args = parser.parse_args()
    config = Config()
    seeds = [int(s) for s in args.fit_seeds.split(",")]
    fitted = cases(seeds, FIT_REAL, config)
    source = f"benchmarks/calibration.py: {', '.join(SETUPS)} seeds {args.fit_seeds}; {FIT_REAL}"
    calibration = fit(list(fitted.values()), source)
    if args.write:
        calibration.save(SHIPPED)
    checked = cases([int(s) for s in args.check_seeds.split(",")], CHECK_REAL, config)
    pooled = [np.concatenate(part) for part in zip(*checked.values(), strict=True)]
    out = {
        "calibration": calibration.__dict__,
        "fit": {k: summary(check(calibration, *v)) for k, v in fitted.items()},
        "check": {k: {**summary(check(calibration, *v)), **gated(calibration, *v, config)}
                  for k, v in checked.items()},
        "check_pooled": check(calibration, *pooled),
    }  # fmt: skip
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
