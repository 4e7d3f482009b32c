"""A robot's voice and ears on a shared channel (`TransportOptions.broadcast`): what it puts on
the air (`gmmap.fleet.net.air`) and who it hears there.

Everything a robot needs of its peers goes on the air, so presence is what is heard there: a
robot greets the channel (``hello``, no payload) when it starts, answers every robot that
starts (a restarted one may still count as present) and every robot new to it by another
message (it may have started before we listened), says ``bye`` when it closes, and counts as
gone after `PRESENCE_S` unheard (it greets after `PRESENCE_S` / 3 of silence). Three robots
meet in ~6 datagrams of ~60 B, where one Zenoh session's handshakes and declarations take
~960 B. Its own messages a robot is asked for again it puts on the air again, once for all
that ask within `REAIRED_S` (`Hearing.aired_lately`).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable

from gmmap.errors import TransportError
from gmmap.fleet.net.air import Air, Message

# Presence on a shared channel: Zenoh's lease there (`gmmap.fleet.net.session.SHARED_LEASE`).
PRESENCE_S = 120.0
HELLO, BYE = "hello", "bye"  # seq 0: a robot that starts, 1: one that answers or keeps present
MAX_HEARD = 1_024  # robots present from the air: forged names cannot grow it without bound
# A message put on the air again for a fetch is not again for this long: the robots that asked
# meanwhile hear it once it has crossed the channel's queue (seconds on a slow channel).
REAIRED_S = 10.0


class Hearing:
    """Robot ``robot`` of ``fleet`` on the group ``endpoint``. ``take(message, payload)`` gets
    every message of another robot of the fleet but greetings; ``present(robot, bool)`` marks
    a robot present or gone and says whether that changed (both run on the air's thread).
    ``announces``: False for a station, which is not a robot its peers wait for."""

    def __init__(
        self,
        endpoint: str,
        fleet: str,
        robot: str,
        announces: bool,
        take: Callable[[Message, bytes], None],
        present: Callable[[str, bool], bool],
    ) -> None:
        self.fleet, self.robot, self.announces = fleet, robot, announces
        self._take, self._present = take, present
        self._lock = threading.Lock()
        self._heard: dict[str, float] = {}  # robot → when last heard (presence)
        self._talkers: dict[str, float] = {}  # the same, pruned by `talkers`' window
        self._reaired: dict[tuple[str, int], float] = {}  # (kind, seq) → when
        self._closed = False
        self.air = Air(endpoint, self._on_air, self._on_tick)
        self.air.start()

    def send(self, kind: str, seq: int, data: bytes | bytearray | memoryview) -> bool:
        """Puts our message on the air where it fits one datagram (else False)."""
        return self.air.send((self.fleet, self.robot, kind, seq), bytes(data))

    def greet(self, seq: int) -> None:
        """Says on the air that we are here (0: we start, 1: we answer or keep present)."""
        if self.announces and not self._closed:
            with contextlib.suppress(TransportError):  # the next greeting may get through
                self.air.send((self.fleet, self.robot, HELLO, seq))

    def close(self) -> None:
        """Says goodbye and leaves the group. Idempotent."""
        if self.announces and not self._closed:
            with contextlib.suppress(TransportError):
                self.air.send((self.fleet, self.robot, BYE, 0))
        self._closed = True
        self.air.close()

    def talkers(self, window_s: float) -> set[str]:
        """The other robots of the fleet heard in the last ``window_s`` s."""
        since = time.monotonic() - window_s
        with self._lock:
            # Forgotten once out of the window: names forged on the air do not pile up.
            self._talkers = {r: at for r, at in self._talkers.items() if at >= since}
            return set(self._talkers)

    def aired_lately(self, kind: str, seq: int) -> bool:
        """Whether our message went on the air again for a fetch within `REAIRED_S` (else it
        counts as going now)."""
        now = time.monotonic()
        with self._lock:
            self._reaired = {m: t for m, t in self._reaired.items() if t > now - REAIRED_S}
            if (kind, seq) in self._reaired:
                return True
            self._reaired[(kind, seq)] = now
        return False

    def _on_air(self, message: Message, payload: bytes) -> None:
        # Our own broadcasts come back too (other robots on this host must hear them), as would
        # a forged one with our name: both are dropped.
        fleet, robot, kind, seq = message
        if fleet != self.fleet or robot == self.robot or self._closed:
            return
        now = time.monotonic()
        with self._lock:
            if robot not in self._heard and len(self._heard) >= MAX_HEARD:
                return
            self._talkers[robot] = now
            if kind == BYE:
                self._heard.pop(robot, None)
            else:
                self._heard[robot] = now
        if kind == BYE:
            self._present(robot, False)
            return
        joined = self._present(robot, True)
        if (kind == HELLO and seq == 0) or (joined and kind != HELLO):
            self.greet(1)
        if kind != HELLO:
            self._take(message, payload)

    def _on_tick(self) -> None:
        # Every second: the robots unheard for PRESENCE_S are gone, and a robot that said
        # nothing for a third of it greets, so that it stays present.
        now = time.monotonic()
        with self._lock:
            expired = [r for r, at in self._heard.items() if at < now - PRESENCE_S]
            for robot in expired:
                del self._heard[robot]
        for robot in expired:
            self._present(robot, False)
        if now > self.air.last_sent + PRESENCE_S / 3:
            self.greet(1)
