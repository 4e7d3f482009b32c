"""What a robot node (`gmmap.fleet.node.robot.RobotNode`) shares with the two parts that talk to its
peers for it: its fetcher (`gmmap.fleet.sharing.fetching`) and its lingerer
(`gmmap.fleet.sharing.lingering`). The node builds one `Shared` and hands it to both, so each
names what it works with, and none reaches into the node.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from gmmap.fleet.net.transport import DEFAULT_KIND, Transport
from gmmap.fleet.sharing.arrivals import Arrivals
from gmmap.fleet.sharing.events import Arrived
from gmmap.fleet.sharing.holdings import MAPPING, Holdings
from gmmap.fleet.storage.store import Store

KIND = DEFAULT_KIND


class Door(Protocol):
    """What the parts use of the node's door (`gmmap.fleet.security.door.Door`): `sharing` sits
    beside `security`, not above it, so it names the methods rather than imports the class."""

    def seal(self, robot: str, kind: str, seq: int, payload: bytes) -> bytes: ...

    def admit(self, robot: str, kind: str, seq: int, wire: bytes) -> bool: ...


@dataclass(kw_only=True)
class Shared:
    """A robot node's store, transport, door and bookkeeping of its peers, the queue of its
    fetches and the way into its keeping stage (``enqueue``), with the one lock and stop flag of
    the node (``lock`` also guards ``counts``)."""

    robot: str
    store: Store
    transport: Transport
    door: Door
    arrivals: Arrivals
    holdings: Holdings
    # Robots a peer holds more of; None: stop.
    fetch_queue: queue.Queue[tuple[str, ...] | None]
    counts: dict[str, int]
    enqueue: Callable[[Arrived], None]
    lock: threading.Lock = field(default_factory=threading.Lock)
    stop: threading.Event = field(default_factory=threading.Event)
    # Datagrams sent while a link was down are lost, not held: a robot heard again is caught up
    # with at once (`Lingerer.heard_again`).
    lossy: bool = False
    state: str = MAPPING  # LINGER once the frames are done (`Lingerer.linger`)

    @property
    def stopping(self) -> bool:
        return self.stop.is_set()

    def held(self) -> dict[str, int]:
        """How many submaps of each robot the store holds, ours included."""
        return {r: self.store.count(r, KIND) for r in {*self.store.robots(), self.robot}}

    def wait(self, done: Callable[[], bool], timeout: float) -> bool:
        """Wait until ``done()`` (True), or ``timeout`` s pass or the node stops (False)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not self.stopping:
            if done():
                return True
            time.sleep(0.02)
        return False
