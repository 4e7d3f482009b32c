"""Fleet transport over Zenoh: robots exchange opaque encoded submaps (bytes) and nothing else.

Key expressions (``<fleet>``, ``<robot>``, ``<kind>`` are names, ``<seq>`` a decimal integer ≥ 0)::

    gmmap/<fleet>/<robot>/<kind>/<seq>     one message (a put); payload = the encoded bytes
    gmmap/<fleet>/<robot>/<kind>/<seq>/via/<r>  the same, told to robot r alone (a query)
    gmmap/<fleet>/<robot>                  liveliness token: the robot is present
    gmmap/<fleet>/<robot>/<kind>/*/via/<r>?since=N;held=5-7,9  fetch query (below)
    gmmap/<fleet>/*/<kind>/*/via/*?since=0;skip=a,b  every robot held but a and b (`fetch_unknown`)

Robots send two kinds: ``submap`` (an encoded submap) and ``have`` (an advert of what the
sender holds, `gmmap.fleet.sharing.holdings`; never fetched).

A fetch asks robot ``r`` (the robot itself, one in between, or ``*``: every peer) for what it
holds of a robot and kind from seq N on, but the seqs the asker holds (``held``); replies are
keyed ``…/<robot>/<kind>/<seq>/via/<r>``. Every robot that called :meth:`Transport.serve`
answers those that name it from its store, for its own data and for others' it holds: a robot
that was away catches up from whoever is present, and robots in between hand on the data of a
robot the asker cannot reach (multi-hop). Zenoh sends a query only to the robots it names.
So a message for one peer alone (`Transport.tell`) is a query on its queryable that carries
the message, whose empty answer ends it: its callbacks get it as they get a put.

Byte accounting (:meth:`Transport.stats`): per data robot and per kind, in each direction,

- ``messages``, ``payload_bytes``: every message and its payload (the encoded submap), published
  or received by subscription, plus fetch replies served or received;
- ``key_bytes``: the UTF-8 length of each message's key expression;
- ``fetch_messages``, ``fetch_payload_bytes``: the part of the above that travelled as fetch
  replies.

Not counted here: Zenoh's framing, TCP/IP headers, liveliness and queries (`gmmap.eval.links`
counts them on a link). Received messages count once accepted (right fleet, another robot,
well-formed key); dropped ones only increment ``ignored``.

Presence: a robot that closes its transport leaves at once, one that dies when Zenoh's lease
expires (60 s, `gmmap.fleet.net.session`). Two sessions of one name count as one robot.

On a shared channel (`TransportOptions.broadcast`) messages go on the air and presence is what
is heard there (`gmmap.fleet.net.hearing`). No unicast session opens until a query needs one
(`Transport._unicast`): a second session, to the peers in ``connect``, which answer from the
session they listen on. A robot asked by a robot on the air for its own messages puts them on
the air again instead of answering (`Querying.fetch`). Where nothing is lost, no byte goes on
the air but the messages and the greetings. A message too large for one datagram is put, and
reaches only the sessions that dialled ours: the peers fetch it after the sender's advert.

Zenoh's callback threads only parse, count and queue each event. One worker runs the message and
join/leave callbacks in arrival order, another answers fetches: a slow provider delays nothing.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import zenoh

from gmmap.errors import TransportConfigError, TransportError
from gmmap.fleet.net.air import Message
from gmmap.fleet.net.counters import ByteCount, Counters
from gmmap.fleet.net.hearing import Hearing
from gmmap.fleet.net.keys import (
    PREFIX,
    alive_key,
    as_payload,
    check_seq,
    data_key,
    free_port,
    parse_data_key,
)
from gmmap.fleet.net.outbox import Budget
from gmmap.fleet.net.querying import DEFAULT_KIND, FetchProvider, Querying, Roster
from gmmap.fleet.net.session import handshake_timeout_ms, open_session
from gmmap.fleet.net.worker import Worker, call_logged
from gmmap.names import NAME_RE, check_name
from gmmap.options import TransportOptions

__all__ = [
    "ByteCount",
    "FetchProvider",
    "MessageCallback",
    "PeerCallback",
    "Transport",
    "TransportConfig",
    "TransportConfigError",
    "TransportError",
    "TransportOptions",
    "alive_key",
    "data_key",
    "free_port",
    "parse_data_key",
]

log = logging.getLogger(__name__)

MessageCallback = Callable[[str, str, int, bytes], None]
"""``callback(robot, kind, seq, payload)`` for a message of another robot of the fleet."""
PeerCallback = Callable[[str], None]
"""``callback(robot)`` when a robot of the fleet joins or leaves."""


@dataclass(frozen=True)
class TransportConfig:
    """A robot's name in its fleet, its transport options and, in a secured fleet, its
    credentials (`gmmap.fleet.security.credentials`: TLS and access control,
    `gmmap.fleet.security.access`)."""

    fleet: str
    robot: str
    options: TransportOptions = field(default_factory=TransportOptions)
    credentials: Any = None
    watch: bool = False  # a station: no liveliness token (credentials with its role imply it)

    def __post_init__(self) -> None:
        check_name("fleet", self.fleet)
        check_name("robot", self.robot)


class Transport(Querying):
    """One robot's Zenoh peer session: publish, subscribe, presence and fetch of opaque bytes.

    The session opens on construction; use it as a context manager (or call :meth:`close`)::

        with Transport(TransportConfig(fleet="lab", robot="a")) as t:
            t.subscribe(lambda robot, kind, seq, payload: inbox.put((robot, seq, payload)))
            t.serve(store.fetch_provider)
            t.publish("submap", 0, encoded)
    """

    def __init__(self, config: TransportConfig) -> None:
        if not isinstance(config, TransportConfig):
            raise TransportConfigError(f"config must be a TransportConfig; got {config!r}")
        self.config = config
        self.fleet = config.fleet
        self.robot = config.robot
        self.listen_endpoints: tuple[str, ...] = ()  # set when the session opens
        self._counters = Counters()
        self._lock = threading.Lock()
        # Zenoh declarations happen under their own lock, never under _lock, which Zenoh's
        # callback threads take: a declaration that waited on one of them could deadlock.
        self._declare_lock = threading.Lock()
        self._present_changed = threading.Condition(self._lock)
        self._present: set[str] = set()
        self._message_callbacks: list[MessageCallback] = []
        self._join_callbacks: list[PeerCallback] = []
        self._leave_callbacks: list[PeerCallback] = []
        self._provider: FetchProvider | None = None
        self._roster: Roster | None = None
        self._budget = Budget(None)  # on fetch answers (`serve`)
        self._data_subscriber: Any = None
        self._queryable: Any = None
        self._probes: dict[str, zenoh.Publisher] = {}
        self._closed = False
        options = config.options
        shared = options.broadcast is not None
        # A station watches: it is not a robot its peers would wait for.
        announces = not config.watch and getattr(config.credentials, "role", None) != "station"
        # On a shared channel the session only listens: peers dial it when they must fetch.
        self._session, self.listen_endpoints = open_session(
            self.robot, replace(options, connect=()) if shared else options, config.credentials
        )
        # On a shared channel messages go on the air once (`TransportOptions.broadcast`).
        self._hearing: Hearing | None = None
        self._repair: zenoh.Session | None = None  # opened by the first query (`_unicast`)
        self._repair_opened = 0.0
        self._events = Worker(f"gmmap-transport-events-{self.robot}")
        self._queries = Worker(f"gmmap-transport-queries-{self.robot}")
        if shared:
            try:
                self._hearing = Hearing(
                    options.broadcast, self.fleet, self.robot, announces, self._from_air,
                    self._set_present,
                )  # fmt: skip
            except TransportError:
                self.close()
                raise
        try:
            liveliness = self._session.liveliness()
            if announces:
                self._token = liveliness.declare_token(alive_key(self.fleet, self.robot))
            if not shared:
                self._alive_subscriber = liveliness.declare_subscriber(
                    f"{PREFIX}/{self.fleet}/*", self._on_liveliness, history=True
                )
        except zenoh.ZError as err:
            self.close()
            raise TransportError(f"cannot declare liveliness for {self.robot!r}: {err}") from err
        if self._hearing is not None:
            self._hearing.greet(0)

    # ---- session ----------------------------------------------------------------------------

    def __enter__(self) -> Transport:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Leave the fleet: close the session (undeclares all), stop the workers. Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._present.clear()
            self._present_changed.notify_all()
        # Closing the session undeclares the token (peers see us leave), subscribers, queryable.
        for session in (self._session, self._repair):
            if session is not None:
                with contextlib.suppress(zenoh.ZError):
                    session.close()
        if self._hearing is not None:
            self._hearing.close()
        if hasattr(self, "_events"):
            self._events.stop()
            self._queries.stop()

    def _check_open(self) -> None:
        if self._closed:
            raise TransportError(f"transport of robot {self.robot!r} is closed")

    # ---- publish / subscribe ----------------------------------------------------------------

    def publish(self, kind: str, seq: int, payload: bytes | bytearray | memoryview) -> None:
        """Send ``payload`` to the fleet as ``gmmap/<fleet>/<robot>/<kind>/<seq>``.

        Reliable and blocking under congestion: a submap is never silently dropped on our side.
        """
        self._check_open()
        check_name("kind", kind)
        check_seq(seq)
        data = as_payload(payload)
        key = data_key(self.fleet, self.robot, kind, seq)
        try:
            if not self._broadcast(kind, seq, data):
                self._session.put(key, data, congestion_control=zenoh.CongestionControl.BLOCK)
        except zenoh.ZError as err:
            raise TransportError(f"cannot publish {key}: {err}") from err
        self._counters.add("sent", self.robot, kind, len(data), len(key.encode()), False)

    def _broadcast(self, kind: str, seq: int, data: bytes | bytearray | memoryview) -> bool:
        """Puts a message on the air where there is one and it fits one datagram."""
        return self._hearing is not None and self._hearing.send(kind, seq, data)

    def _aired_lately(self, kind: str, seq: int) -> bool:
        """`Hearing.aired_lately`; False without a shared channel."""
        return self._hearing is not None and self._hearing.aired_lately(kind, seq)

    def subscribe(self, callback: MessageCallback) -> None:
        """Call ``callback(robot, kind, seq, payload)`` for each message of another robot of this
        fleet, on the transport's event thread (in arrival order). Own messages, other fleets and
        malformed key expressions are ignored. Several callbacks may be registered."""
        self._check_open()
        if not callable(callback):
            raise TransportConfigError(f"callback must be callable; got {callback!r}")
        with self._lock:
            self._message_callbacks.append(callback)
        with self._declare_lock:
            if self._data_subscriber is not None:
                return
            # Declared lazily: before anyone listens, messages are not received nor counted.
            self._data_subscriber = self._session.declare_subscriber(
                f"{PREFIX}/{self.fleet}/*/*/*",
                self._on_sample,
                allowed_origin=zenoh.Locality.REMOTE,
            )

    def has_listeners(self, kind: str = DEFAULT_KIND) -> bool:
        """Whether some other session subscribes to this robot's messages of ``kind`` now (a
        publish before anyone listens is not stored by Zenoh: peers would fetch it later)."""
        self._check_open()
        check_name("kind", kind)
        with self._declare_lock:
            probe = self._probes.get(kind)
            if probe is None:
                # Declared on the wildcard of our own keys, never put on: only for matching.
                probe = self._session.declare_publisher(
                    f"{PREFIX}/{self.fleet}/{self.robot}/{kind}/*",
                    allowed_destination=zenoh.Locality.REMOTE,
                )
                self._probes[kind] = probe
        return bool(probe.matching_status.matching)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        # Zenoh thread: parse, count, enqueue; nothing slow.
        try:
            key = str(sample.key_expr)
            parsed = parse_data_key(key) if sample.kind == zenoh.SampleKind.PUT else None
            self._take(key, parsed, sample.payload)
        except Exception:  # never let a bad sample take down Zenoh's callback thread
            log.exception("gmmap transport: dropping a sample that could not be handled")

    def _from_air(self, message: Message, payload: bytes) -> None:
        # The air's thread: as `_on_sample`; taken once someone subscribes, as a put is.
        if self._data_subscriber is not None and not self._closed:
            self._take(data_key(*message), message, payload)

    def _unicast(self, key: str, timeout: float) -> zenoh.Session:
        """The session a query on ``key`` goes out on: ours, or on a shared channel a second
        one, opened to the peers in ``connect`` by the first query; while its links open, a
        query waits (up to ``timeout`` s) until some peer's answer to ``key`` is declared on it."""
        if self._hearing is None:
            return self._session
        with self._declare_lock:
            if self._repair is None:
                options = replace(self.config.options, listen=())
                self._repair, _ = open_session(self.robot, options)
                self._repair_opened = time.monotonic()
            session = self._repair
        # Its links open in the background, slowly on a slow channel (`handshake_timeout_ms`).
        opening = handshake_timeout_ms(self.config.options.channel_rate) / 1000
        if time.monotonic() > self._repair_opened + opening:
            return session
        deadline = time.monotonic() + timeout
        querier = session.declare_querier(key, allowed_destination=zenoh.Locality.REMOTE)
        try:
            while not querier.matching_status.matching and time.monotonic() < deadline:
                time.sleep(0.05)
        finally:
            querier.undeclare()
        return session

    def talkers(self, window_s: float) -> set[str]:
        """The other robots of the fleet heard on the air (`TransportOptions.broadcast`) in the
        last ``window_s`` s."""
        return set() if self._hearing is None else self._hearing.talkers(window_s)

    def _take(
        self, key: str, parsed: tuple[str, str, str, int] | None, data: zenoh.ZBytes | bytes
    ) -> None:
        """A message of another robot of the fleet (put, broadcast, or told: `tell`): count and
        queue it (a Zenoh payload copied only once it is taken)."""
        if parsed is None or parsed[0] != self.fleet or parsed[1] == self.robot:
            self._counters.bump("ignored")
            return
        _, robot, kind, seq = parsed
        payload = data if isinstance(data, bytes) else data.to_bytes()
        self._counters.add("received", robot, kind, len(payload), len(key.encode()), False)
        self._events.submit(self._deliver, robot, kind, seq, payload)

    def _deliver(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        with self._lock:
            callbacks = list(self._message_callbacks)
        for callback in callbacks:
            call_logged(callback, robot, kind, seq, payload)

    # ---- presence ---------------------------------------------------------------------------

    def on_join(self, callback: PeerCallback) -> None:
        """Call ``callback(robot)`` when another robot of the fleet appears; robots already
        present are reported at once (on the event thread), so no join is missed."""
        self._check_open()
        with self._lock:
            self._join_callbacks.append(callback)
            present = sorted(self._present)
        for robot in present:
            self._events.submit(call_logged, callback, robot)

    def on_leave(self, callback: PeerCallback) -> None:
        """Call ``callback(robot)`` when another robot of the fleet disappears (it closed its
        transport, or its session timed out after Zenoh's lease)."""
        self._check_open()
        with self._lock:
            self._leave_callbacks.append(callback)

    def peers(self) -> list[str]:
        """The other robots of the fleet present now, sorted."""
        with self._lock:
            return sorted(self._present)

    def wait_for_peers(self, robots: Iterable[str], timeout: float) -> bool:
        """Block until all ``robots`` are present (True) or ``timeout`` seconds pass (False)."""
        wanted = set(robots)
        deadline = time.monotonic() + timeout
        with self._present_changed:
            while not wanted <= self._present:
                left = deadline - time.monotonic()
                if left <= 0 or self._closed:
                    return False
                self._present_changed.wait(left)
            return True

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        parts = str(sample.key_expr).split("/")
        if len(parts) != 3 or parts[1] != self.fleet or not NAME_RE.fullmatch(parts[2]):
            return
        robot = parts[2]
        if robot == self.robot:
            return
        self._set_present(robot, sample.kind == zenoh.SampleKind.PUT)

    def _set_present(self, robot: str, present: bool) -> bool:
        """Marks ``robot`` present or gone and runs the join or leave callbacks where that
        changed; whether it did."""
        with self._lock:
            if self._closed or (robot in self._present) == present:
                return False
            (self._present.add if present else self._present.discard)(robot)
            self._present_changed.notify_all()
            callbacks = list(self._join_callbacks if present else self._leave_callbacks)
        for callback in callbacks:
            self._events.submit(call_logged, callback, robot)
        return True

    # ---- accounting -------------------------------------------------------------------------

    def stats(self) -> dict[str, Any]:
        """Byte counters (see the module docstring)::

        {"fleet": ..., "robot": ...,
         "sent":     {robot: {kind: {"messages", "payload_bytes", "key_bytes",
                                     "fetch_messages", "fetch_payload_bytes"}}},
         "received": {robot: {kind: {...}}},
         "totals":   {"sent": {...}, "received": {...}},
         "queries":  {"sent": n, "served": n},
         "ignored":  n}
        """
        return {"fleet": self.fleet, "robot": self.robot, **self._counters.snapshot()}
