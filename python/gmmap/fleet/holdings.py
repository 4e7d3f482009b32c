"""What each robot holds, told to its peers, so that a robot ends only once the peers in reach
hold what it holds and it holds what they hold (`gmmap.fleet.robot.RobotNode.linger`).

An advert is the message ``gmmap/<fleet>/<robot>/have/<n>``; its payload is compact JSON,
``{"robot_0": 9, "robot_1": 7}``: how many submaps of each robot the sender holds. Counts, not
sets: a robot's submaps are numbered from 0 and a peer that holds as many holds the same ones
unless a gap is still being filled, which the next advert shows. A malformed or oversized
advert is ignored, never trusted.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterable, Mapping

from gmmap.options import NAME_RE

KIND = "have"
MAX_BYTES = 65_536
MAX_ROBOTS = 1_024


def encode(counts: Mapping[str, int]) -> bytes:
    return json.dumps(dict(sorted(counts.items())), separators=(",", ":")).encode()


def decode(payload: bytes) -> dict[str, int] | None:
    """The counts of an advert, or None when it is not one."""
    if len(payload) > MAX_BYTES:
        return None
    try:
        counts = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None
    if not isinstance(counts, dict) or len(counts) > MAX_ROBOTS:
        return None
    for name, n in counts.items():
        if not NAME_RE.fullmatch(name) or type(n) is not int or n < 0:
            return None
    return counts


class Holdings:
    """The latest advert of every peer (thread-safe: Zenoh's thread writes, the node reads)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._peers: dict[str, dict[str, int]] = {}

    def update(self, peer: str, payload: bytes) -> bool:
        counts = decode(payload)
        if counts is not None:
            with self._lock:
                self._peers[peer] = counts
        return counts is not None

    def lacking(self, mine: Mapping[str, int], peers: Iterable[str]) -> dict[str, dict[str, int]]:
        """Per peer in reach that does not hold what we hold, or holds more: ``they_lack`` and
        ``we_lack``, submaps summed over robots (-1 each while the peer has not told us)."""
        with self._lock:
            known = {p: self._peers.get(p) for p in peers}
        out = {}
        for peer, theirs in known.items():
            if theirs is None:
                out[peer] = {"they_lack": -1, "we_lack": -1}
                continue
            they = sum(max(0, n - theirs.get(r, 0)) for r, n in mine.items())
            we = sum(max(0, n - mine.get(r, 0)) for r, n in theirs.items())
            if they or we:
                out[peer] = {"they_lack": they, "we_lack": we}
        return out


def describe(lacking: dict[str, dict[str, int]]) -> str:
    """``lacking`` (`Holdings.lacking`) as words."""
    parts = []
    for peer, v in sorted(lacking.items()):
        if v["they_lack"] < 0:
            parts.append(f"{peer} (no advert yet)")
        else:
            parts.append(f"{peer} (lacks {v['they_lack']} of ours, holds {v['we_lack']} more)")
    return ", ".join(parts)
