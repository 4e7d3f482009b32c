"""The messages of exploring robots run as processes (`gmmap explore --processes`).

Between robots, beside each submap (kind ``submap``, `gmmap.fleet.wire.codec`):

- ``horizons`` (the submap's seq): its free-space horizons (`gmmap.mapping.frontier`);
- ``claim`` (a running count): the robot's position and goal in its map frame, 16 bytes of
  float32 (x, y, goal x, goal y; NaN: no goal).

Between the simulator and each robot, in place of the robot's wheels and the world its
sensor sees (not fleet traffic; JSON, small): ``tick`` (simulator → robots: the time, each
robot's true pose and how many data messages each had sent by its last step) and ``step``
(robot → simulator: its direction of travel, status, and its sent messages and bytes so
far). A step that does not decode is a `DecodeError`: the simulator stops the run.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import asdict, dataclass

import numpy as np

from gmmap.errors import DecodeError
from gmmap.mapping.explore import Claim

DATA = ("submap", "horizons", "claim")  # what robots send each other
_CLAIM = struct.Struct("<4f")


def encode_claim(claim: Claim) -> bytes:
    goal = (math.nan, math.nan) if claim.goal is None else claim.goal
    return _CLAIM.pack(*claim.position, *goal)


def decode_claim(data: bytes) -> Claim:
    """A claim; `DecodeError` unless 16 bytes with a finite position."""
    if len(data) != _CLAIM.size:
        raise DecodeError(f"a claim is {_CLAIM.size} bytes, got {len(data)}")
    x, y, gx, gy = _CLAIM.unpack(data)
    if not (math.isfinite(x) and math.isfinite(y)):
        raise DecodeError("a claim's position is not finite")
    goal = np.array([gx, gy]) if math.isfinite(gx) and math.isfinite(gy) else None
    return Claim(np.array([x, y]), goal)


@dataclass
class Tick:
    """One simulator step: every robot senses at ``poses`` (x, y, yaw in the world) at time
    ``t``; ``decide``: whether robots choose a direction (not while they turn on the spot at
    the start); ``end``: the run ends (robots send the submap of their last frames);
    ``sent``: each robot's data messages sent by its previous step (a robot takes in that
    many of each peer's first)."""

    t: float
    poses: dict[str, list[float]]
    sent: dict[str, int]
    decide: bool = True
    end: bool = False


@dataclass
class Step:
    """A robot's answer to a tick: ``direction`` (x, y) in its map frame or None (it stays)."""

    direction: list[float] | None
    status: str
    sent: int
    bytes: int


def encode_json(message: Tick | Step) -> bytes:
    return json.dumps(asdict(message)).encode()


def decode_tick(data: bytes) -> Tick:
    return _decode(Tick, data)


def decode_step(data: bytes) -> Step:
    return _decode(Step, data)


def _decode(cls, data: bytes):
    try:
        return cls(**json.loads(data))
    except (ValueError, TypeError) as exc:
        raise DecodeError(f"not a {cls.__name__.lower()} message: {exc}") from exc
