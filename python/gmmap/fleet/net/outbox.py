"""What a robot sends, in priority order and within its byte budget (`RobotOptions.budget`).

The construction stage and the lingering node put messages here and never wait for the link;
one sender thread publishes them. When the link (or the budget) is slower than the robot
builds, messages wait here and leave in this order:

1. adverts (`gmmap.fleet.sharing.holdings`): about 80 B each, and what tells the peers whether to
   wait (only the latest waits: it says all the robot holds);
2. own submaps, newest first. Two robots that meet are near each other now, so their newest
   submaps are the likeliest to overlap, verify and join their maps; the older ones follow
   (a peer fills the gaps by fetching, `Fetcher.fetch`, whose answers go oldest first so
   that a fetch its timeout cuts short resumes from its first gap).

Own submaps leave in bundles (`RobotOptions.bundle`): the outbox holds them until ``bundle``
wait, or the oldest has waited ``bundle_wait`` s, or an advert is due, or the robot's frames
ended (`Outbox.release`), and then sends all that waits back to back. Zenoh puts messages
queued within a millisecond into one batch, so a bundle shares its TCP/IP headers and ACKs:
on a link of 1,448-byte segments a 750 B submap costs about 905 B on the wire alone, 860 B in
threes, 840 B in fours (docs/benchmarks.md, "links", by bundle). The price is latency: a submap may
reach the peers ``bundle_wait`` s later.

The budget is a token bucket over the payload and key bytes of everything this robot puts on
its links, fetch answers included (`Budget.take`, which `Transport.serve` calls too); Zenoh's
framing and the TCP/IP headers come on top (see docs/benchmarks.md). In Zenoh's peer mode one
publication goes to every peer, so the budget holds on each link. On a channel the fleet
shares (`TransportOptions.channel_rate`) the robot takes an equal share of it, updated as
robots come and go (`air_share`).
"""

from __future__ import annotations

import heapq
import logging
import math
import threading
import time
from collections.abc import Callable

from gmmap.errors import TransportError
from gmmap.fleet.net.keys import data_key

log = logging.getLogger(__name__)

BURST_S = 1.0  # the bucket holds this many seconds of budget (and at least one message)
# Of a shared channel's bytes/s, what the robots' messages may take together: the rest is for
# what the budget does not count (UDP/IP headers, greetings, the sessions that repair what a
# robot missed; docs/benchmarks.md, "channel").
AIR_SHARE = 0.6


def air_share(channel_rate: float | None, robots: int, budget: float | None) -> float | None:
    """A robot's budget on a channel of ``channel_rate`` bytes/s that ``robots`` share (itself
    included): an equal share of `AIR_SHARE` of it, so that no robot starves the others, and
    never more than its own ``budget`` (None: no limit)."""
    if channel_rate is None:
        return budget
    share = AIR_SHARE * channel_rate / max(1, robots)
    return share if budget is None else min(share, budget)


Publish = Callable[[str, int, bytes, "frozenset[str] | None"], None]


class Budget:
    """A token bucket of ``rate`` bytes/s (None: unlimited), thread-safe; `follow` makes the
    rate a function of time."""

    def __init__(self, rate: float | None) -> None:
        self.rate = rate
        self._lock = threading.Lock()
        self._tokens = rate * BURST_S if rate else 0.0
        self._at = time.monotonic()
        self._source: Callable[[], float | None] | None = None

    def set_rate(self, rate: float | None) -> None:
        """From now on ``rate`` bytes/s; the tokens saved stay, within the new burst (a
        bucket that had no limit starts full, as a new one does)."""
        with self._lock:
            self._switch(rate, 0)

    def follow(self, source: Callable[[], float | None] | None) -> None:
        """Take the rate from ``source()`` while waiting to send, from now on (None: stop)."""
        with self._lock:
            self._source = source

    def _switch(self, rate: float | None, n: int) -> None:
        """The tokens saved up to now at the old rate, then ``rate``; a message of ``n`` bytes
        keeps what it saved toward itself. Called locked."""
        saved = math.inf if self.rate is None else self._accrued(n)
        self._at, self.rate = time.monotonic(), rate
        self._tokens = min(saved, max(rate * BURST_S, n)) if rate else 0.0

    def _accrued(self, n: int) -> float:
        """The tokens now, within the burst or ``n``, whichever is more. Called locked."""
        assert self.rate is not None
        now = time.monotonic()
        cap = max(self.rate * BURST_S, float(n))
        self._tokens = min(cap, self._tokens + (now - self._at) * self.rate)
        self._at = now
        return self._tokens

    def take(self, n: int, stopped: Callable[[], bool] = lambda: False) -> bool:
        """Wait until ``n`` bytes may go and take them; False if ``stopped()`` first."""
        while not stopped():
            with self._lock:
                if self._source is not None and (rate := self._source()) != self.rate:
                    self._switch(rate, n)
                if self.rate is None:
                    return True
                if self._accrued(n) >= n:
                    self._tokens -= n
                    return True
                wait = (n - self._tokens) / self.rate
            time.sleep(min(wait, 0.1))
        return False


class Outbox:
    """Messages waiting to be published, ``urgent`` kind first (the adverts, oldest first),
    then the rest newest first, sent by one thread through ``publish(kind, seq, payload,
    to)`` (``to``: the peers it is for, None: all) within ``budget``, each costing its payload
    and its key (``sender``: fleet, robot)."""

    def __init__(
        self,
        publish: Publish,
        budget: Budget,
        urgent: str,
        sender: tuple[str, str],
        bundle: int = 1,
        bundle_wait: float = 0.0,
    ):
        self._publish, self.budget = publish, budget
        self._urgent, self._sender = urgent, sender
        self._bundle, self._wait = bundle, bundle_wait
        self._oldest = 0.0  # when the oldest message waiting was queued (monotonic)
        self._open = False  # a bundle is leaving: send until nothing waits
        self._heap: list[tuple[tuple[int, int], str, int, bytes, frozenset[str] | None]] = []
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._sending = False
        self._thread = threading.Thread(target=self._run, name="gmmap-outbox", daemon=True)
        self._thread.start()

    def put(self, kind: str, seq: int, payload: bytes, to: frozenset[str] | None = None) -> None:
        """Queue a message for the peers ``to`` (None: all); an urgent one replaces those of
        its kind still waiting for the same peers, or for any where it goes to all (an advert
        says all a robot holds: only the latest counts)."""
        rank = (0, seq) if kind == self._urgent else (1, -seq)
        with self._cond:
            if not self._heap:
                self._oldest = time.monotonic()
            if kind == self._urgent:
                self._heap = [m for m in self._heap if m[1] != kind or to not in (None, m[4])]
                heapq.heapify(self._heap)
            heapq.heappush(self._heap, (rank, kind, seq, payload, to))
            self._cond.notify()

    def release(self) -> None:
        """Hold nothing from now on: no more own submaps are coming to bundle with."""
        with self._cond:
            self._bundle = 1
            self._cond.notify()

    def held(self, kind: str) -> set[int]:
        """The seqs of ``kind`` waiting here, not yet being sent."""
        with self._cond:
            return {m[2] for m in self._heap if m[1] == kind}

    def now(self) -> None:
        """Send what waits now (a peer asked for it), bundling again afterwards."""
        with self._cond:
            if self._heap:
                self._open = True
                self._cond.notify()

    def _due(self) -> float:
        """Seconds until what waits may leave (0: now; inf: nothing waits). Called locked."""
        if not self._heap:
            return math.inf
        if self._open or len(self._heap) >= self._bundle or self._heap[0][1] == self._urgent:
            return 0.0
        return max(0.0, self._oldest + self._wait - time.monotonic())

    def pending(self) -> int:
        """Messages queued or being sent."""
        with self._cond:
            return len(self._heap) + self._sending

    def flush(self, timeout: float) -> bool:
        """Send what waits, holding nothing back from now on, and wait until it is sent
        (True) or ``timeout`` s pass."""
        self.release()
        deadline = time.monotonic() + timeout
        while self.pending() and time.monotonic() < deadline and not self._stop.is_set():
            time.sleep(0.02)
        return not self.pending()

    def close(self, flush_s: float = 0.0) -> None:
        """Stop sending, after up to ``flush_s`` s sending what waits (a bundle held back)."""
        if flush_s > 0:
            self.flush(flush_s)
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        while True:
            with self._cond:
                while (due := self._due()) > 0 and not self._stop.is_set():
                    self._cond.wait(None if due == math.inf else due)
                if self._stop.is_set():
                    return
                _, kind, seq, payload, to = heapq.heappop(self._heap)
                self._open = bool(self._heap)
                self._sending = True
            try:
                key = data_key(*self._sender, kind, seq).encode()
                if self.budget.take(len(payload) + len(key), self._stop.is_set):
                    self._publish(kind, seq, payload, to)
            except TransportError as err:  # closing, or the link is gone: the store keeps it
                log.debug("not sent %s/%d: %s", kind, seq, err)
            finally:
                with self._cond:
                    self._sending = False
