"""A robot node's adverts and ending (`gmmap.fleet.node.robot.RobotNode`): what it tells its peers
it holds (`gmmap.fleet.sharing.holdings`), and when it leaves the fleet.

- When a peer joins while the robot holds anything, it tells that peer what it holds, SETTLE_S
  later (the peer's queryable is surely declared by then), unless an advert to all reached it
  since. The others know it already, so the advert goes to the peers that joined alone
  (`Transport.tell`), or to all where at least half of them did (three robots, or all
  joining at once after a restart): there one put costs no more.
- After its frames it lingers (`Lingering.linger`): it tells all what it holds when that is
  news to one of them, and ends once the peers in reach hold what it holds and it holds what
  they hold, and every robot it knows of is done mapping and its last submap is here, or at
  ``robot.deadline``. It then leaves the fleet and finishes its matching.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from gmmap.fleet.sharing import holdings
from gmmap.fleet.storage.records import edge_of


class Lingering:
    """Adverts and the ending of `RobotNode`, a mixin: it uses the node's ``robot``,
    ``config``, ``store``, ``mapper``, ``transport``, ``outbox``, ``arrivals``, ``holdings``,
    ``door``, ``fetch_queue``, ``_lock``, ``_state``, ``_adverts``, ``_told``, ``_told_at``,
    ``_told_state``, ``_told_done``, ``_joiners``, ``lossy``, ``stopping``, ``_held``,
    ``_delivered``, ``_matched`` and ``_wait``."""

    def linger(self, seconds: float, progress: Callable | None = None) -> bool:
        """Work on for ``seconds`` after the frames, then until the peers hold what we hold and
        no more, and every robot we know of is done mapping and its last submap is here
        (`gmmap.fleet.sharing.holdings`), or ``robot.deadline`` s; True if complete. Then leave the
        fleet, and finish matching."""
        if self.stopping:
            return False
        start = time.monotonic()
        end = start + max(seconds, self.config.robot.deadline)
        seen, changed, fetch, said, complete = None, start, start, start, False
        self._state = holdings.LINGER
        # Our last submaps leave now, and our news with them: in one batch, one ACK.
        self._advertise(self._held(), holdings.LINGER)
        self.outbox.release()
        while not self.stopping and (now := time.monotonic()) < end:
            mine = self._held()
            present = self.transport.peers()
            lacking = self.holdings.lacking(mine, present)
            done = self.holdings.finished(self.robot, holdings.LINGER, mine)
            unfinished = self.holdings.unfinished(self.robot, done, mine)
            if mine != seen:
                seen, changed = mine, now
            # In a mesh, one advert once submaps stop arriving says it all; a relay tells at once.
            quiet = now >= changed + holdings.SETTLE_S or self.holdings.relaying(mine, present)
            news = quiet and self.holdings.is_news(
                mine,
                self._told,
                self._told_state,
                present,
                self.arrivals.quiet(present),
                (done, self._told_done),
            )
            if holdings.advert_due(now, news, self._told_at):
                self._advertise(mine, holdings.LINGER)
            # The final advert may not make it out before the session closes: the last one must.
            settled = now >= max(changed, self._told_at) + holdings.SETTLE_S
            ended = not lacking and not unfinished
            if now >= start + seconds and settled and ended and self._delivered():
                complete = True
                break
            wanted = holdings.wanted(self.holdings.adverts(), mine)
            # Only what a peer says it holds more of, and not while submaps are arriving anyway.
            if now >= fetch and wanted and now >= changed + holdings.SETTLE_S:
                self.fetch_queue.put(tuple(wanted))
                fetch = now + holdings.FETCH_EVERY_S
            if progress and not ended and now >= said + holdings.PROGRESS_EVERY_S:
                progress(f"{self.robot}: waiting for {holdings.describe(lacking, unfinished)}")
                said = now
            time.sleep(0.05)
        if not self.stopping:
            self._wait(self._delivered, max(5.0, seconds))
        mine = self._held()
        # Done: the peers need not wait for us. Where all are done and hold what we told, our
        # leaving says as much, and an advert to each would cost two packets.
        if not (complete and mine == self._told and self.holdings.at_rest(self.robot)):
            self._advertise(mine, holdings.FINAL)
        self.outbox.flush(timeout=max(5.0, seconds))
        # Done with the fleet: matching what arrived last and rejudging would only cost
        # keep-alives. The rejudging needs every submap held by the matching stage first.
        self.transport.close()
        self._wait(self._matched, max(5.0, end - time.monotonic()))
        if self.config.robot.rejudge and not self.stopping:
            if progress:
                progress(f"{self.robot}: judging all {len(self.mapper.submaps)} submaps again")
            self.mapper = self.mapper.rejudged()
            self.store.replace_edges(edge_of(m) for m in self.mapper.matches)
        return complete

    def _advertise(
        self, counts: dict[str, int], state: str, to: frozenset[str] | None = None
    ) -> None:
        """Tell the peers ``to`` (None: all) what we hold; only what all were told is
        remembered as told. A put goes once to every peer, a message told to one peer alone
        is a query and its empty answer on its link: to half the peers or more, a put costs
        no more."""
        peers = self.transport.peers()
        to = None if to is not None and 2 * len(to & set(peers)) >= len(peers) else to
        done = self.holdings.finished(self.robot, state, counts)
        with self._lock:  # the lingering node and a peer's join both advertise
            if to is None:
                self._told, self._told_at, self._told_state = counts, time.monotonic(), state
                self._told_done = done
            seq, self._adverts = self._adverts, self._adverts + 1
        advert = holdings.encode(counts, state, peers, done)
        sealed = self.door.seal(self.robot, holdings.KIND, seq, advert)
        self.outbox.put(holdings.KIND, seq, sealed, to)

    def _joined(self, peer: str) -> None:
        """A peer joined: tell it what we hold once its queryable is surely declared."""
        self.arrivals.met(peer)
        if any(self._held().values()):  # else it missed nothing: what we build, it hears
            with self._lock:
                self._joiners[peer] = time.monotonic()
            threading.Timer(holdings.SETTLE_S, self._tell).start()

    def _heard_again(self, peer: str, seq: int | None) -> None:
        """A message of ``peer`` (its submap ``seq``, or an advert) on a lossy link: where we
        had not heard it for a while, its link came back, and what we sent it meanwhile is
        lost: tell it what we hold (it fetches what it lacks), and take its next advert as a
        first one. Where its submap is newer than one we lack, fetch the gap from it now: the
        meeting may be short."""
        if peer in self.arrivals.quiet(self.transport.peers()):
            self.holdings.meet(peer)
            self.arrivals.hear(peer)
            held = self._held()
            if any(held.values()) and not self.stopping:
                self._advertise(held, self._state, frozenset({peer}))
        if seq is not None and seq > self.arrivals.since(peer, self.store.seqs(peer)):
            self.fetch_queue.put((peer,))

    def _tell(self) -> None:
        """Tell the peers that joined SETTLE_S ago what we hold, unless an advert to all
        reached them since: to them alone, as the others know it already (`_advertise`)."""
        now = time.monotonic()
        with self._lock:
            due = {p: t for p, t in self._joiners.items() if t + holdings.SETTLE_S <= now + 0.1}
            self._joiners = {p: t for p, t in self._joiners.items() if p not in due}
            told_at = self._told_at
        to = frozenset(p for p, t in due.items() if told_at < t + holdings.SETTLE_S / 2)
        held = self._held() if not self.stopping else {}
        if to and any(held.values()):
            self._advertise(held, self._state, to)
