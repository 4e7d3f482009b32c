"""A robot node's fetch stage (`gmmap.fleet.node.robot.RobotNode`): what it asks its peers for,
in the thread of its `Fetcher`.

A fetch asks for a robot's submaps from the first gap in what arrived, but those that arrived
after it (`gmmap.fleet.sharing.arrivals`):

- when an advert (`gmmap.fleet.sharing.holdings`) says a peer holds more of a robot than we do.
  Where that robot talks to us and all we lack of it is newer than what it last sent us, it is
  queued behind on a slow link (`Arrivals.on_its_way`) and a fetch would send it twice: we
  ask again once the robot could have fallen quiet, and only if we still lack it. Before
  asking the robot itself we wait `LANDING_S`: what it sent the peer may be landing here too.
  Both only where robots bundle (`Arrivals.patient`): on links that come and go a robot that
  sent nothing newer more likely went out of reach, and a meeting may last a second;
- while we map, every `holdings.FETCH_EVERY_S`, for each present robot still mapping that
  sent us nothing for a while although another robot did (`Fetcher.stalled`). A rendezvous
  link that went down stays "present" until Zenoh's lease ends, and the robot we hear may
  hold that robot's newest submaps: it maps too, so no advert of its tells us.

The owner answers for its own submaps while we hear it. Where it leaves a query unanswered, or
is quiet, the robots in between answer (``relay``), oldest first: the one peer we hear whose
advert holds the most of that robot (`Fetcher._holder`), or, where none does or it answers
nothing, every peer. Asking one spares the others' copies, and each query goes only to the
robots it names (`gmmap.fleet.net.transport`).
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from concurrent.futures import ThreadPoolExecutor

from gmmap.fleet.sharing import holdings
from gmmap.fleet.sharing.events import Arrived
from gmmap.fleet.sharing.shared import KIND, Shared

log = logging.getLogger(__name__)

# Before asking a robot for what a peer's advert says it lacks: the robot sent it to every
# peer at once, and under load or on a slower link it lands here a moment after there.
LANDING_S = 1.0


class Fetcher:
    """A robot node's fetch stage: `run` is its thread, which fetches the robots queued on
    ``shared.fetch_queue`` and, while the node maps, asks about those that fell quiet; each
    submap fetched goes to ``shared.enqueue``."""

    def __init__(self, shared: Shared) -> None:
        self.shared = shared

    def run(self) -> None:
        # The probe keeps its time however busy the fetches are: gaps fetched one after
        # another must not put off asking about a robot that fell quiet.
        probe_at = time.monotonic() + holdings.FETCH_EVERY_S
        fetch_queue = self.shared.fetch_queue
        while not self.shared.stopping:
            items = []
            with contextlib.suppress(queue.Empty):
                items.append(fetch_queue.get(timeout=max(0.0, probe_at - time.monotonic())))
                # One round serves every request queued meanwhile.
                while True:
                    items.append(fetch_queue.get_nowait())
            if None in items:
                return
            if items:
                self.fetch({r for i in items for r in i})
            if time.monotonic() >= probe_at:
                self.fetch(set(self.stalled()), probe=True)
                probe_at = time.monotonic() + holdings.FETCH_EVERY_S

    def fetch(self, robots: set[str], probe: bool = False) -> None:
        """Fetch what we lack of ``robots``; a probe asks the robots in between even where no
        advert says they hold more."""
        robots -= {self.shared.robot}
        # All at once: a stalled link holds a query until its timeout, and a meeting may end.
        try:
            with ThreadPoolExecutor(max(1, len(robots))) as pool:
                list(pool.map(lambda r: self._fetch_one(r, probe), sorted(robots)))
        except Exception:
            log.exception("%s: fetching %s failed", self.shared.robot, sorted(robots))

    def _fetch_one(self, r: str, probe: bool) -> None:
        if self.shared.stopping:
            return
        arrivals, transport = self.shared.arrivals, self.shared.transport
        held, since, told = self._lacking(r)
        if since >= told and not probe:
            return
        if not probe and arrivals.on_its_way(r, since):
            self._later(r)  # a peer with a faster link to r told us: r's own sends follow
            return
        relay = probe or arrivals.relayed(r, transport.peers())
        if not relay and arrivals.patient:  # what r sent the peer may be landing here
            time.sleep(LANDING_S)
            held, since, told = self._lacking(r)
            if since >= told:
                return
        asked = arrivals.now()
        if relay:
            got = self._relayed(r, since, held, probe)
        else:
            got = transport.fetch(r, KIND, since, held=held)
        # On a shared channel the robot answers on the air: its answer is on its way here.
        if not got and not relay and not arrivals.shared_channel and arrivals.unanswered(r, asked):
            # Its link to us stalled: at once through those in between.
            got = self._relayed(r, since, held, probe=False)
        for seq, payload in got:
            self.enqueue_fetched(r, seq, payload)

    def _relayed(self, r: str, since: int, held: set[int], probe: bool) -> list[tuple[int, bytes]]:
        """``r``'s submaps from ``since`` on, through the robots in between. A probe asks every
        peer: while robots map, their adverts are old."""
        via = None if probe else self._holder(r, since)
        transport = self.shared.transport
        got = transport.fetch(r, KIND, since, relay=True, via=via, held=held)
        if not got and via is not None:  # its advert is stale, or its link stalled
            got = transport.fetch(r, KIND, since, relay=True, held=held)
        return got

    def _holder(self, r: str, since: int) -> str | None:
        """The peer we hear whose advert holds the most of ``r`` past ``since``; None where
        none does."""
        present = self.shared.transport.peers()
        heard = set(present) - set(self.shared.arrivals.quiet(present)) - {r}
        held = {p: h.get(r, 0) for p, h in self.shared.holdings.adverts().items() if p in heard}
        best = max(held.values(), default=0)
        return min(p for p, n in held.items() if n == best) if best > since else None

    def _lacking(self, r: str) -> tuple[set[int], int, int]:
        """What of ``r`` arrived, where a fetch of it starts, and how many of it the adverts say
        a peer holds."""
        arrivals = self.shared.arrivals
        held = arrivals.held(r, self.shared.store.seqs(r))
        since = arrivals.since(r, held)
        # The adverts count what is stored; what is still queued here counts as arrived. On a
        # lossy link, its newest submap that came from it says it holds all before.
        told = max((h.get(r, 0) for h in self.shared.holdings.adverts().values()), default=0)
        if self.shared.lossy:
            told = max(told, arrivals.latest(r) + 1)
        return held, since, told

    def _later(self, r: str) -> None:
        """Asks about ``r`` again once it could have fallen quiet: if what it sends has not
        come by then, its link went down, and the robots in between answer."""

        def again() -> None:
            if not self.shared.stopping:
                self.shared.fetch_queue.put((r,))

        timer = threading.Timer(self.shared.arrivals.quiet_s, again)
        timer.daemon = True
        timer.start()

    def stalled(self) -> list[str]:
        """While we map: the present robots still mapping, of which we hold something, that
        sent us nothing for a while although another present robot did."""
        shared = self.shared
        # On a shared channel a robot that went quiet went quiet for all: no peer holds more
        # of it, and each probe is a query to every peer on air time they all share.
        if shared.state != holdings.MAPPING or shared.stopping or shared.arrivals.shared_channel:
            return []
        present = shared.transport.peers()
        quiet = shared.arrivals.quiet(present)
        if len(quiet) == len(present):  # we hear no one: no robot in between to ask
            return []
        told = shared.holdings.states()
        return [
            r
            for r in quiet
            if told.get(r, holdings.MAPPING) == holdings.MAPPING and shared.store.count(r, KIND)
        ]

    def enqueue_fetched(self, robot: str, seq: int, payload: bytes) -> None:
        """Hand a submap a fetch brought on to the keeping stage, if admitted and new."""
        shared = self.shared
        # A relay's reply too must carry the owner's seal.
        if not shared.door.admit(robot, KIND, seq, payload) or not shared.arrivals.add(robot, seq):
            return
        with shared.lock:  # fetches of several robots run at once
            shared.counts["fetched"] += 1
        shared.enqueue(Arrived("fetched", robot, seq, payload))
