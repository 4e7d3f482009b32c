"""``gmmap demo``: simulated robots in the office world, each a separate ``gmmap robot`` process.

The robots talk over Zenoh on loopback only (each listens on its own free port and connects to
the others' endpoints; multicast scouting off) and share nothing but encoded submaps. When they
are done, the demo reads their reports and compares each robot's recovered frame (its
``to_reference``) with the simulator's ground truth, which the robots never see: the true
transform from robot r's map frame into its reference's is inv(M_ref) @ M_r, M being each
robot's map→world. The errors are reported as they come out: place recognition in the office
is weak (corridors alias), so wrong or missing merges are possible and are shown as such.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from gmmap.eval.pairs import describe_pair, match_errors, pair_errors
from gmmap.eval.registration import describe_match_errors
from gmmap.fleet.transport import free_port

DESCRIPTOR_BYTES = 1024  # the paper's Fig. 9: a float32 GMM plus a 256-float descriptor


def run_demo(
    robots: int = 3,
    world: str = "office",
    seed: int = 0,
    frames_per_submap: int = 20,
    max_frames: int | None = None,
    sensor: str = "lidar",
    sim_width: int = 320,
    drift: float = 0.02,
    linger: float = 5.0,
    out: Path | None = None,
    log=print,
    min_matches: int = 1,
) -> dict:
    start = time.perf_counter()
    if out is None:
        out = Path(tempfile.mkdtemp(prefix="gmmap-demo-"))
    out.mkdir(parents=True, exist_ok=True)
    names = [f"robot_{i}" for i in range(robots)]
    for name in names:  # a demo starts afresh: robots would resume from an earlier run's stores
        for stale in out.glob(f"{name}.sqlite*"):
            stale.unlink()
    ports = [free_port() for _ in names]
    fleet = f"demo{os.getpid()}"
    procs = []
    log(f"starting {robots} robot processes in {world} (fleet {fleet}, output {out})")
    for i, name in enumerate(names):
        cmd = [
            sys.executable, "-c", "from gmmap.cli import main; main()", "robot",
            "--id", name, "--fleet", fleet, "--sim", world, "--sim-index", str(i),
            "--robots", str(robots), "--seed", str(seed), "--sensor", sensor,
            "--sim-width", str(sim_width), "--sim-drift", str(drift),
            # the pose graph's odometry noise follows the simulated drift (with a floor)
            "--odometry-drift", str(max(drift, 0.001)), "--min-matches", str(min_matches),
            "--port", str(ports[i]), "--store", str(out / f"{name}.sqlite"),
            "--frames-per-submap", str(frames_per_submap), "--linger", str(linger),
            "--report", str(out / f"{name}.json"), "--json",
        ]  # fmt: skip
        for j, other in enumerate(names):
            if j != i:
                cmd += ["--peer", f"tcp/127.0.0.1:{ports[j]}", "--wait-for", other]
        if max_frames:
            cmd += ["--max-frames", str(max_frames)]
        if i == 0:  # the lowest name: the reference of whatever group it is in
            cmd += ["--map-png", str(out / "map.png")]
        procs.append(
            subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        )
    readers = [threading.Thread(target=_relay, args=(p, log), daemon=True) for p in procs]
    for t in readers:
        t.start()
    codes = [p.wait() for p in procs]
    for t in readers:
        t.join(timeout=5)
    if any(codes):
        raise RuntimeError(f"robot processes exited with {codes}; see the log above")
    reports = {n: json.loads((out / f"{n}.json").read_text()) for n in names}
    report = summarise(reports, world, robots, seed)
    report["out"] = str(out)
    report["map_png"] = reports[names[0]].get("map_png")
    report["map_rrd"] = reports[names[0]].get("map_rrd")
    report["wall_s"] = time.perf_counter() - start
    (out / "demo.json").write_text(json.dumps(report, indent=1))
    return report


def _relay(proc: subprocess.Popen, log) -> None:
    """Child's status lines and messages → our progress log, as they come."""

    def pump(stream, fmt):
        for line in stream:
            line = line.rstrip()
            if line:
                log(fmt(line))

    def status(line: str) -> str:
        try:
            s = json.loads(line)
        except ValueError:
            return line
        return (
            f"  {s['robot']}: submap {s['seq']} sent ({s['bytes']} B); {s['received']} received, "
            f"{s['matches']} matches, groups {s['groups']}"
        )

    err = threading.Thread(target=pump, args=(proc.stderr, lambda x: f"  {x}"), daemon=True)
    err.start()
    pump(proc.stdout, status)
    err.join(timeout=5)


def summarise(reports: dict[str, dict], world: str, robots: int, seed: int) -> dict:
    """The demo's report from the robots' reports and the simulator's ground truth."""
    from gmmap.io.sim import get_world, simulate

    truth = {r.name: r.map_to_world for r in simulate(get_world(world), robots, seed)}
    # The view of the robot that holds the most (ties: the lowest name): it has every match.
    view = max(sorted(reports), key=lambda n: sum(reports[n]["held"].values()))
    v = reports[view]
    groups = v["groups"]
    truth_anchors, poses, kept = _anchors(reports, view)
    to_reference = {n: np.array(T) for n, T in v["to_reference"].items()}
    pairs = pair_errors(groups, reports, poses, truth_anchors, kept, to_reference, truth)
    subs = [s for r in reports.values() for s in r["submaps"] if s["points_float32"]]
    wire = float(np.mean([s["wire"] for s in subs]))
    points = float(np.mean([s["points_float32"] for s in subs]))
    gmm = float(np.mean([s["gmm_float32"] for s in subs])) + DESCRIPTOR_BYTES
    return {
        "robots": robots,
        "world": world,
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


def _anchors(reports: dict[str, dict], view: str):
    """True anchors (every robot's own), ``view``'s optimised poses and its kept match nodes."""
    truth = {
        (name, int(seq)): np.array(T)
        for name, r in reports.items()
        for seq, T in r.get("ground_truth", {}).items()
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


def format_report(r: dict) -> str:
    b = r["bytes_per_submap"]
    lines = [
        f"robots          {r['robots']} in {r['world']}, {r['submaps']} submaps",
        f"groups          {r['groups']} (view of {r['view']})",
        f"bytes/submap    wire {b['wire']:.0f} B vs points (float32) {b['points_float32']:.0f} B"
        f" vs GMM float32 + descriptor {b['gmm_float32_plus_descriptor']:.0f} B",
        f"reduction       {r['reduction_vs_points']:.0f}x vs points, "
        f"{r['reduction_vs_gmm_float32_plus_descriptor']:.1f}x vs GMM + descriptor",
    ]
    for p in r["pairs"]:
        lines.append(f"pair            {describe_pair(p)}")
    for n, m in r["matches"].items():
        lines.append(
            f"matches         {n}: {m['accepted']} of {m['accepted'] + m['rejected']} over "
            f"C_thr, {m['backend_accepted']} kept by PCM/GNC; {r['received'][n]} submaps received"
        )
    for i, line in enumerate(describe_match_errors(r.get("match_errors", {}))):
        lines.append(f"{'where they met' if i == 0 else '':<16}{line}")
    lines.append(f"map             {r.get('map_png')}")
    if r.get("map_rrd"):
        lines.append(f"rerun           {r['map_rrd']} (open with: rerun {r['map_rrd']})")
    lines.append(f"output          {r['out']}")
    lines.append(f"wall time       {r['wall_s']:.1f} s")
    return "\n".join(lines)
