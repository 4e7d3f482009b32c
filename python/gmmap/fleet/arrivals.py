"""What a robot has received of each other robot, stored or still queued, for its fetches
(`gmmap.fleet.robot`): where a fetch starts, and whether the robots in between must answer.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable


class Arrivals:
    """The sequence numbers received per robot, and the robots that are present yet did not
    answer a fetch for their own submaps (thread-safe: Zenoh's threads and the fetcher)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seqs: dict[str, set[int]] = {}
        self._silent: set[str] = set()

    def add(self, robot: str, seq: int, direct: bool = False) -> bool:
        """Notes that ``robot``'s ``seq`` arrived (``direct``: from that robot itself, which is
        then not silent); False if it had arrived already."""
        with self._lock:
            seqs = self._seqs.setdefault(robot, set())
            if direct:
                self._silent.discard(robot)
            new = seq not in seqs
            seqs.add(seq)
        return new

    def since(self, robot: str, stored: Iterable[int]) -> int:
        """Where a fetch of ``robot`` starts: its first gap, else after its latest. What arrived
        counts, stored or still queued: asking again for submaps waiting in a busy robot's
        inbox would have them sent twice."""
        with self._lock:
            have = set(stored) | self._seqs.get(robot, set())
        return next(seq for seq in range(len(have) + 1) if seq not in have)

    def relayed(self, robot: str, present: Iterable[str]) -> bool:
        """Whether the robots in between must answer for ``robot``: it is out of reach, or
        present and silent (a link that stalled: Zenoh sees it leave only when its lease
        expires)."""
        with self._lock:
            return robot not in set(present) or robot in self._silent

    def unanswered(self, robot: str) -> None:
        """``robot``, present, sent nothing of its own when asked: relays answer from now on,
        until something of it arrives directly."""
        with self._lock:
            self._silent.add(robot)
