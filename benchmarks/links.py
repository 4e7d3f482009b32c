"""The demo over emulated links: submaps lost, time and bytes, against perfect links.

Prints one JSON object. Each case runs the whole demo (`gmmap.cli.demo.run_demo`, robots as
separate processes) with one counting relay between every two robots (`gmmap.fleet.links`):
perfect links, per-link caps of 10 kB/s, 2 kB/s and 500 B/s, 30 % loss (a 0.2 s TCP stall
per lost chunk) and two partitions of 30 s. Per case: submaps lost (built but never delivered
to a peer; goal 0), whether every robot ended complete, the wall time, the bytes on the wire
per delivered submap (Zenoh's framing, adverts and fetches included, TCP/IP headers not;
goal <= 1,000 B) and whether the robots end holding the same submaps and groups as on
perfect links. Rendezvous links and kill -9 restarts are not among the cases.

    .venv/bin/python benchmarks/links.py [--robots 3,5] [--cases perfect,10k,...]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

from gmmap.cli.demo import backend_follows_drift, run_demo
from gmmap.config import Config
from gmmap.options import LinkOptions, RobotOptions, SimOptions

CASES = {
    "perfect": LinkOptions(emulate=True),
    "10k": LinkOptions(rate=10_000),
    "2k": LinkOptions(rate=2_000),
    "500": LinkOptions(rate=500),
    "loss_30": LinkOptions(loss=0.3),
    "partitions_2x30s": LinkOptions(outages=((5.0, 35.0), (45.0, 75.0))),
}


def case(robots: int, link: LinkOptions) -> dict:
    base = Config(sim=SimOptions(robots=robots), robot=RobotOptions(linger=2.0, deadline=180.0))
    config = backend_follows_drift(replace(base, link=link))
    with tempfile.TemporaryDirectory() as out:
        r = run_demo(config, None, Path(out), lambda m: None)
        reports = {n: json.loads((Path(out) / f"{n}.json").read_text()) for n in r["received"]}
    return {
        "lost": sum(r["lost"].values()),
        "complete": all(rep["complete"] for rep in reports.values()),
        "wall_s": round(r["wall_s"], 1),
        "wire_bytes_per_delivered_submap": r["wire_bytes_per_delivered_submap"],
        "payload_bytes_per_submap": r["bytes_per_submap"]["wire"],
        "groups": r["groups"],
        "held": {n: rep["held"] for n, rep in reports.items()},
    }


def ended(row: dict) -> tuple:
    """What the robots ended with: the submaps each held and the groups."""
    return row["held"], row["groups"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="3,5")
    parser.add_argument("--cases", default=",".join(CASES))
    args = parser.parse_args()
    out: dict = {}
    for robots in (int(n) for n in args.robots.split(",")):
        rows = {}
        for name in args.cases.split(","):
            print(f"{robots} robots, {name}", file=sys.stderr, flush=True)
            rows[name] = case(robots, CASES[name])
            print(json.dumps(rows[name]), file=sys.stderr, flush=True)
        perfect = rows.get("perfect")
        for row in rows.values():
            row["same_as_perfect"] = perfect is not None and ended(row) == ended(perfect)
        for row in rows.values():
            del row["held"]
        out[f"{robots}_robots"] = rows
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
