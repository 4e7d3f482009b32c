"""What a robot node passes between its stages and to its caller (`gmmap.fleet.node.robot`): an
arrived submap for keeping and matching, and an own submap built and sent."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gmmap.mapping.submap import Submap


@dataclass(frozen=True)
class Arrived:
    """An encoded submap for the matching stage: ``origin`` "own", "received" or "fetched"."""

    origin: str
    robot: str
    seq: int
    payload: bytes


@dataclass(frozen=True)
class Built:
    """An own submap, built and sent: the submap as built (its ground truth, where the frames
    had one, stays with it), its sizes and the node's status after sending it."""

    submap: Submap
    sizes: dict
    status: dict


BuiltCallback = Callable[[Built], None]


def sizes_of(s: Submap, wire: int, n_points: int | None) -> dict:
    """A built submap's bytes: on the wire, as float32 points and as a float32 mixture."""
    points = None if n_points is None else 12 * int(n_points)
    return {"wire": wire, "points_float32": points, "gmm_float32": int(s.gmm.float32_bytes),
            "components": len(s.gmm)}  # fmt: skip
