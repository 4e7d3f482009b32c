"""A robot node's report (`RobotNode.report`): what it built, sent, received and held, and
what this process used (`resources`)."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from gmmap.fleet.node.robot import RobotNode
    from gmmap.mapping.backend import BackendResult

try:
    import resource
except ImportError:  # Windows: no getrusage
    resource = None  # type: ignore[assignment]


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
