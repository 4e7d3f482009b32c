"""Byte accounting of the fleet transport (`gmmap.fleet.net.transport`; what is counted and what is
not is in its module docstring).
"""

from __future__ import annotations

import threading
from dataclasses import asdict, dataclass
from typing import Any

MAX_ENTRIES = 1024  # (direction, robot, kind) counted apart; beyond, all under "*"
OTHERS = "*"


@dataclass
class ByteCount:
    """Messages and bytes of one (direction, robot, kind); fetch_* are the fetch-reply part."""

    messages: int = 0
    payload_bytes: int = 0
    key_bytes: int = 0
    fetch_messages: int = 0
    fetch_payload_bytes: int = 0

    def add(self, payload: int, key: int, fetched: bool) -> None:
        self.messages += 1
        self.payload_bytes += payload
        self.key_bytes += key
        if fetched:
            self.fetch_messages += 1
            self.fetch_payload_bytes += payload

    def merge(self, other: ByteCount) -> None:
        for name, value in asdict(other).items():
            setattr(self, name, getattr(self, name) + value)


class Counters:
    """Thread-safe byte counters; Zenoh callbacks and user threads update them concurrently."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[tuple[str, str, str], ByteCount] = {}
        self.queries_sent = 0
        self.queries_served = 0
        self.ignored = 0

    def add(self, direction: str, robot: str, kind: str, payload: int, key: int, fetched: bool):
        with self._lock:
            at = (direction, robot, kind)
            if at not in self._counts and len(self._counts) >= MAX_ENTRIES:
                at = (direction, OTHERS, OTHERS)  # a flood under made-up names stays bounded
            self._counts.setdefault(at, ByteCount()).add(payload, key, fetched)

    def bump(self, name: str) -> None:
        with self._lock:
            setattr(self, name, getattr(self, name) + 1)

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            out: dict[str, Any] = {"sent": {}, "received": {}}
            totals = {"sent": ByteCount(), "received": ByteCount()}
            for (direction, robot, kind), count in sorted(self._counts.items()):
                out[direction].setdefault(robot, {})[kind] = asdict(count)
                totals[direction].merge(count)
            out["totals"] = {d: asdict(c) for d, c in totals.items()}
            out["queries"] = {"sent": self.queries_sent, "served": self.queries_served}
            out["ignored"] = self.ignored
            return out
