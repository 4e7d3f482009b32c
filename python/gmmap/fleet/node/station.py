"""A base station (``gmmap station``): it watches a fleet and maps what the robots send, and
sends nothing of its own, so the robots' links and budgets carry what they would without it.

A `StationNode` is a `RobotNode` without frames that holds no liveliness token (its peers do not
count it, wait for it or tell it anything), advertises nothing and answers no fetch. It takes
every submap the robots publish, fetches what their adverts show it lacks, and catches up on its
own: when a robot appears, and every ``station.sweep_s`` while any is present, it asks each robot it
knows for what it lacks beyond what has arrived (the owner where present, its relays otherwise),
and the present robots for those of robots it has not heard of (`Transport.fetch_unknown`). It
also asks each present robot for its byte counts (`gmmap.fleet.sharing.linkstats`). Those queries,
and their answers, are the only bytes it adds to the fleet's links; a sweep that finds nothing costs
two small queries per robot. Its matching, optimisation and merge are the robots' own. In a
secured fleet its credentials carry the station role: Zenoh's access control lets it subscribe
and query, nothing else (`gmmap.fleet.security.access`).
"""

from __future__ import annotations

import contextlib
import logging
import threading
from pathlib import Path

from gmmap.config import Config
from gmmap.errors import DecodeError
from gmmap.fleet.node.robot import KIND, RobotNode
from gmmap.fleet.security.access import STATION
from gmmap.fleet.security.credentials import CredentialsError, load
from gmmap.fleet.sharing import linkstats
from gmmap.fleet.wire.codec import decode
from gmmap.mapping.submap import Submap

log = logging.getLogger(__name__)


class StationNode(RobotNode):
    """Watches ``config.robot.fleet`` under the name ``config.robot.name``."""

    watch = True
    tells = False

    def __init__(self, config: Config, sweep_s: float | None = None) -> None:
        folder = config.security.credentials
        if folder is not None and (role := load(Path(folder)).role) != STATION:
            raise CredentialsError(
                f"{folder} is a {role}'s folder: the fleet's access control would let the station "
                "publish; issue one with gmmap fleet add DIR NAME --role station"
            )
        super().__init__(config)
        self.sweep_s = config.station.sweep_s if sweep_s is None else sweep_s
        self._wake = threading.Event()
        self.links: dict[str, dict] = {}  # robot → its byte counts, as it last told them
        self.arrived: dict[tuple[str, int], Submap] = {}  # decoded on arrival, for the view

    def start(self) -> None:
        super().start()
        self._spawn("sweep", self._sweeper)

    def stop(self) -> None:
        self._wake.set()
        super().stop()

    def _enqueue(self, item) -> None:
        # Shown at once (`arrived`), not only once the matching stage, which can lag behind a
        # large fleet by tens of seconds, has taken it.
        if item.origin != "own" and (item.robot, item.seq) not in self.arrived:
            with contextlib.suppress(DecodeError):
                self.arrived[(item.robot, item.seq)] = decode(self.door.inner(item.payload))
        super()._enqueue(item)

    def _serve(self) -> None:  # answers no fetch
        pass

    def _joined(self, peer: str) -> None:
        self.arrivals.met(peer)
        self._wake.set()

    def _sweeper(self) -> None:
        while not self.stopping:
            try:
                self.sweep()
            except Exception:
                log.exception("%s: a catch-up sweep failed", self.robot)
            self._wake.wait(self.sweep_s)
            self._wake.clear()

    def sweep(self) -> int:
        """One catch-up round; the submaps it fetched."""
        t = self.transport
        peers = set(t.peers())
        if not peers or self.stopping:
            return 0
        known = set(self.store.robots()) | peers
        fetched = 0
        for robot, got in t.fetch_unknown(known | {self.robot}, KIND).items():
            fetched += self._take(robot, got)
        for robot in sorted(known - {self.robot}):
            since = self.arrivals.since(robot, self.store.seqs(robot))
            fetched += self._take(robot, t.fetch(robot, KIND, since, relay=robot not in peers))
        for robot in sorted(peers):
            self._count(robot, t.fetch(robot, linkstats.KIND, 0))
        return fetched

    def link_counts(self) -> dict[str, dict]:
        """Robot → bytes sent and received per peer, as each last told; the station's own."""
        return {**self.links, self.robot: linkstats.counts(self.transport.stats(), self.robot)}

    def _count(self, robot: str, got: list[tuple[int, bytes]]) -> None:
        for seq, payload in got[-1:]:
            if self.door.admit(robot, linkstats.KIND, seq, payload):
                told = linkstats.decode(self.door.inner(payload))
                if told is not None and told.get("robot") == robot:
                    self.links[robot] = told

    def _take(self, robot: str, got: list[tuple[int, bytes]]) -> int:
        before = self.counts["fetched"]
        for seq, payload in got:
            self.fetcher.enqueue_fetched(robot, seq, payload)
        return self.counts["fetched"] - before
