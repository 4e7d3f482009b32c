"""A robot node's adverts and ending (`gmmap.fleet.node.robot.RobotNode`), kept by its `Lingerer`:
what it tells its peers it holds (`gmmap.fleet.sharing.holdings`), and when it leaves the fleet.

- When a peer joins while the robot holds anything, it tells that peer what it holds, SETTLE_S
  later (the peer's queryable is surely declared by then), unless an advert to all reached it
  since. The others know it already, so the advert goes to the peers that joined alone
  (`Transport.tell`), or to all where at least half of them did (three robots, or all
  joining at once after a restart): there one put costs no more.
- After its frames it lingers (`Lingerer.linger`): it tells all what it holds when that is
  news to one of them, and ends once the peers in reach hold what it holds and it holds what
  they hold, and every robot it knows of is done mapping and its last submap is here, or at
  ``robot.deadline``. It then leaves the fleet; the node finishes its matching. On a shared
  channel its adverts go to all, and wait while its own submaps do.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from gmmap.fleet.net.outbox import Outbox
from gmmap.fleet.sharing import holdings
from gmmap.fleet.sharing.shared import KIND, Shared


class Lingerer:
    """A robot node's adverts and ending: it tells the peers what the node holds through the
    ``outbox`` (unless ``tells`` is False: a station tells nothing), and `linger` ends the
    node's time in the fleet once ``delivered()`` and the peers hold the same."""

    def __init__(
        self, shared: Shared, outbox: Outbox, delivered: Callable[[], bool], tells: bool = True
    ) -> None:
        self.shared, self.outbox, self.delivered, self.tells = shared, outbox, delivered, tells
        # Adverts are numbered from the clock (ms), so a restarted robot's stay the newest.
        self._adverts, self._told_at, self._told = time.time_ns() // 1_000_000, 0.0, {}
        self._told_done: dict[str, int] = {}  # the robots done mapping our last advert named
        self._joiners: dict[str, float] = {}  # peers that joined, not yet told: when
        self._told_state = holdings.MAPPING

    def linger(self, seconds: float, end: float, progress: Callable | None = None) -> bool:
        """Work on for ``seconds`` after the frames, then until the peers hold what we hold and
        no more, and every robot we know of is done mapping and its last submap is here
        (`gmmap.fleet.sharing.holdings`), or until ``end`` (`time.monotonic`); True if complete.
        Then leave the fleet."""
        shared, robot = self.shared, self.shared.robot
        start = time.monotonic()
        seen, changed, fetch, said, complete = None, start, start, start, False
        shared.state = holdings.LINGER
        # Our last submaps leave now, and our news with them: in one batch, one ACK.
        self.advertise(shared.held(), holdings.LINGER)
        self.outbox.release()
        while not shared.stopping and (now := time.monotonic()) < end:
            mine = shared.held()
            present = shared.transport.peers()
            lacking = shared.holdings.lacking(mine, present)
            done = shared.holdings.finished(robot, holdings.LINGER, mine)
            unfinished = shared.holdings.unfinished(robot, done, mine)
            if mine != seen:
                seen, changed = mine, now
            # In a mesh, one advert once submaps stop arriving says it all; a relay tells at once.
            quiet = now >= changed + holdings.SETTLE_S or shared.holdings.relaying(mine, present)
            news = quiet and shared.holdings.is_news(
                mine,
                self._told,
                self._told_state,
                present,
                shared.arrivals.quiet(present),
                (done, self._told_done),
            )
            # On a shared channel a robot whose own submaps still wait for the air is heard by
            # all as it sends them, and no peer can end before the last: its adverts wait.
            talking = shared.arrivals.shared_channel and bool(self.outbox.held(KIND))
            if not talking and holdings.advert_due(now, news, self._told_at):
                self.advertise(mine, holdings.LINGER)
            # The final advert may not make it out before the session closes: the last one must.
            settled = now >= max(changed, self._told_at) + holdings.SETTLE_S
            ended = not lacking and not unfinished
            if now >= start + seconds and settled and ended and self.delivered():
                complete = True
                break
            wanted = holdings.wanted(shared.holdings.adverts(), mine)
            # Only what a peer says it holds more of, and not while submaps are arriving anyway.
            if now >= fetch and wanted and now >= changed + holdings.SETTLE_S:
                shared.fetch_queue.put(tuple(wanted))
                fetch = now + holdings.FETCH_EVERY_S
            if progress and not ended and now >= said + holdings.PROGRESS_EVERY_S:
                progress(f"{robot}: waiting for {holdings.describe(lacking, unfinished)}")
                said = now
            time.sleep(0.05)
        if not shared.stopping:
            shared.wait(self.delivered, max(5.0, seconds))
        mine = shared.held()
        # Done: the peers need not wait for us. Where all are done and hold what we told, our
        # leaving says as much, and an advert to each would cost two packets.
        if not (complete and mine == self._told and shared.holdings.at_rest(robot)):
            self.advertise(mine, holdings.FINAL)
        self.outbox.flush(timeout=max(5.0, seconds))
        # Done with the fleet: matching what arrived last and rejudging would only cost
        # keep-alives.
        shared.transport.close()
        return complete

    def advertise(
        self, counts: dict[str, int], state: str, to: frozenset[str] | None = None
    ) -> None:
        """Tell the peers ``to`` (None: all) what we hold; only what all were told is
        remembered as told. A put goes once to every peer, a message told to one peer alone
        is a query and its empty answer on its link: to half the peers or more, a put costs
        no more."""
        if not self.tells:
            return
        shared = self.shared
        peers = shared.transport.peers()
        # On a shared channel every robot in range hears it anyway.
        to = None if to is not None and 2 * len(to & set(peers)) >= len(peers) else to
        to = None if shared.arrivals.shared_channel else to
        done = shared.holdings.finished(shared.robot, state, counts)
        with shared.lock:  # the lingering node and a peer's join both advertise
            if to is None:
                self._told, self._told_at, self._told_state = counts, time.monotonic(), state
                self._told_done = done
            seq, self._adverts = self._adverts, self._adverts + 1
        advert = holdings.encode(counts, state, peers, done)
        sealed = shared.door.seal(shared.robot, holdings.KIND, seq, advert)
        self.outbox.put(holdings.KIND, seq, sealed, to)

    def joined(self, peer: str) -> None:
        """A peer joined: tell it what we hold once its queryable is surely declared."""
        self.shared.arrivals.met(peer)
        # Where we hold nothing it missed nothing: what we build, it hears.
        if self.tells and any(self.shared.held().values()):
            with self.shared.lock:
                self._joiners[peer] = time.monotonic()
            threading.Timer(holdings.SETTLE_S, self._tell).start()

    def heard_again(self, peer: str, seq: int | None) -> None:
        """A message of ``peer`` (its submap ``seq``, or an advert) on a lossy link: where we
        had not heard it for a while, its link came back, and what we sent it meanwhile is
        lost: tell it what we hold (it fetches what it lacks), and take its next advert as a
        first one. Where its submap is newer than one we lack, fetch the gap from it now: the
        meeting may be short."""
        shared = self.shared
        if peer in shared.arrivals.quiet(shared.transport.peers()):
            shared.holdings.meet(peer)
            shared.arrivals.hear(peer)
            held = shared.held()
            if any(held.values()) and not shared.stopping:
                self.advertise(held, shared.state, frozenset({peer}))
        if seq is not None and seq > shared.arrivals.since(peer, shared.store.seqs(peer)):
            shared.fetch_queue.put((peer,))

    def _tell(self) -> None:
        """Tell the peers that joined SETTLE_S ago what we hold, unless an advert to all
        reached them since: to them alone, as the others know it already (`advertise`)."""
        now = time.monotonic()
        with self.shared.lock:
            due = {p: t for p, t in self._joiners.items() if t + holdings.SETTLE_S <= now + 0.1}
            self._joiners = {p: t for p, t in self._joiners.items() if p not in due}
            told_at = self._told_at
        to = frozenset(p for p, t in due.items() if told_at < t + holdings.SETTLE_S / 2)
        held = self.shared.held() if not self.shared.stopping else {}
        if to and any(held.values()):
            self.advertise(held, self.shared.state, to)
