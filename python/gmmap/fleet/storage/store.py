"""A robot's embedded store (SQLite): its own and received submaps, edges and small metadata.

Submaps are opaque encoded bytes (the codec's output) keyed by ``(robot, kind, seq)``; the store
never decodes them. Edges are registration results between two submaps, accepted or rejected, so a
restarted robot neither loses its constraints nor re-registers pairs it already judged.

Durability: WAL journal; every write is one transaction, so a crash mid-write leaves the store as
of the last commit. ``durable=True`` (default) also syncs each commit to disk (``synchronous =
FULL``), which survives power loss; ``durable=False`` survives a process crash only and is faster.

Threads: one connection shared under a lock. The node's stages write a few records a second, so
serialising them costs nothing, and one connection keeps every method a plain transaction.

A file that is not a SQLite database, or a database that is not a gmmap store, raises
:class:`StoreFormatError` and is never written to. A store written by a newer gmmap (higher schema
version) raises it too, rather than being misread.
"""

from __future__ import annotations

import contextlib
import math
import sqlite3
import threading
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from types import TracebackType

from gmmap.errors import FileFormatError, GmmapError, InvalidInputError
from gmmap.fleet.storage.records import (
    Edge,
    SubmapRecord,
    _blob_matrix,
    _check_payload,
    _check_seq,
    _check_text,
    _matrix_blob,
    _submap,
)

__all__ = [
    "EDGE_STATUSES",
    "SCHEMA_VERSION",
    "Edge",
    "Store",
    "StoreError",
    "StoreFormatError",
    "SubmapRecord",
]

SCHEMA_VERSION = 1
EDGE_STATUSES = ("accepted", "rejected")
DEFAULT_KIND = "submap"

# application_id marks the file as a gmmap store for tools such as `file` ("gmm1" in ASCII).
_APPLICATION_ID = 0x676D6D31

_SCHEMA = """
CREATE TABLE schema_version (
    version INTEGER NOT NULL
);
CREATE TABLE meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE submaps (
    robot    TEXT    NOT NULL,
    kind     TEXT    NOT NULL,
    seq      INTEGER NOT NULL CHECK (seq >= 0),
    payload  BLOB    NOT NULL,
    own      INTEGER NOT NULL CHECK (own IN (0, 1)),
    received REAL    NOT NULL,
    PRIMARY KEY (robot, kind, seq)
) WITHOUT ROWID;
CREATE TABLE edges (
    id           INTEGER PRIMARY KEY,
    target_robot TEXT    NOT NULL,
    target_seq   INTEGER NOT NULL,
    source_robot TEXT    NOT NULL,
    source_seq   INTEGER NOT NULL,
    transform    BLOB    NOT NULL,
    information  BLOB    NOT NULL,
    confidence   REAL    NOT NULL,
    status       TEXT    NOT NULL CHECK (status IN ('accepted', 'rejected')),
    created      REAL    NOT NULL,
    UNIQUE (target_robot, target_seq, source_robot, source_seq)
);
CREATE INDEX edges_by_source ON edges (source_robot, source_seq);
"""


class StoreError(GmmapError):
    """The store cannot be opened or used (locked, unwritable, closed, …)."""


class StoreFormatError(StoreError, FileFormatError):
    """The file is not a gmmap store: corrupt, another database, or a newer schema version."""


# SQLite result codes (low byte of the extended code) that mean "this file is not a database we
# can read": SQLITE_CORRUPT, SQLITE_NOTADB.
_CORRUPT_CODES = (11, 26)


def _error(path: Path, action: str, err: sqlite3.Error) -> StoreError:
    """The typed error for a SQLite failure: corruption is a format error, the rest (locked,
    read-only, cannot open) a plain store error."""
    code = getattr(err, "sqlite_errorcode", None)  # Python ≥ 3.11
    corrupt = (
        (code & 0xFF) in _CORRUPT_CODES
        if isinstance(code, int)
        else any(word in str(err) for word in ("not a database", "malformed"))
    )
    if corrupt:
        return StoreFormatError(f"{path} is not a usable gmmap store ({action}): {err}")
    return StoreError(f"cannot {action} store {path}: {err}")


class Store:
    """A robot's SQLite store at ``path`` (created when absent). Use as a context manager."""

    def __init__(self, path: str | Path, *, durable: bool = True, timeout: float = 30.0) -> None:
        self.path = Path(path)
        self._lock = threading.RLock()
        try:
            # check_same_thread off: the lock below, not the thread, guards the connection.
            self._conn = sqlite3.connect(
                self.path, timeout=timeout, check_same_thread=False, isolation_level=None
            )
        except sqlite3.Error as err:
            raise StoreError(f"cannot open store {self.path}: {err}") from err
        try:
            self._open(durable)
        except BaseException:
            self._conn.close()
            raise

    # ---- opening ----------------------------------------------------------------------------

    def _open(self, durable: bool) -> None:
        # Read before any write: a corrupt or foreign file must fail here, untouched.
        try:
            tables = {
                row[0]
                for row in self._conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
            }
        except sqlite3.Error as err:
            raise _error(self.path, "open", err) from err
        if tables and "schema_version" not in tables:
            raise StoreFormatError(
                f"{self.path} is a SQLite database but not a gmmap store "
                f"(tables: {', '.join(sorted(tables))}); refusing to modify it"
            )
        try:
            self._conn.execute("PRAGMA journal_mode = WAL")
            self._conn.execute(f"PRAGMA synchronous = {'FULL' if durable else 'NORMAL'}")
            self._conn.execute("PRAGMA foreign_keys = ON")
            if tables:
                self._check_version()
            else:
                self._create()
        except sqlite3.Error as err:
            raise _error(self.path, "open", err) from err

    def _create(self) -> None:
        with self._transaction() as conn:
            # Another process may have created it between our check and this write lock.
            if conn.execute("SELECT 1 FROM sqlite_master WHERE name = 'schema_version'").fetchone():
                return
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    conn.execute(statement)
            conn.execute("INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,))
            conn.execute(f"PRAGMA application_id = {_APPLICATION_ID}")

    def _check_version(self) -> None:
        row = self._conn.execute("SELECT MAX(version) FROM schema_version").fetchone()
        version = row[0] if row else None
        if not isinstance(version, int):
            raise StoreFormatError(f"{self.path}: gmmap store without a schema version")
        if version > SCHEMA_VERSION:
            raise StoreFormatError(
                f"{self.path} has store schema version {version}, newer than this gmmap "
                f"supports ({SCHEMA_VERSION}); upgrade gmmap to open it"
            )
        # Older versions would be migrated here; version 1 is the first.

    @property
    def schema_version(self) -> int:
        with self._lock:
            return int(self._read("SELECT MAX(version) FROM schema_version")[0][0])

    def close(self) -> None:
        """Close the connection (a checkpoint folds the WAL back into the file). Idempotent."""
        with self._lock:
            if self._conn is None:
                return
            with contextlib.suppress(sqlite3.Error):
                self._conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            self._conn.close()
            self._conn = None  # type: ignore[assignment]

    def __enter__(self) -> Store:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ---- plumbing ---------------------------------------------------------------------------

    @contextlib.contextmanager
    def _transaction(self):
        """One write transaction under the lock: committed whole or rolled back whole."""
        with self._lock:
            conn = self._connection()
            try:
                # IMMEDIATE takes the write lock up front, so a busy database waits (timeout)
                # instead of failing half-way through the transaction.
                conn.execute("BEGIN IMMEDIATE")
            except sqlite3.Error as err:
                raise _error(self.path, "write to", err) from err
            try:
                yield conn
            except sqlite3.Error as err:
                with contextlib.suppress(sqlite3.Error):
                    conn.execute("ROLLBACK")
                raise _error(self.path, "write to", err) from err
            except BaseException:
                with contextlib.suppress(sqlite3.Error):
                    conn.execute("ROLLBACK")
                raise
            try:
                conn.execute("COMMIT")
            except sqlite3.Error as err:
                with contextlib.suppress(sqlite3.Error):
                    conn.execute("ROLLBACK")
                raise _error(self.path, "commit to", err) from err

    def _connection(self) -> sqlite3.Connection:
        if self._conn is None:
            raise StoreError(f"store {self.path} is closed")
        return self._conn

    def _read(self, sql: str, params: tuple = ()) -> list[tuple]:
        with self._lock:
            try:
                return self._connection().execute(sql, params).fetchall()
            except sqlite3.Error as err:
                raise _error(self.path, "read", err) from err

    # ---- submaps ----------------------------------------------------------------------------

    def put_submap(
        self,
        robot: str,
        seq: int,
        payload: bytes,
        *,
        kind: str = DEFAULT_KIND,
        own: bool = False,
        received: float | None = None,
        meta: Mapping[str, str] | None = None,
    ) -> bool:
        """Store one message; True when new. Idempotent: an existing (robot, kind, seq) is kept
        as it is (the first copy wins), since every copy of a message carries the same bytes.
        ``meta`` values are set in the same transaction: a robot's own submap and how far its
        input got are stored together or not at all (a crash between them would build that
        submap again after a restart)."""
        items = [(robot, seq, payload)]
        return self.put_submaps(items, kind=kind, own=own, received=received, meta=meta) == 1

    def put_submaps(
        self,
        items: Iterable[tuple[str, int, bytes]],
        *,
        kind: str = DEFAULT_KIND,
        own: bool = False,
        received: float | None = None,
        meta: Mapping[str, str] | None = None,
    ) -> int:
        """Store ``(robot, seq, payload)`` items in one transaction (e.g. a fetch's replies),
        with ``meta`` (see `put_submap`); returns how many were new."""
        _check_text("kind", kind)
        meta_rows = [_meta_row(k, v) for k, v in (meta or {}).items()]
        when = time.time() if received is None else float(received)
        rows = [
            (_check_text("robot", r), kind, _check_seq("seq", s), _check_payload(p), int(own), when)
            for r, s, p in items
        ]
        with self._transaction() as conn:
            before = conn.total_changes
            conn.executemany(
                "INSERT OR IGNORE INTO submaps (robot, kind, seq, payload, own, received) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                rows,
            )
            new = conn.total_changes - before
            conn.executemany(META_UPSERT, meta_rows)
            return new

    def get_submap(self, robot: str, seq: int, kind: str = DEFAULT_KIND) -> SubmapRecord | None:
        """The stored message, or None."""
        rows = self._read(
            "SELECT robot, kind, seq, payload, own, received FROM submaps "
            "WHERE robot = ? AND kind = ? AND seq = ?",
            (robot, kind, _check_seq("seq", seq)),
        )
        return _submap(rows[0]) if rows else None

    def submaps(
        self,
        robot: str | None = None,
        kind: str = DEFAULT_KIND,
        since_seq: int = 0,
        *,
        own: bool | None = None,
    ) -> list[SubmapRecord]:
        """Stored messages of ``kind`` (of one robot, or all), seq ≥ ``since_seq``, ordered by
        robot then seq; ``own`` True/False keeps only this robot's own / received ones."""
        sql = (
            "SELECT robot, kind, seq, payload, own, received FROM submaps "
            "WHERE kind = ? AND seq >= ?"
        )
        params: list[object] = [kind, _check_seq("since_seq", since_seq)]
        if robot is not None:
            sql += " AND robot = ?"
            params.append(robot)
        if own is not None:
            sql += " AND own = ?"
            params.append(int(own))
        return [_submap(row) for row in self._read(sql + " ORDER BY robot, seq", tuple(params))]

    def fetch_provider(self, robot: str, kind: str, since_seq: int) -> list[tuple[int, bytes]]:
        """``(seq, payload)`` held for ``robot`` with seq ≥ since_seq: the transport's provider
        (``transport.serve(store.fetch_provider)``)."""
        rows = self._read(
            "SELECT seq, payload FROM submaps WHERE robot = ? AND kind = ? AND seq >= ? "
            "ORDER BY seq",
            (robot, kind, _check_seq("since_seq", since_seq)),
        )
        return [(int(seq), bytes(payload)) for seq, payload in rows]

    def seqs(self, robot: str, kind: str = DEFAULT_KIND) -> list[int]:
        """The stored sequence numbers of ``robot``, ascending."""
        rows = self._read(
            "SELECT seq FROM submaps WHERE robot = ? AND kind = ? ORDER BY seq", (robot, kind)
        )
        return [int(row[0]) for row in rows]

    def latest_seq(self, robot: str, kind: str = DEFAULT_KIND) -> int | None:
        """The highest stored seq of ``robot`` (a restarted robot continues after its own)."""
        rows = self._read(
            "SELECT MAX(seq) FROM submaps WHERE robot = ? AND kind = ?", (robot, kind)
        )
        return None if rows[0][0] is None else int(rows[0][0])

    def missing(self, robot: str, upto: int, kind: str = DEFAULT_KIND) -> list[int]:
        """The seqs in 0..``upto`` (inclusive) not stored for ``robot``: what to fetch after
        hearing of seq ``upto``."""
        upto = _check_seq("upto", upto)
        have = set(self.seqs(robot, kind))
        return [seq for seq in range(upto + 1) if seq not in have]

    def robots(self) -> list[str]:
        """Robots with at least one stored message, sorted."""
        return [row[0] for row in self._read("SELECT DISTINCT robot FROM submaps ORDER BY robot")]

    def count(self, robot: str | None = None, kind: str | None = None) -> int:
        """How many messages are stored (optionally of one robot and/or kind)."""
        sql, params = "SELECT COUNT(*) FROM submaps WHERE 1 = 1", []
        if robot is not None:
            sql, params = sql + " AND robot = ?", [*params, robot]
        if kind is not None:
            sql, params = sql + " AND kind = ?", [*params, kind]
        return int(self._read(sql, tuple(params))[0][0])

    # ---- edges ------------------------------------------------------------------------------

    def put_edge(self, edge: Edge) -> int:
        """Store an edge and return its id. One edge per (target, source) submap pair: a later
        decision on the same pair replaces the earlier one (same id)."""
        row = _edge_row(edge)
        with self._transaction() as conn:
            conn.execute(EDGE_UPSERT, row)
            found = conn.execute(
                "SELECT id FROM edges WHERE target_robot = ? AND target_seq = ? "
                "AND source_robot = ? AND source_seq = ?",
                row[:4],
            ).fetchone()
            return int(found[0])

    def replace_edges(self, edges: Iterable[Edge]) -> None:
        """All stored edges become ``edges``, in one transaction (a mapper's judgements redone
        over everything held)."""
        rows = [_edge_row(e) for e in edges]
        with self._transaction() as conn:
            conn.execute("DELETE FROM edges")
            conn.executemany(EDGE_UPSERT, rows)

    def edges(self, status: str | None = None, robot: str | None = None) -> list[Edge]:
        """Stored edges in insertion order; ``status`` filters accepted/rejected, ``robot`` keeps
        edges touching that robot (as target or source)."""
        sql = (
            "SELECT target_robot, target_seq, source_robot, source_seq, transform, information, "
            "confidence, status, id, created FROM edges WHERE 1 = 1"
        )
        params: list[object] = []
        if status is not None:
            if status not in EDGE_STATUSES:
                raise InvalidInputError(f"status must be one of {EDGE_STATUSES}; got {status!r}")
            sql += " AND status = ?"
            params.append(status)
        if robot is not None:
            sql += " AND (target_robot = ? OR source_robot = ?)"
            params += [robot, robot]
        return [
            Edge(
                target_robot=tr,
                target_seq=int(ts),
                source_robot=sr,
                source_seq=int(ss),
                transform=_blob_matrix(t, 4),
                information=_blob_matrix(info, 6),
                confidence=float(conf),
                status=st,
                id=int(eid),
                created=float(created),
            )
            for tr, ts, sr, ss, t, info, conf, st, eid, created in self._read(
                sql + " ORDER BY id", tuple(params)
            )
        ]

    # ---- meta -------------------------------------------------------------------------------

    def set_meta(self, key: str, value: str) -> None:
        """Set a small text value (robot name, fleet, last fetched seq…)."""
        row = _meta_row(key, value)
        with self._transaction() as conn:
            conn.execute(META_UPSERT, row)

    def get_meta(self, key: str, default: str | None = None) -> str | None:
        rows = self._read("SELECT value FROM meta WHERE key = ?", (key,))
        return rows[0][0] if rows else default

    def meta(self) -> dict[str, str]:
        return dict(self._read("SELECT key, value FROM meta ORDER BY key"))


META_UPSERT = (
    "INSERT INTO meta (key, value) VALUES (?, ?) "
    "ON CONFLICT (key) DO UPDATE SET value = excluded.value"
)


def _meta_row(key: str, value: str) -> tuple[str, str]:
    _check_text("meta key", key)
    if not isinstance(value, str):
        raise InvalidInputError(f"meta value must be a string; got {type(value).__name__}")
    return key, value


EDGE_UPSERT = (
    "INSERT INTO edges (target_robot, target_seq, source_robot, source_seq, transform, "
    "information, confidence, status, created) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) "
    "ON CONFLICT (target_robot, target_seq, source_robot, source_seq) DO UPDATE SET "
    "transform = excluded.transform, information = excluded.information, "
    "confidence = excluded.confidence, status = excluded.status, created = excluded.created"
)


def _edge_row(edge: Edge) -> tuple:
    if edge.status not in EDGE_STATUSES:
        raise InvalidInputError(f"edge status must be one of {EDGE_STATUSES}; got {edge.status!r}")
    confidence = float(edge.confidence)
    if not (math.isfinite(confidence) and 0.0 <= confidence <= 1.0):
        raise InvalidInputError(f"edge confidence must be in [0, 1]; got {edge.confidence!r}")
    return (
        _check_text("target_robot", edge.target_robot),
        _check_seq("target_seq", edge.target_seq),
        _check_text("source_robot", edge.source_robot),
        _check_seq("source_seq", edge.source_seq),
        _matrix_blob("transform", edge.transform, 4),
        _matrix_blob("information", edge.information, 6),
        confidence,
        edge.status,
        time.time() if edge.created is None else float(edge.created),
    )
