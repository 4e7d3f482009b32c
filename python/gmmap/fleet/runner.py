"""The ``gmmap robot`` process around a `RobotNode`: signals, lingering, the report and the map."""

from __future__ import annotations

import json
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gmmap.config import Config
from gmmap.fleet.robot import BuiltCallback, RobotNode
from gmmap.mapping.frame import Frame
from gmmap.mapping.live import LiveInput

if TYPE_CHECKING:
    from gmmap.mapping.backend import BackendResult
    from gmmap.mapping.mapper import Mapper

try:
    import resource
except ImportError:  # Windows: no getrusage
    resource = None  # type: ignore[assignment]


def run_robot(
    config: Config,
    frames: Sequence[Frame] | LiveInput,
    report_path: Path | None = None,
    on_finish: Callable[[Mapper], dict] | None = None,
    on_built: BuiltCallback | None = None,
    progress: Callable[[str], None] | None = None,
    on_start: Callable[[RobotNode], object] | None = None,
) -> dict:
    """Run a node over ``frames``, linger, report, shut down. SIGINT/SIGTERM stop it cleanly
    (the report is still written, with what was done). ``on_finish`` receives the node's
    mapper at the end, unless interrupted (to save its map, trajectories, …), and returns what
    to add to the report. ``on_start`` receives the node once it started (a ROS bridge that
    publishes its outputs, say)."""
    import signal

    say = progress or (lambda _m: None)
    name = config.robot.name
    node = RobotNode(config, on_built)
    stopped = threading.Event()

    def on_signal(signum, _frame):
        say(f"{name}: signal {signum}, stopping")
        stopped.set()
        node.request_stop()

    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, on_signal)
    try:
        node.start()
        if on_start is not None:
            on_start(node)
        if config.robot.wait_for:
            ok = node.transport.wait_for_peers(config.robot.wait_for, config.robot.wait_timeout)
            peers = ", ".join(node.transport.peers()) or "none"
            say(f"{name}: peers {'present' if ok else 'missing'}: {peers}")
        count = f"{len(frames)} frames" if hasattr(frames, "__len__") else "live frames"
        resumed = f"resuming at {node.frames_consumed}, {node.reloaded} submaps reloaded"
        say(f"{name}: {count}, {resumed}")
        builder = node.start_frames(frames)
        while builder.is_alive() and not stopped.is_set():
            builder.join(0.1)
        complete = node.linger(config.robot.linger, progress=say)
        report = node.report()
        report["interrupted"] = stopped.is_set()
        report["complete"] = complete
        if on_finish is not None and not stopped.is_set():
            report.update(on_finish(node.mapper))
        if report_path is not None:
            report_path.parent.mkdir(parents=True, exist_ok=True)
            report_path.write_text(json.dumps(report, indent=1))
    finally:
        node.stop()
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return report


def node_report(node: RobotNode) -> dict:
    """The node's report: what it built, sent, received and held, its byte counts, its
    matches, groups, frames and poses, and the edges its pose graph holds."""
    mapper = node.mapper
    result = mapper.result
    stats = node.transport.stats()
    edges = node.store.edges()
    held = sorted(mapper.submaps)
    robots = sorted({r for r, _ in held} | {node.robot})
    frames = mapper.frames
    return {
        "robot": node.robot,
        "fleet": node.config.robot.fleet,
        "frames_consumed": node.frames_consumed,
        **{f"submaps_{k}": node.counts[k] for k in ("built", "sent", "received", "fetched")},
        "decode_errors": node.counts["decode_errors"],
        "secure": node.door.secure,
        "refused": node.door.refusals.by_cause(),
        "refused_by_sender": node.door.refusals.snapshot(),
        "reloaded": node.reloaded,
        "held": {r: sum(1 for x, _ in held if x == r) for r in robots},
        "bytes": {
            "by_robot_and_kind": {d: dict(stats.get(d, {})) for d in ("sent", "received")},
            "totals": stats.get("totals", {}),
            "ignored": stats.get("ignored", 0),
        },
        "matches_accepted": sum(e.status == "accepted" for e in edges),
        "matches_rejected": sum(e.status == "rejected" for e in edges),
        "backend_accepted": len(result.accepted) if result else 0,
        "backend_rejected": len(result.rejected) if result else 0,
        "groups": node.groups(),
        "reference": {r: frames.reference(r) for r in frames.robots} if result else {},
        "to_reference": (
            {r: np.asarray(frames.to_reference(r)).tolist() for r in frames.robots}
            if result
            else {}
        ),
        "poses": (
            {f"{r}/{seq}": P.tolist() for (r, seq), P in sorted(result.poses.items())}
            if result
            else {}
        ),
        "submaps": [{"seq": k, **v} for k, v in sorted(node.wire.items())],
        "optimisations": node.counts["optimised"],
        "resources": resources(),
        "edges": _graph_edges(node, result),
    }


def _graph_edges(node: RobotNode, result: BackendResult | None) -> list[dict]:
    """The pose graph's inter-robot edges (the accepted registrations) and the backend's verdict."""
    return [
        {
            "target": [m.candidate.robot, m.candidate.seq],
            "source": list(m.query),
            "transform": np.asarray(m.registration.transform).tolist(),
            "backend": "accepted" if result and i in result.accepted else "rejected",
        }
        for i, m in sorted(node.mapper.edge_matches.items())
    ]


def resources() -> dict | None:
    """This process's CPU time (user + system, all threads) and peak resident memory so far."""
    if resource is None:
        return None
    usage = resource.getrusage(resource.RUSAGE_SELF)
    # ru_maxrss is in kilobytes on Linux and in bytes on macOS.
    scale = 1 / 1024**2 if sys.platform == "darwin" else 1 / 1024
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "max_rss_mb": usage.ru_maxrss * scale}
