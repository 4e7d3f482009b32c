"""Fleet transport over Zenoh: robots exchange opaque encoded submaps (bytes) and nothing else.

Key expressions (``<fleet>``, ``<robot>``, ``<kind>`` are names, ``<seq>`` a decimal integer ≥ 0)::

    gmmap/<fleet>/<robot>/<kind>/<seq>     one message (a put); payload = the encoded bytes
    gmmap/<fleet>/<robot>                  liveliness token: the robot is present
    gmmap/<fleet>/<robot>/<kind>/*?since=N fetch query: everything of that robot and kind, seq ≥ N
    gmmap/<fleet>/*/<kind>/*?since=0;skip=a,b  every robot held but a and b (`fetch_unknown`)

Every robot that called :meth:`Transport.serve` answers fetch queries from its provider (its
store), for its own data and for other robots' data it holds, so a robot that was away can catch
up from whoever is present. Replies use the message key expressions above.

Byte accounting (:meth:`Transport.stats`): per data robot and per kind, in each direction,

- ``messages``, ``payload_bytes``: every message and its payload (the encoded submap), published
  or received by subscription, plus fetch replies served or received;
- ``key_bytes``: the UTF-8 length of each message's key expression (the application-level
  overhead of naming the message);
- ``fetch_messages``, ``fetch_payload_bytes``: the part of the above that travelled as fetch
  replies.

Not counted: Zenoh's framing, TCP/IP headers, liveliness and query control traffic (the Python
API does not expose them). Received messages are counted once accepted (right fleet, another
robot, well-formed key); dropped ones only increment ``ignored``.

Presence: a robot that closes its transport leaves at once; one that dies leaves when Zenoh's
lease expires (10 s by default). Two live sessions with one robot name count as one robot (Zenoh
merges identical tokens) and see each other's messages as their own: names must be unique.

Callbacks run on Zenoh's threads, which must never be blocked for long: they only parse, count and
hand each event to a queue. One worker thread runs the user's message and join/leave callbacks in
arrival order, another answers fetch queries, so a slow provider never delays messages.
"""

from __future__ import annotations

import contextlib
import json
import logging
import queue
import socket
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from types import TracebackType
from typing import Any

import zenoh

from gmmap.errors import TransportConfigError, TransportError
from gmmap.options import NAME_RE, TransportOptions, check_name

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

PREFIX = "gmmap"
DEFAULT_KIND = "submap"

MessageCallback = Callable[[str, str, int, bytes], None]
"""``callback(robot, kind, seq, payload)`` for a message of another robot of the fleet."""
PeerCallback = Callable[[str], None]
"""``callback(robot)`` when a robot of the fleet joins or leaves."""
FetchProvider = Callable[[str, str, int], Iterable[tuple[int, bytes]]]
"""``provider(robot, kind, since_seq)`` → the held ``(seq, payload)`` pairs with seq ≥ since_seq."""
Roster = Callable[[], Iterable[str]]
"""``roster()`` → the robots whose messages are held."""


@dataclass(frozen=True)
class TransportConfig:
    """A robot's name in its fleet and its transport options."""

    fleet: str
    robot: str
    options: TransportOptions = field(default_factory=TransportOptions)

    def __post_init__(self) -> None:
        check_name("fleet", self.fleet)
        check_name("robot", self.robot)


def _check_seq(seq: object, what: str = "seq") -> int:
    # bool is an int subclass; True as a sequence number is a bug, not a 1.
    if isinstance(seq, bool) or not isinstance(seq, int) or seq < 0:
        raise TransportConfigError(f"{what} must be an integer ≥ 0; got {seq!r}")
    return seq


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (the OS picks it; another process may still race)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def data_key(fleet: str, robot: str, kind: str, seq: int) -> str:
    """The key expression of one message: ``gmmap/<fleet>/<robot>/<kind>/<seq>``."""
    return f"{PREFIX}/{fleet}/{robot}/{kind}/{seq}"


def alive_key(fleet: str, robot: str) -> str:
    """The liveliness token of a robot: ``gmmap/<fleet>/<robot>``."""
    return f"{PREFIX}/{fleet}/{robot}"


def parse_data_key(key: str) -> tuple[str, str, str, int] | None:
    """``(fleet, robot, kind, seq)`` of a message key expression, or None when malformed."""
    parts = str(key).split("/")
    if len(parts) != 5 or parts[0] != PREFIX:
        return None
    _, fleet, robot, kind, seq_text = parts
    if not all(NAME_RE.fullmatch(name) for name in (fleet, robot, kind)):
        return None
    # Canonical decimal only: "007" or "+7" would give two keys for one message.
    if not seq_text.isdigit() or str(int(seq_text)) != seq_text:
        return None
    return fleet, robot, kind, int(seq_text)


@dataclass
class ByteCount:
    """Messages and bytes of one (direction, robot, kind); fetch_* are the fetch-reply part."""

    messages: int = 0
    payload_bytes: int = 0
    key_bytes: int = 0
    fetch_messages: int = 0
    fetch_payload_bytes: int = 0

    def add(self, payload: int, key: int, fetched: bool) -> None:
        self.messages += 1
        self.payload_bytes += payload
        self.key_bytes += key
        if fetched:
            self.fetch_messages += 1
            self.fetch_payload_bytes += payload

    def merge(self, other: ByteCount) -> None:
        for name, value in asdict(other).items():
            setattr(self, name, getattr(self, name) + value)


class _Counters:
    """Thread-safe byte counters; Zenoh callbacks and user threads update them concurrently."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[tuple[str, str, str], ByteCount] = {}
        self.queries_sent = 0
        self.queries_served = 0
        self.ignored = 0

    def add(self, direction: str, robot: str, kind: str, payload: int, key: int, fetched: bool):
        with self._lock:
            self._counts.setdefault((direction, robot, kind), ByteCount()).add(
                payload, key, fetched
            )

    def bump(self, name: str) -> None:
        with self._lock:
            setattr(self, name, getattr(self, name) + 1)

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            out: dict[str, Any] = {"sent": {}, "received": {}}
            totals = {"sent": ByteCount(), "received": ByteCount()}
            for (direction, robot, kind), count in sorted(self._counts.items()):
                out[direction].setdefault(robot, {})[kind] = asdict(count)
                totals[direction].merge(count)
            out["totals"] = {d: asdict(c) for d, c in totals.items()}
            out["queries"] = {"sent": self.queries_sent, "served": self.queries_served}
            out["ignored"] = self.ignored
            return out


_STOP = object()


class _Worker:
    """A daemon thread running queued calls in order; a failing call is logged, never fatal."""

    def __init__(self, name: str) -> None:
        self._queue: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> None:
        self._queue.put((fn, args))

    def stop(self, timeout: float = 5.0) -> None:
        self._queue.put(_STOP)
        # A callback that closes the transport runs on this very thread: joining would deadlock.
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is _STOP:
                return
            fn, args = item
            try:
                fn(*args)
            except Exception:
                log.exception("gmmap transport callback %r failed", fn)


class Transport:
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
        self.listen_endpoints: tuple[str, ...] = ()
        self._counters = _Counters()
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
        self._data_subscriber: Any = None
        self._queryable: Any = None
        self._probes: dict[str, zenoh.Publisher] = {}
        self._closed = False
        self._session = self._open_session()
        self._events = _Worker(f"gmmap-transport-events-{self.robot}")
        self._queries = _Worker(f"gmmap-transport-queries-{self.robot}")
        try:
            liveliness = self._session.liveliness()
            self._token = liveliness.declare_token(alive_key(self.fleet, self.robot))
            self._alive_subscriber = liveliness.declare_subscriber(
                f"{PREFIX}/{self.fleet}/*", self._on_liveliness, history=True
            )
        except zenoh.ZError as err:
            self.close()
            raise TransportError(f"cannot declare liveliness for {self.robot!r}: {err}") from err

    # ---- session ----------------------------------------------------------------------------

    def _zenoh_config(self) -> zenoh.Config:
        cfg = zenoh.Config()
        entries: dict[str, Any] = {
            "mode": self.config.options.mode,
            "listen/endpoints": list(self.listen_endpoints),
            "connect/endpoints": list(self.config.options.connect),
            "scouting/multicast/enabled": self.config.options.multicast_scouting,
        }
        entries.update(self.config.options.zenoh_options)
        for key, value in entries.items():
            try:
                cfg.insert_json5(key, json.dumps(value))
            except (zenoh.ZError, TypeError, ValueError) as err:
                raise TransportConfigError(f"bad Zenoh option {key}={value!r}: {err}") from err
        return cfg

    def _open_session(self) -> zenoh.Session:
        # A port we pick ourselves may be taken between free_port() and Zenoh's bind: retry.
        attempts = 3 if self.config.options.listen is None and self.config.options.port == 0 else 1
        for attempt in range(attempts):
            self.listen_endpoints = (
                self.config.options.listen
                if self.config.options.listen is not None  # () listens nowhere (connects only)
                else (f"tcp/127.0.0.1:{self.config.options.port or free_port()}",)
            )
            try:
                return zenoh.open(self._zenoh_config())
            except zenoh.ZError as err:
                if attempt + 1 == attempts:
                    raise TransportError(
                        f"cannot open the Zenoh session of robot {self.robot!r} (listen "
                        f"{list(self.listen_endpoints)}, connect "
                        f"{list(self.config.options.connect)}): "
                        f"{err}"
                    ) from err
        raise AssertionError("unreachable")

    def __enter__(self) -> Transport:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
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
        with contextlib.suppress(zenoh.ZError):
            self._session.close()
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
        _check_seq(seq)
        data = _as_bytes(payload)
        key = data_key(self.fleet, self.robot, kind, seq)
        try:
            self._session.put(key, data, congestion_control=zenoh.CongestionControl.BLOCK)
        except zenoh.ZError as err:
            raise TransportError(f"cannot publish {key}: {err}") from err
        self._counters.add("sent", self.robot, kind, len(data), len(key.encode()), False)

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
            parsed = parse_data_key(key)
            if (
                parsed is None
                or sample.kind != zenoh.SampleKind.PUT
                or parsed[0] != self.fleet
                or parsed[1] == self.robot
            ):
                self._counters.bump("ignored")
                return
            _, robot, kind, seq = parsed
            payload = sample.payload.to_bytes()
            self._counters.add("received", robot, kind, len(payload), len(key.encode()), False)
            self._events.submit(self._deliver, robot, kind, seq, payload)
        except Exception:  # never let a bad sample take down Zenoh's callback thread
            log.exception("gmmap transport: dropping a sample that could not be handled")

    def _deliver(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        with self._lock:
            callbacks = list(self._message_callbacks)
        for callback in callbacks:
            _call_logged(callback, robot, kind, seq, payload)

    # ---- presence ---------------------------------------------------------------------------

    def on_join(self, callback: PeerCallback) -> None:
        """Call ``callback(robot)`` when another robot of the fleet appears; robots already
        present are reported at once (on the event thread), so no join is missed."""
        self._check_open()
        with self._lock:
            self._join_callbacks.append(callback)
            present = sorted(self._present)
        for robot in present:
            self._events.submit(_call_logged, callback, robot)

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
        joined = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            if self._closed or (robot in self._present) == joined:
                return
            (self._present.add if joined else self._present.discard)(robot)
            self._present_changed.notify_all()
            callbacks = list(self._join_callbacks if joined else self._leave_callbacks)
        for callback in callbacks:
            self._events.submit(_call_logged, callback, robot)

    # ---- fetch ------------------------------------------------------------------------------

    def serve(self, provider: FetchProvider, roster: Roster | None = None) -> None:
        """Answer other robots' fetch queries with ``provider(robot, kind, since_seq)``, which
        returns the ``(seq, payload)`` pairs held (own or received) with seq ≥ since_seq, and,
        with ``roster()`` (the robots held), `fetch_unknown` queries. It runs on the
        transport's query thread. Calling again replaces both."""
        self._check_open()
        if not callable(provider):
            raise TransportConfigError(f"provider must be callable; got {provider!r}")
        if roster is not None and not callable(roster):
            raise TransportConfigError(f"roster must be callable; got {roster!r}")
        with self._lock:
            self._provider, self._roster = provider, roster
        with self._declare_lock:
            if self._queryable is not None:
                return
            self._queryable = self._session.declare_queryable(
                f"{PREFIX}/{self.fleet}/*/*/*",
                self._on_query,
                complete=False,
                allowed_origin=zenoh.Locality.REMOTE,
            )

    def _on_query(self, query: zenoh.Query) -> None:
        # Zenoh thread: keep the query object alive and answer it on the query worker.
        self._queries.submit(self._answer, query)

    def _answer(self, query: zenoh.Query) -> None:
        try:
            request = _parse_fetch(str(query.key_expr), query.parameters.get("since"))
            if request is None or request[0] != self.fleet:
                self._counters.bump("ignored")
                return
            _, robot, kind, since = request
            with self._lock:
                provider, roster = self._provider, self._roster
            if provider is None or self._closed:
                return
            self._counters.bump("queries_served")
            try:
                if robot == "*":  # fetch_unknown: every robot held but those named in skip
                    skip = set(query.parameters.get("skip", "").split(","))
                    robots = sorted(set(roster() if roster else ()) - skip - {""})
                else:
                    robots = [robot]
                held = [(r, seq, p) for r in robots for seq, p in provider(r, kind, since)]
            except Exception as err:
                log.exception("gmmap transport: fetch provider failed for %s/%s", robot, kind)
                query.reply_err(f"provider failed: {err}".encode())
                return
            for r, seq, payload in held:
                if not isinstance(seq, int) or seq < since:
                    continue
                data = _as_bytes(payload)
                key = data_key(self.fleet, r, kind, seq)
                query.reply(key, data)
                self._counters.add("sent", r, kind, len(data), len(key.encode()), True)
        finally:
            # Finalises the query: the requester's get() ends without waiting for its timeout.
            with contextlib.suppress(Exception):
                query.drop()

    def fetch(
        self,
        robot: str,
        kind: str = DEFAULT_KIND,
        since_seq: int = 0,
        timeout: float | None = None,
    ) -> list[tuple[int, bytes]]:
        """Ask the present peers for ``robot``'s messages of ``kind`` with seq ≥ ``since_seq``.

        Returns ``(seq, payload)`` sorted by seq, one per seq (the first reply wins when several
        peers hold it). Waits at most ``timeout`` seconds (default ``config.fetch_timeout``) and
        returns what arrived by then; no peer serving gives an empty list.
        """
        self._check_open()
        check_name("robot", robot)
        check_name("kind", kind)
        _check_seq(since_seq, "since_seq")
        found = self._query(
            f"{PREFIX}/{self.fleet}/{robot}/{kind}/*?since={since_seq}",
            timeout,
            lambda p: p[:3] == (self.fleet, robot, kind) and p[3] >= since_seq,
        )
        return sorted((seq, payload) for (_, seq), payload in found.items())

    def fetch_unknown(
        self, known: Iterable[str], kind: str = DEFAULT_KIND, timeout: float | None = None
    ) -> dict[str, list[tuple[int, bytes]]]:
        """Ask the present peers for the messages of ``kind`` of every robot not in ``known``:
        how a robot that joins late learns of robots that left before it came. Returns
        ``{robot: [(seq, payload)]}`` sorted by seq, the first reply per message winning."""
        self._check_open()
        check_name("kind", kind)
        skip = sorted({check_name("robot", r) for r in known})
        found = self._query(
            f"{PREFIX}/{self.fleet}/*/{kind}/*?since=0;skip={','.join(skip)}",
            timeout,
            lambda p: p[0] == self.fleet and p[2] == kind and p[1] not in skip,
        )
        out: dict[str, list[tuple[int, bytes]]] = {}
        for (robot, seq), payload in sorted(found.items()):
            out.setdefault(robot, []).append((seq, payload))
        return out

    def _query(
        self,
        selector: str,
        timeout: float | None,
        accept: Callable[[tuple[str, str, str, int]], bool],
    ) -> dict[tuple[str, int], bytes]:
        """Sends a fetch query and keeps the first reply per (robot, seq) whose key ``accept``
        takes, counting each as received."""
        timeout = self.config.options.fetch_timeout if timeout is None else float(timeout)
        if not timeout > 0:
            raise TransportConfigError(f"timeout must be > 0 s; got {timeout!r}")
        self._counters.bump("queries_sent")
        try:
            replies = self._session.get(
                selector,
                target=zenoh.QueryTarget.ALL,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=timeout,
                allowed_destination=zenoh.Locality.REMOTE,
            )
        except zenoh.ZError as err:
            raise TransportError(f"cannot query {selector}: {err}") from err
        found: dict[tuple[str, int], bytes] = {}
        for reply in replies:
            sample = reply.ok
            if sample is None:
                log.warning("gmmap transport: a peer failed to answer %s: %s", selector, reply.err)
                continue
            key = str(sample.key_expr)
            parsed = parse_data_key(key)
            if parsed is None or not accept(parsed):
                self._counters.bump("ignored")
                continue
            _, robot, kind, seq = parsed
            payload = sample.payload.to_bytes()
            self._counters.add("received", robot, kind, len(payload), len(key.encode()), True)
            found.setdefault((robot, seq), payload)
        return found

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


def _parse_fetch(key: str, since: str | None) -> tuple[str, str, str, int] | None:
    """``(fleet, robot, kind, since)`` of a fetch query ``gmmap/<fleet>/<robot>/<kind>/*``;
    robot ``*`` for `fetch_unknown`."""
    parts = key.split("/")
    if len(parts) != 5 or parts[0] != PREFIX or parts[4] != "*":
        return None
    _, fleet, robot, kind, _ = parts
    names = (fleet, kind) if robot == "*" else (fleet, robot, kind)
    if not all(NAME_RE.fullmatch(name) for name in names):
        return None
    since_text = "0" if since is None else since
    if not since_text.isdigit():
        return None
    return fleet, robot, kind, int(since_text)


def _as_bytes(payload: object) -> bytes:
    if isinstance(payload, bytes):
        return payload
    if isinstance(payload, (bytearray, memoryview)):
        return bytes(payload)
    raise TransportConfigError(f"payload must be bytes; got {type(payload).__name__}")


def _call_logged(callback: Callable[..., Any], *args: Any) -> None:
    try:
        callback(*args)
    except Exception:
        log.exception("gmmap transport: callback %r failed", callback)
