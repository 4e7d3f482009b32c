"""The demo's report (`gmmap demo --json`) from its robots' reports, evaluated outside the
robots: the groups and pairs as the robot holding the most sees them, against the simulator's
ground truth, and the bytes per submap against points and a float32 GMM."""

from __future__ import annotations

import numpy as np

from gmmap.eval.fleetplots import DESCRIPTOR_BYTES
from gmmap.options import SimOptions


def summarise(reports: dict[str, dict], anchors: dict[str, dict], sim: SimOptions) -> dict:
    """The demo's report from the robots' reports, their anchors' ground truth (``anchors``:
    robot → seq → 4x4) and the simulator's map frames."""
    from gmmap.eval.pairs import match_errors, pair_errors
    from gmmap.io.sim import simulate_options

    truth = {r.name: r.map_to_world for r in simulate_options(sim)}
    # The view of the robot that holds the most (ties: the lowest name): it has every match.
    view = max(sorted(reports), key=lambda n: sum(reports[n]["held"].values()))
    v = reports[view]
    groups = v["groups"]
    truth_anchors, poses, kept = _anchors(reports, anchors, view)
    to_reference = {n: np.array(T) for n, T in v["to_reference"].items()}
    pairs = pair_errors(groups, reports, poses, truth_anchors, kept, to_reference, truth)
    subs = [s for r in reports.values() for s in r["submaps"] if s["points_float32"]]
    wire = float(np.mean([s["wire"] for s in subs]))
    points = float(np.mean([s["points_float32"] for s in subs]))
    gmm = float(np.mean([s["gmm_float32"] for s in subs])) + DESCRIPTOR_BYTES
    return {
        "robots": sim.robots,
        "world": sim.world,
        "groups": groups,
        "view": view,
        "submaps": len(subs),
        "bytes_per_submap": {
            "wire": wire,
            "points_float32": points,
            "gmm_float32_plus_descriptor": gmm,
        },
        "reduction_vs_points": points / wire,
        "reduction_vs_gmm_float32_plus_descriptor": gmm / wire,
        "pairs": pairs,
        "matches": {
            n: {
                "accepted": r["matches_accepted"],
                "rejected": r["matches_rejected"],
                "backend_accepted": r["backend_accepted"],
                "backend_rejected": r["backend_rejected"],
            }
            for n, r in sorted(reports.items())
        },
        "received": {n: r["submaps_received"] for n, r in sorted(reports.items())},
        "secure": all(r.get("secure", False) for r in reports.values()),
        "refused": {n: r.get("refused", {}) for n, r in sorted(reports.items())},
        "bytes_sent": _totals(reports, "sent"),
        "bytes_received": _totals(reports, "received"),
        "resources": {n: r.get("resources") for n, r in sorted(reports.items())},
        # every robot's kept registrations, and the view's as optimised there
        "match_errors": match_errors(_registered(reports), kept, poses, truth_anchors),
    }


def _totals(reports: dict[str, dict], direction: str) -> dict:
    """Payload bytes each robot sent or received (all kinds, fetches included)."""
    return {
        n: r["bytes"]["totals"].get(direction, {}).get("payload_bytes")
        for n, r in sorted(reports.items())
    }


def _anchors(reports: dict[str, dict], anchors: dict[str, dict], view: str):
    """True anchors (every robot's own), ``view``'s optimised poses and its kept match nodes."""
    truth = {
        (name, int(seq)): np.array(T) for name, own in anchors.items() for seq, T in own.items()
    }
    poses = {(k.rsplit("/", 1)[0], int(k.rsplit("/", 1)[1])): np.array(P)
             for k, P in reports[view]["poses"].items()}  # fmt: skip
    kept = [(tuple(e["target"]), tuple(e["source"])) for e in _kept(reports[view])]
    return truth, poses, kept


def _kept(report: dict):
    return (e for e in report.get("edges", []) if e.get("backend") == "accepted")


def _registered(reports: dict[str, dict]) -> list:
    """Every robot's kept registrations (target, source, transform), each node pair once."""
    once = {}
    for r in reports.values():
        for e in _kept(r):
            t, s = tuple(e["target"]), tuple(e["source"])
            once[frozenset({t, s})] = (t, s, np.array(e["transform"]))
    return list(once.values())
