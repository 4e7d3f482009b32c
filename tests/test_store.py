import os
import sqlite3
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from gmmap.errors import FileFormatError, GmmapError, InvalidInputError
from gmmap.fleet.storage.store import SCHEMA_VERSION, Edge, Store, StoreError, StoreFormatError


def _edge(target_seq=0, source_seq=1, status="accepted", confidence=0.8, shift=1.0) -> Edge:
    transform = np.eye(4)
    transform[:3, 3] = [shift, -2.0, 0.5]
    information = np.diag([100.0, 100.0, 100.0, 400.0, 400.0, 400.0])
    return Edge("a", target_seq, "b", source_seq, transform, information, confidence, status)


def test_submap_round_trip_and_queries(tmp_path: Path):
    with Store(tmp_path / "robot.db") as store:
        assert store.schema_version == SCHEMA_VERSION
        assert store.put_submap("a", 0, b"\x00own", own=True)
        assert store.put_submap("a", 2, bytearray(b"two"), own=True)
        assert store.put_submap("b", 1, b"from b", received=123.5)
        assert store.put_submap("b", 1, b"other", kind="descriptor")
        # Idempotent: the same key again is not new, and the first copy is kept.
        assert not store.put_submap("b", 1, b"duplicate")

        rec = store.get_submap("b", 1)
        assert (rec.robot, rec.kind, rec.seq, rec.payload, rec.own, rec.received) == (
            "b",
            "submap",
            1,
            b"from b",
            False,
            123.5,
        )
        assert store.get_submap("b", 1, kind="descriptor").payload == b"other"
        assert store.get_submap("c", 0) is None

        assert [(r.robot, r.seq) for r in store.submaps()] == [("a", 0), ("a", 2), ("b", 1)]
        assert [r.seq for r in store.submaps("a", since_seq=1)] == [2]
        assert [r.robot for r in store.submaps(own=False)] == ["b"]
        assert store.fetch_provider("a", "submap", 1) == [(2, b"two")]
        assert store.seqs("a") == [0, 2]
        assert store.missing("a", 4) == [1, 3, 4]
        assert store.missing("c", 1) == [0, 1]
        assert store.latest_seq("a") == 2 and store.latest_seq("c") is None
        assert store.robots() == ["a", "b"]
        assert store.count() == 4 and store.count("b") == 2 and store.count(kind="submap") == 3

        assert store.put_submaps([("c", 0, b"x"), ("c", 1, b"y"), ("a", 0, b"z")]) == 2


def test_bad_arguments_raise_typed_errors(tmp_path: Path):
    with Store(tmp_path / "robot.db") as store:
        for args in [("", 0, b"x"), ("a", -1, b"x"), ("a", True, b"x"), ("a", 0, "text")]:
            with pytest.raises(InvalidInputError):
                store.put_submap(*args)
        # A batch with one bad item stores nothing.
        with pytest.raises(InvalidInputError):
            store.put_submaps([("a", 0, b"ok"), ("a", 1, None)])
        assert store.count() == 0
        with pytest.raises(InvalidInputError):
            store.put_edge(_edge(status="maybe"))
        with pytest.raises(InvalidInputError):
            store.put_edge(_edge(confidence=1.5))
        bad = _edge()
        with pytest.raises(InvalidInputError):
            store.put_edge(Edge("a", 0, "b", 1, np.eye(3), bad.information, 0.5))
        with pytest.raises(InvalidInputError):
            store.put_edge(Edge("a", 0, "b", 1, bad.transform, np.full((6, 6), np.nan), 0.5))


def test_edges_round_trip_and_replace(tmp_path: Path):
    with Store(tmp_path / "robot.db") as store:
        first = store.put_edge(_edge(0, 1))
        second = store.put_edge(_edge(3, 4, status="rejected", confidence=0.1))
        assert first != second
        edges = store.edges()
        assert [(e.target_seq, e.source_seq, e.status) for e in edges] == [
            (0, 1, "accepted"),
            (3, 4, "rejected"),
        ]
        np.testing.assert_array_equal(edges[0].transform, _edge().transform)
        np.testing.assert_array_equal(edges[0].information, _edge().information)
        assert edges[0].confidence == 0.8 and edges[0].id == first and edges[0].created > 0
        # A later decision on the same pair replaces the earlier one.
        assert store.put_edge(_edge(0, 1, status="rejected", confidence=0.3, shift=5.0)) == first
        assert len(store.edges()) == 2
        assert [e.target_seq for e in store.edges(status="rejected")] == [0, 3]
        assert store.edges(status="accepted") == []
        assert store.edges(status="rejected")[0].transform[0, 3] == 5.0
        assert len(store.edges(robot="b")) == 2 and store.edges(robot="c") == []


def test_meta(tmp_path: Path):
    with Store(tmp_path / "robot.db") as store:
        assert store.get_meta("robot") is None and store.get_meta("robot", "x") == "x"
        store.set_meta("robot", "a")
        store.set_meta("robot", "b")
        store.set_meta("fleet", "lab")
        assert store.meta() == {"fleet": "lab", "robot": "b"}
        with pytest.raises(InvalidInputError):
            store.set_meta("n", 3)
        # A submap and how far the input got go in together, or neither does.
        assert store.put_submap("a", 0, b"s0", own=True, meta={"frames": "20"})
        assert store.get_meta("frames") == "20"
        with pytest.raises(InvalidInputError):
            store.put_submap("a", 1, b"s1", own=True, meta={"frames": 40})
        assert store.seqs("a") == [0] and store.get_meta("frames") == "20"


def test_restart_keeps_everything(tmp_path: Path):
    path = tmp_path / "robot.db"
    with Store(path) as store:
        store.put_submap("a", 0, b"mine", own=True)
        store.put_submap("b", 5, b"theirs")
        store.put_edge(_edge())
        store.set_meta("robot", "a")
    with Store(path) as store:
        assert store.get_submap("a", 0).payload == b"mine" and store.get_submap("a", 0).own
        assert store.get_submap("b", 5).payload == b"theirs"
        assert len(store.edges()) == 1 and store.get_meta("robot") == "a"
        assert store.put_submap("a", 1, b"next", own=True)
    with Store(path) as store:
        assert store.seqs("a") == [0, 1]
    with sqlite3.connect(path) as conn:
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_closed_store_raises(tmp_path: Path):
    store = Store(tmp_path / "robot.db")
    store.close()
    store.close()
    with pytest.raises(StoreError):
        store.seqs("a")
    with pytest.raises(StoreError):
        store.put_submap("a", 0, b"x")


def test_concurrent_writers(tmp_path: Path):
    path = tmp_path / "robot.db"
    errors: list[BaseException] = []
    with Store(path) as store:

        def writer(robot: str) -> None:
            try:
                for seq in range(40):
                    store.put_submap(robot, seq, f"{robot}{seq}".encode())
                    store.put_submap(robot, seq, b"again")  # duplicates race too
                    store.seqs(robot)
                store.put_edge(_edge(source_seq=int(robot[1:])))
            except BaseException as err:  # surfaced below: threads swallow exceptions
                errors.append(err)

        threads = [threading.Thread(target=writer, args=(f"r{i}",)) for i in range(8)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert errors == []
    with Store(path) as store:
        assert store.count() == 8 * 40
        assert all(store.seqs(f"r{i}") == list(range(40)) for i in range(8))
        assert store.get_submap("r3", 7).payload == b"r37"
        assert len(store.edges()) == 8


def test_two_connections_one_file(tmp_path: Path):
    # A second process (here a second connection) sees committed writes: WAL readers.
    path = tmp_path / "robot.db"
    with Store(path) as first, Store(path) as second:
        first.put_submap("a", 0, b"x")
        assert second.get_submap("a", 0).payload == b"x"


_CRASH = """
import os, sys
from gmmap.fleet.storage.store import Store
store = Store(sys.argv[1])
store.put_submap("a", 0, b"committed")
with store._transaction() as conn:
    conn.execute(
        "INSERT INTO submaps (robot, kind, seq, payload, own, received) "
        "VALUES ('a', 'submap', 1, x'00', 0, 0)"
    )
    os._exit(3)  # dies mid-transaction, as a killed process would
"""


def test_crash_mid_write_keeps_committed_data(tmp_path: Path):
    path = tmp_path / "robot.db"
    result = subprocess.run([sys.executable, "-c", _CRASH, str(path)], timeout=60)
    assert result.returncode == 3
    with Store(path) as store:
        assert store.seqs("a") == [0]
        assert store.get_submap("a", 0).payload == b"committed"
        assert store.put_submap("a", 1, b"after restart")


def test_corrupt_file_raises_typed_error_and_is_untouched(tmp_path: Path):
    path = tmp_path / "robot.db"
    garbage = os.urandom(3000)
    path.write_bytes(garbage)
    with pytest.raises(StoreFormatError) as info:
        Store(path)
    assert isinstance(info.value, FileFormatError) and isinstance(info.value, GmmapError)
    assert str(path) in str(info.value)
    assert path.read_bytes() == garbage
    assert sorted(p.name for p in tmp_path.iterdir()) == ["robot.db"]


def test_damaged_store_pages_raise_typed_error(tmp_path: Path):
    path = tmp_path / "robot.db"
    with Store(path) as store:
        store.put_submaps([("a", seq, os.urandom(2000)) for seq in range(50)])
    data = bytearray(path.read_bytes())
    data[4096 : len(data) - 4096] = os.urandom(len(data) - 8192)  # keep the header page
    path.write_bytes(bytes(data))
    with pytest.raises(StoreFormatError), Store(path) as store:
        store.submaps("a")


def test_foreign_database_is_refused(tmp_path: Path):
    path = tmp_path / "other.db"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE photos (id INTEGER)")
    before = path.read_bytes()
    with pytest.raises(StoreFormatError, match="not a gmmap store"):
        Store(path)
    assert path.read_bytes() == before


def test_newer_schema_is_refused(tmp_path: Path):
    path = tmp_path / "robot.db"
    Store(path).close()
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE schema_version SET version = ?", (SCHEMA_VERSION + 1,))
    with pytest.raises(StoreFormatError, match="newer"):
        Store(path)


def test_unopenable_path_raises_store_error(tmp_path: Path):
    with pytest.raises(StoreError):
        Store(tmp_path / "missing-dir" / "robot.db")
