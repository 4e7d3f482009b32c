"""Hostile input at a robot's door: a size cap per message, a rate limit per sending robot
(`SecurityOptions`: ``max_bytes``, ``rate``, ``burst``), and counters of everything refused,
by robot and cause (`Refusals`).

Both bounds keep a flood from costing more than it brings: a message over ``max_bytes`` is
dropped before it is parsed or queued, and a sender over its rate (a token bucket: ``rate``
messages a second, ``burst`` at once) is dropped until its bucket refills, so the inbox grows
at most by what the honest rate allows; all senders together get FLEET_SHARE times one
sender's rate and burst. What is tracked per sender is bounded too
(``MAX_SENDERS``): names beyond it share one bucket and one counter, ``"*"``, so a flood under
made-up names cannot grow the robot's memory.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from gmmap.fleet_options import SecurityOptions

MAX_SENDERS = 256
OTHERS = "*"  # the shared entry of senders beyond MAX_SENDERS
ALL = ""  # the bucket of all senders together
FLEET_SHARE = 8  # all senders together may send as much as this many at their rate


class Refusals:
    """Counts of refused messages, per sending robot and cause (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[str, dict[str, int]] = {}

    def add(self, robot: str, cause: str) -> None:
        with self._lock:
            if robot not in self._counts and len(self._counts) >= MAX_SENDERS:
                robot = OTHERS
            per = self._counts.setdefault(robot, {})
            per[cause] = per.get(cause, 0) + 1

    def snapshot(self) -> dict[str, dict[str, int]]:
        with self._lock:
            return {r: dict(c) for r, c in sorted(self._counts.items())}

    def by_cause(self) -> dict[str, int]:
        """The counts per cause, all senders together."""
        out: dict[str, int] = {}
        for per in self.snapshot().values():
            for cause, n in per.items():
                out[cause] = out.get(cause, 0) + n
        return dict(sorted(out.items()))


class Guard:
    """Admits or refuses each arriving message before anything else looks at it."""

    def __init__(
        self,
        options: SecurityOptions | None = None,
        refusals: Refusals | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.options = options or SecurityOptions()
        self.refusals = refusals or Refusals()
        self._clock = clock
        self._lock = threading.Lock()
        self._buckets: dict[str, tuple[float, float]] = {}  # sender -> (tokens, at)

    def admit(self, robot: str, size: int) -> bool:
        """True if a message of ``size`` bytes from ``robot`` may go on; otherwise counts it
        (``oversize`` or ``rate``) and returns False."""
        if size > self.options.max_bytes:
            self.refusals.add(robot, "oversize")
            return False
        if self.options.rate is not None and not self._take(robot):
            self.refusals.add(robot, "rate")
            return False
        return True

    def _take(self, robot: str) -> bool:
        rate, burst = float(self.options.rate or 0.0), float(self.options.burst)
        now = self._clock()
        with self._lock:
            if robot not in self._buckets and len(self._buckets) >= MAX_SENDERS:
                robot = OTHERS
            # All senders together too: a flood under many names is held to FLEET_SHARE senders.
            ok = self._spend(ALL, now, rate * FLEET_SHARE, burst * FLEET_SHARE, False)
            ok = self._spend(robot, now, rate, burst, not ok) and ok
        return ok

    def _spend(self, bucket: str, now: float, rate: float, burst: float, dry: bool) -> bool:
        tokens, at = self._buckets.get(bucket, (burst, now))
        tokens = min(burst, tokens + (now - at) * rate)
        ok = tokens >= 1.0 and not dry
        self._buckets[bucket] = (tokens - 1.0 if ok else tokens, now)
        return ok
