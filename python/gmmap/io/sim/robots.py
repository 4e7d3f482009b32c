"""Robot motion along a route: rotate in place towards each waypoint, then drive to it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from gmmap.errors import InvalidInputError


@dataclass(frozen=True)
class Motion:
    """How robots move: ``speed`` (m/s), ``turn_rate`` (rad/s), sensor ``rate`` (Hz), a full
    turn in place at the start (``spin``) so each robot first sees its whole room, and a sway
    of the carrier (``sway``: degrees of roll and pitch, as a handheld sensor or a legged robot
    rocks; 0 for a wheeled robot on a flat floor)."""

    speed: float = 0.5
    turn_rate: float = 0.8
    rate: float = 5.0
    spin: bool = True
    sway: float = 0.0


# Sway periods (s): a slow rock and a faster pitch, incommensurate so the two never lock.
SWAY_PERIODS = (2.3, 1.7)


def route_poses(route: list[tuple[float, float]], motion: Motion) -> np.ndarray:
    """(M, 4, 4) body→world poses sampled at ``motion.rate`` along the route (z = 0)."""
    if len(route) < 2:
        raise InvalidInputError("a route needs at least two waypoints")
    keys = _keyframes(np.asarray(route, dtype=np.float64), motion)
    t = np.arange(0.0, keys[-1, 0] + 1e-9, 1.0 / motion.rate)
    x, y, yaw = (np.interp(t, keys[:, 0], keys[:, i]) for i in (1, 2, 3))
    poses = np.tile(np.eye(4), (len(t), 1, 1))
    c, s = np.cos(yaw), np.sin(yaw)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = c, -s, s, c
    poses[:, 0, 3], poses[:, 1, 3] = x, y
    return poses @ _sway(t, math.radians(motion.sway)) if motion.sway else poses


def _sway(t: np.ndarray, amplitude: float) -> np.ndarray:
    """(M, 4, 4) rotations of the body by roll then pitch, each a sine of its own period."""
    roll = amplitude * np.sin(2 * math.pi * t / SWAY_PERIODS[0])
    pitch = amplitude * np.sin(2 * math.pi * t / SWAY_PERIODS[1] + 1.0)
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    out = np.tile(np.eye(4), (len(t), 1, 1))
    # R = Ry(pitch) @ Rx(roll)
    out[:, 0, 0], out[:, 0, 1], out[:, 0, 2] = cp, sp * sr, sp * cr
    out[:, 1, 1], out[:, 1, 2] = cr, -sr
    out[:, 2, 0], out[:, 2, 1], out[:, 2, 2] = -sp, cp * sr, cp * cr
    return out


def _keyframes(route: np.ndarray, motion: Motion) -> np.ndarray:
    """Rows (t, x, y, yaw) where motion changes: turns in place and straight drives."""
    t, (x, y) = 0.0, route[0]
    yaw = _heading(route[0], route[1])
    keys = [(t, x, y, yaw)]
    if motion.spin:
        t += 2 * math.pi / motion.turn_rate
        yaw += 2 * math.pi
        keys.append((t, x, y, yaw))
    for a, b in pairwise(route):
        turn = (_heading(a, b) - yaw + math.pi) % (2 * math.pi) - math.pi
        if abs(turn) > 1e-9:
            t += abs(turn) / motion.turn_rate
            yaw += turn
            keys.append((t, x, y, yaw))
        t += float(np.linalg.norm(b - a)) / motion.speed
        x, y = b
        keys.append((t, x, y, yaw))
    return np.array(keys)


def _heading(a: np.ndarray, b: np.ndarray) -> float:
    return math.atan2(b[1] - a[1], b[0] - a[0])
