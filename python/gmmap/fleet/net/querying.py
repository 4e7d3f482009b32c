"""The query side of `gmmap.fleet.net.transport.Transport` (a mixin of it, on its session, counters
and workers): answering fetches from the store (`Querying.serve`), fetching (`Querying.fetch`,
`Querying.fetch_unknown`) and telling one peer alone (`Querying.tell`). The key expressions are
in the transport's module docstring.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable
from typing import Any

import zenoh

from gmmap.errors import TransportConfigError, TransportError
from gmmap.fleet.net.counters import Counters
from gmmap.fleet.net.keys import (
    as_payload,
    check_seq,
    fetch_selector,
    parse_fetch,
    parse_reply_key,
    queryable_key,
    reply_key,
)
from gmmap.fleet.net.outbox import Budget
from gmmap.fleet.net.worker import Worker
from gmmap.names import check_name

log = logging.getLogger(__name__)

DEFAULT_KIND = "submap"

FetchProvider = Callable[[str, str, int], Iterable[tuple[int, bytes]]]
"""``provider(robot, kind, since_seq)`` → the held ``(seq, payload)`` pairs with seq ≥ since_seq."""
Roster = Callable[[], Iterable[str]]
"""``roster()`` → the robots whose messages are held."""


class Querying:
    """Fetch and tell over the transport's session (`gmmap.fleet.net.transport.Transport`, which
    sets these attributes and defines ``_check_open``, ``peers``, ``_take``, ``_broadcast``,
    ``_aired_lately`` and ``_unicast``)."""

    fleet: str
    robot: str
    config: Any  # TransportConfig
    _session: zenoh.Session
    _counters: Counters
    _lock: threading.Lock
    _declare_lock: threading.Lock
    _queries: Worker
    _closed: bool
    _provider: FetchProvider | None
    _roster: Roster | None
    _budget: Budget
    _queryable: Any
    _broadcast: Callable[[str, int, bytes | bytearray | memoryview], bool]
    _aired_lately: Callable[[str, int], bool]
    _hearing: Any  # on a shared channel, `gmmap.fleet.net.hearing.Hearing`; else None
    _unicast: Callable[[str, float], zenoh.Session]

    def tell(self, peer: str, kind: str, seq: int, payload: bytes | bytearray | memoryview) -> None:
        """Send ``payload`` as `publish` does, to ``peer`` alone (its queryable, `serve`), and
        do not wait for the empty answer."""
        self._check_open()
        check_name("peer", peer)
        check_name("kind", kind)
        data = as_payload(payload)
        key = reply_key(self.fleet, self.robot, kind, check_seq(seq), peer)
        if self._broadcast(kind, seq, data):  # on a shared channel the others hear it too
            self._counters.add("sent", self.robot, kind, len(data), len(key.encode()), False)
            return
        timeout = self.config.options.fetch_timeout
        try:
            self._unicast(key, timeout).get(
                key,
                lambda _reply: None,
                target=zenoh.QueryTarget.ALL,
                payload=data,
                timeout=timeout,
                congestion_control=zenoh.CongestionControl.BLOCK,
                allowed_destination=zenoh.Locality.REMOTE,
            )
        except zenoh.ZError as err:
            raise TransportError(f"cannot tell {key}: {err}") from err
        self._counters.add("sent", self.robot, kind, len(data), len(key.encode()), False)

    # ---- fetch ------------------------------------------------------------------------------

    def serve(
        self, provider: FetchProvider, roster: Roster | None = None, budget: Budget | None = None
    ) -> None:
        """Answer other robots' fetch queries with ``provider(robot, kind, since_seq)``, which
        returns the ``(seq, payload)`` pairs held (own or received) with seq ≥ since_seq, and,
        with ``roster()`` (the robots held), `fetch_unknown` queries, each reply within
        ``budget``. It runs on the transport's query thread. Calling again replaces all."""
        self._check_open()
        if not callable(provider):
            raise TransportConfigError(f"provider must be callable; got {provider!r}")
        if roster is not None and not callable(roster):
            raise TransportConfigError(f"roster must be callable; got {roster!r}")
        with self._lock:
            self._provider, self._roster, self._budget = provider, roster, budget or Budget(None)
        with self._declare_lock:
            if self._queryable is not None:
                return
            self._queryable = self._session.declare_queryable(
                queryable_key(self.fleet, self.robot),
                self._on_query,
                complete=False,
                allowed_origin=zenoh.Locality.REMOTE,
            )

    def _on_query(self, query: zenoh.Query) -> None:
        # Zenoh thread: keep the query object alive and answer it on the query worker.
        self._queries.submit(self._answer, query)

    def _answer(self, query: zenoh.Query) -> None:
        try:
            key = str(query.key_expr)
            if query.payload is not None:  # a message told to us alone
                if not self._closed:
                    self._take(key, parse_reply_key(key), query.payload)
                return
            request = parse_fetch(key, query.parameters)
            if request is None or request.fleet != self.fleet:
                self._counters.bump("ignored")
                return
            robot, kind = request.robot, request.kind
            with self._lock:
                provider, roster, budget = self._provider, self._roster, self._budget
            if provider is None or self._closed:
                return
            self._counters.bump("queries_served")
            try:
                every = roster() if roster and robot == "*" else ()  # fetch_unknown
                robots = sorted(set(every) - request.skip) if robot == "*" else [robot]
                found = [(r, s, p) for r in robots for s, p in provider(r, kind, request.since)]
            except Exception as err:
                log.exception("gmmap transport: fetch provider failed for %s/%s", robot, kind)
                query.reply_err(f"provider failed: {err}".encode())
                return
            found = sorted(h for h in found if request.wants(h[1]))
            for r, seq, payload in found:  # oldest first: a fetch cut short resumes at its gap
                data, key = as_payload(payload), reply_key(self.fleet, r, kind, seq, self.robot)
                # Where the asker hears a shared channel, our own messages go on the air again,
                # once for all the robots that missed them: they hear them as they heard us.
                own = r == self.robot and request.air
                if own and self._aired_lately(kind, seq):
                    continue
                if not budget.take(len(data) + len(key.encode()), lambda: self._closed):
                    return
                if own and self._broadcast(kind, seq, data):
                    self._counters.add("sent", r, kind, len(data), len(key.encode()), True)
                    continue
                query.reply(key, data)
                self._counters.add("sent", r, kind, len(data), len(key.encode()), True)
        finally:
            # Finalises the query: the requester's get() ends without waiting for its timeout.
            try:
                query.drop()
            except Exception:  # already finalised by Zenoh (the session closing): harmless
                log.debug("dropping a fetch query failed", exc_info=True)

    def fetch(
        self,
        robot: str,
        kind: str = DEFAULT_KIND,
        since_seq: int = 0,
        timeout: float | None = None,
        relay: bool = False,
        via: str | None = None,
        held: Iterable[int] = (),
    ) -> list[tuple[int, bytes]]:
        """Ask ``robot`` for its messages of ``kind`` with seq ≥ ``since_seq``, but those
        ``held`` already; or, with ``relay`` (or where ``robot`` is not present), the robots in
        between: ``via`` alone where given, else every peer holding them. Returns ``(seq,
        payload)`` sorted by seq, the first reply per seq winning, of what arrived within
        ``timeout`` s (default ``config.fetch_timeout``); no peer serving gives an empty list.
        On a shared channel a robot asked for its own messages puts them on the air instead
        (where both hear it): they come to the `subscribe` callbacks, for every robot that
        missed them."""
        self._check_open()
        check_name("robot", robot)
        check_name("kind", kind)
        check_seq(since_seq, "since_seq")
        if via is not None:
            check_name("via", via)
        else:
            via = "*" if relay or robot not in self.peers() else robot
        air = self._hearing is not None
        found = self._query(
            fetch_selector(self.fleet, robot, kind, via, since_seq, held, air=air),
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
            fetch_selector(self.fleet, "*", kind, "*", skip=skip),
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
            replies = self._unicast(selector.partition("?")[0], timeout).get(
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
            if (sample := reply.ok) is None:
                why = reply.err.payload.to_bytes().decode(errors="replace")  # "Timeout"
                log.warning("gmmap transport: a peer failed to answer %s: %s", selector, why)
                continue
            key = str(sample.key_expr)
            parsed = parse_reply_key(key)
            if parsed is None or not accept(parsed):
                self._counters.bump("ignored")
                continue
            _, robot, kind, seq = parsed
            payload = sample.payload.to_bytes()
            self._counters.add("received", robot, kind, len(payload), len(key.encode()), True)
            found.setdefault((robot, seq), payload)
        return found
