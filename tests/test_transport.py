import queue
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
import zenoh

from gmmap.fleet.net.keys import (
    FetchRequest,
    fetch_key,
    listen_port,
    parse_fetch,
    parse_reply_key,
    parse_seq_ranges,
    seq_ranges,
)
from gmmap.fleet.net.transport import (
    Transport,
    TransportConfig,
    TransportConfigError,
    TransportError,
    TransportOptions,
    alive_key,
    data_key,
    parse_data_key,
)
from gmmap.fleet.storage.store import Store

WAIT = 10.0  # generous: polling returns as soon as the condition holds


def tconfig(fleet="lab", robot="a", **options) -> TransportConfig:
    """A robot's transport configuration: its name and `TransportOptions`."""
    return TransportConfig(fleet, robot, TransportOptions(**options))


def wait_until(condition: Callable[[], bool], timeout: float = WAIT) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return condition()


def endpoint(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


class Inbox:
    """Collects (robot, kind, seq, payload) from a subscription."""

    def __init__(self) -> None:
        self.items: queue.Queue = queue.Queue()

    def __call__(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        self.items.put((robot, kind, seq, payload))

    def get(self, timeout: float = WAIT):
        return self.items.get(timeout=timeout)

    def empty(self) -> bool:
        return self.items.empty()


@pytest.fixture
def pair() -> Iterator[tuple[Transport, Transport]]:
    """Robots a and b of fleet "lab" on loopback; b connects to a."""
    port_a = listen_port()
    with (
        Transport(tconfig("lab", "a", port=port_a)) as a,
        Transport(tconfig("lab", "b", connect=[endpoint(port_a)])) as b,
    ):
        assert a.wait_for_peers(["b"], WAIT) and b.wait_for_peers(["a"], WAIT)
        yield a, b


def test_key_expressions():
    assert data_key("lab", "a", "submap", 7) == "gmmap/lab/a/submap/7"
    assert alive_key("lab", "a") == "gmmap/lab/a"
    assert parse_data_key("gmmap/lab/a/submap/7") == ("lab", "a", "submap", 7)
    for bad in [
        "gmmap/lab/a/submap",
        "gmmap/lab/a/submap/x",
        "gmmap/lab/a/submap/07",
        "gmmap/lab/a/submap/-1",
        "gmmap/lab/*/submap/1",
        "other/lab/a/submap/1",
        "gmmap/lab/a/submap/1/extra",
    ]:
        assert parse_data_key(bad) is None, bad
    assert fetch_key("lab", "a", "submap", "b") == "gmmap/lab/a/submap/*/via/b"
    asked = parse_fetch("gmmap/lab/a/submap/*/via/b", {"since": "3", "held": "5-6"})
    assert asked == FetchRequest("lab", "a", "submap", 3, ((5, 6),))
    assert [seq for seq in range(9) if asked.wants(seq)] == [3, 4, 7, 8]
    every = parse_fetch("gmmap/lab/*/submap/*/via/*", {"skip": "a,b"})
    assert every == FetchRequest("lab", "*", "submap", 0, (), frozenset({"a", "b"}))
    for bad in ["gmmap/lab/a/submap/*", "gmmap/lab/a/submap/*/by/b", "gmmap/lab/a/submap/1/via/b"]:
        assert parse_fetch(bad, {}) is None, bad
    assert parse_fetch("gmmap/lab/a/submap/*/via/b", {"since": "x"}) is None
    assert parse_reply_key("gmmap/lab/a/submap/7/via/b") == ("lab", "a", "submap", 7)
    assert seq_ranges([9, 0, 1, 2, 3, 7, 10]) == "0-3,7,9-10" and seq_ranges([]) == ""
    assert parse_seq_ranges("0-3,7,9-10") == [(0, 3), (7, 7), (9, 10)]
    assert parse_seq_ranges(None) == [] == parse_seq_ranges("")
    for bad in ["3-1", "a", "1-", "-1", "1,,2", ",".join(["1"] * 257), "9" * 20]:
        assert parse_seq_ranges(bad) is None, bad
    for bad in ["gmmap/lab/a/submap/7", "gmmap/lab/a/submap/7/via/b*", "gmmap/lab/a/submap/7/by/b"]:
        assert parse_reply_key(bad) is None, bad


@pytest.mark.parametrize(
    "kwargs",
    [
        {"fleet": "", "robot": "a"},
        {"fleet": "lab", "robot": ""},
        {"fleet": "lab", "robot": "a/b"},
        {"fleet": "lab", "robot": "a*"},
        {"fleet": "l?b", "robot": "a"},
        {"fleet": "lab", "robot": "@a"},
        {"fleet": "lab", "robot": "a b"},
        {"fleet": "lab", "robot": 3},
        {"fleet": "lab", "robot": "a", "listen": ["tcp/127.0.0.1"]},
        {"fleet": "lab", "robot": "a", "listen": ["127.0.0.1:7447"]},
        {"fleet": "lab", "robot": "a", "listen": ["bogus/127.0.0.1:7447"]},
        {"fleet": "lab", "robot": "a", "listen": ["tcp/127.0.0.1:99999"]},
        {"fleet": "lab", "robot": "a", "listen": "tcp/127.0.0.1:7447"},
        {"fleet": "lab", "robot": "a", "connect": ["tcp/127.0.0.1:0"]},
        {"fleet": "lab", "robot": "a", "connect": ["tcp/[::1:7447"]},
        {"fleet": "lab", "robot": "a", "connect": [""]},
        {"fleet": "lab", "robot": "a", "port": 70000},
        {"fleet": "lab", "robot": "a", "mode": "router"},
        {"fleet": "lab", "robot": "a", "mode": "client"},
        {"fleet": "lab", "robot": "a", "fetch_timeout": 0},
    ],
)
def test_bad_config_raises_typed_error(kwargs):
    with pytest.raises(TransportConfigError) as info:
        tconfig(**kwargs)
    assert isinstance(info.value, ValueError) and isinstance(info.value, TransportError)


def test_good_config_normalises_endpoints():
    cfg = tconfig(
        "lab",
        "robot-1.x_y",
        listen=["tcp/0.0.0.0:7447", "tcp/[::1]:7448"],
        connect=["tcp/peer.local:7447", "udp/10.0.0.2:7447#rel=1"],
    )
    o = cfg.options
    assert o.listen == ("tcp/0.0.0.0:7447", "tcp/[::1]:7448")
    assert isinstance(o.connect, tuple) and not o.multicast_scouting and o.mode == "peer"


def test_bad_zenoh_option_raises_config_error():
    with pytest.raises(TransportConfigError, match="Zenoh option"):
        Transport(tconfig("lab", "a", zenoh_options={"no/such/option": 1}))


def test_port_in_use_raises_transport_error():
    port = listen_port()
    with (
        Transport(tconfig("lab", "a", port=port)),
        pytest.raises(TransportError, match="cannot open"),
    ):
        Transport(tconfig("lab", "b", port=port))


def test_exchange_submaps_and_count_bytes(pair):
    a, b = pair
    inbox_a, inbox_b = Inbox(), Inbox()
    a.subscribe(inbox_a)
    b.subscribe(inbox_b)
    # Puts have no history: publish once the subscriptions have reached the other side.
    assert wait_until(lambda: a.has_listeners("submap") and b.has_listeners("descriptor"))

    payloads = {0: b"\x01" * 1000, 1: bytes(range(256)) * 3, 2: b""}
    for seq, payload in payloads.items():
        a.publish("submap", seq, payload)
    b.publish("descriptor", 0, bytearray(b"xyz"))

    got = [inbox_b.get() for _ in payloads]
    assert got == [("a", "submap", seq, p) for seq, p in payloads.items()]
    assert inbox_a.get() == ("b", "descriptor", 0, b"xyz")
    time.sleep(0.2)
    assert inbox_a.empty() and inbox_b.empty()  # nobody hears its own messages

    total = sum(len(p) for p in payloads.values())
    keys = sum(len(data_key("lab", "a", "submap", s)) for s in payloads)
    sent = a.stats()["sent"]["a"]["submap"]
    assert (sent["messages"], sent["payload_bytes"], sent["key_bytes"]) == (3, total, keys)
    assert b.stats()["received"]["a"]["submap"] == sent
    assert b.stats()["sent"]["b"]["descriptor"]["payload_bytes"] == 3
    assert a.stats()["received"]["b"]["descriptor"]["payload_bytes"] == 3
    assert a.stats()["totals"]["sent"]["payload_bytes"] == total
    assert a.stats()["totals"]["received"]["messages"] == 1
    assert a.stats()["robot"] == "a" and a.stats()["fleet"] == "lab"


def test_liveliness_join_and_leave():
    port_a = listen_port()
    joined, left = queue.Queue(), queue.Queue()
    with Transport(tconfig("lab", "a", port=port_a)) as a:
        a.on_join(joined.put)
        a.on_leave(left.put)
        assert a.peers() == []
        b = Transport(tconfig("lab", "b", connect=[endpoint(port_a)]))
        try:
            assert joined.get(timeout=WAIT) == "b"
            assert a.peers() == ["b"] and wait_until(lambda: b.peers() == ["a"])
            # A callback registered late still hears of robots already present.
            late = queue.Queue()
            b.on_join(late.put)
            assert late.get(timeout=WAIT) == "a"
        finally:
            b.close()
        assert left.get(timeout=WAIT) == "b"
        assert a.peers() == []
        assert joined.empty()


def raw_session(port: int) -> zenoh.Session:
    """A bare Zenoh session connected to ``port``: a peer that speaks Zenoh, not gmmap."""
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", f'["{endpoint(port)}"]')
    cfg.insert_json5("listen/endpoints", "[]")
    cfg.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(cfg)


def test_other_fleet_and_malformed_keys_are_ignored(pair):
    a, _ = pair
    inbox = Inbox()
    a.subscribe(inbox)
    port_a = int(a.listen_endpoints[0].rsplit(":", 1)[1])
    with Transport(tconfig("other", "c", listen=[], connect=[endpoint(port_a)])) as c:
        assert c.listen_endpoints == ()
        # Fleets do not see each other's presence either.
        with raw_session(port_a) as raw:
            probe = raw.declare_publisher("gmmap/lab/x/submap/*")
            assert wait_until(lambda: probe.matching_status.matching)
            c.publish("submap", 0, b"other fleet")
            for bad in ["submap/notanint", "submap/007", "sub map/1", "submap/1/extra"]:
                raw.put(f"gmmap/lab/x/{bad}", b"junk")
            raw.put("gmmap/lab/a/submap/5", b"pretends to be a")  # our own name: ignored
            raw.put("gmmap/lab/x/submap/1", b"valid")  # sent last: when it arrives, all did
            assert inbox.get() == ("x", "submap", 1, b"valid")
    assert inbox.empty()
    assert a.peers() == ["b"]
    stats = a.stats()
    # The bad seqs, the bad kind and our own name; ".../1/extra" matches no subscription.
    assert stats["ignored"] == 4
    assert set(stats["received"]) == {"x"}


def test_callback_errors_do_not_stop_delivery(pair):
    a, b = pair
    inbox = Inbox()

    def broken(*_args):
        raise RuntimeError("bug in a stage")

    b.subscribe(broken)
    b.subscribe(inbox)
    assert wait_until(a.has_listeners)
    a.publish("submap", 0, b"one")
    a.publish("submap", 1, b"two")
    assert [inbox.get()[2], inbox.get()[2]] == [0, 1]


def test_fetch_what_was_missed(tmp_path: Path):
    """b starts after a published: it fetches a's submaps from a's store."""
    port_a = listen_port()
    with (
        Store(tmp_path / "a.db") as store,
        Transport(tconfig("lab", "a", port=port_a)) as a,
    ):
        a.serve(store.fetch_provider)
        payloads = [bytes([seq]) * (100 + seq) for seq in range(4)]
        for seq, payload in enumerate(payloads):
            store.put_submap("a", seq, payload, own=True)
            a.publish("submap", seq, payload)
        store.put_submap("z", 0, b"relayed")  # a also serves what it received from others

        with Transport(tconfig("lab", "b", connect=[endpoint(port_a)])) as b:
            assert b.wait_for_peers(["a"], WAIT)
            got = b.fetch("a", "submap", 0, timeout=WAIT)
            assert got == list(enumerate(payloads))
            assert b.fetch("a", "submap", 2, timeout=WAIT) == [(2, payloads[2]), (3, payloads[3])]
            assert b.fetch("a", "submap", 10, timeout=WAIT) == []
            assert b.fetch("a", "submap", 0, timeout=WAIT, held=[1, 2]) == [
                (0, payloads[0]),
                (3, payloads[3]),
            ]
            assert b.fetch("z", timeout=WAIT) == [(0, b"relayed")]

            received = b.stats()["received"]["a"]["submap"]
            again = [payloads[2], payloads[3], payloads[0], payloads[3]]
            expected = sum(map(len, payloads + again))
            assert received["fetch_messages"] == 8 == received["messages"]
            assert received["fetch_payload_bytes"] == expected
            assert b.stats()["queries"]["sent"] == 5
            served = a.stats()["sent"]["a"]["submap"]
            assert served["fetch_payload_bytes"] == expected
            assert served["payload_bytes"] == expected + sum(map(len, payloads))
            assert a.stats()["queries"]["served"] == 5


def test_a_fetch_reaches_only_the_robots_it_names(tmp_path: Path):
    """From the owner, its owner alone answers; through one robot in between, that one; for a
    robot out of reach with none named, every holder."""
    port_a, port_c = listen_port(), listen_port()
    with (
        Store(tmp_path / "a.db") as store_a,
        Store(tmp_path / "c.db") as store_c,
        Transport(tconfig("lab", "a", port=port_a)) as a,
        Transport(tconfig("lab", "c", port=port_c)) as c,
    ):
        for store, t in ((store_a, a), (store_c, c)):
            store.put_submap("z", 0, b"z0")
            t.serve(store.fetch_provider)
        store_a.put_submap("a", 0, b"a0", own=True)
        store_c.put_submap("a", 0, b"a0")
        with Transport(tconfig("lab", "b", connect=[endpoint(port_a), endpoint(port_c)])) as b:
            assert b.wait_for_peers(["a", "c"], WAIT)

            def served():
                return [t.stats()["queries"]["served"] for t in (a, c)]

            assert b.fetch("a", "submap", 0, timeout=WAIT) == [(0, b"a0")]
            assert served() == [1, 0]
            assert b.fetch("z", "submap", 0, timeout=WAIT, via="c") == [(0, b"z0")]
            assert served() == [1, 1]
            assert b.fetch("z", "submap", 0, timeout=WAIT) == [(0, b"z0")]  # z is out of reach
            assert served() == [2, 2]
            assert b.fetch("a", "submap", 0, timeout=WAIT, relay=True) == [(0, b"a0")]
            assert served() == [3, 3]


def test_a_message_told_to_one_peer_reaches_that_peer_alone():
    """b tells a alone: a's callbacks get it as a put, c hears nothing; a message told in
    a's own name, or with a malformed key, is ignored."""
    port_a, port_c = listen_port(), listen_port()
    got: dict[str, list] = {"a": [], "c": []}
    with (
        Transport(tconfig("lab", "a", port=port_a)) as a,
        Transport(tconfig("lab", "c", port=port_c)) as c,
    ):
        for name, t in (("a", a), ("c", c)):
            t.serve(lambda robot, kind, since: [])
            t.subscribe(lambda *m, name=name: got[name].append(m))
        with Transport(tconfig("lab", "b", connect=[endpoint(port_a), endpoint(port_c)])) as b:
            assert b.wait_for_peers(["a", "c"], WAIT)
            b.tell("a", "have", 7, b"news")
            assert wait_until(lambda: got["a"] == [("b", "have", 7, b"news")])
            b.publish("have", 8, b"all")
            # Each link carries it at its own pace: wait for both.
            assert wait_until(lambda: got["a"][-1:] == got["c"][-1:] == [("b", "have", 8, b"all")])
            assert len(got["c"]) == 1
            with raw_session(port_a) as raw:
                list(raw.get("gmmap/lab/a/have/9/via/a", payload=b"x", timeout=WAIT))
                list(raw.get("gmmap/lab/b/have/x/via/a", payload=b"x", timeout=WAIT))
            assert a.stats()["ignored"] == 2 and len(got["a"]) == 2
        assert a.stats()["received"]["b"]["have"]["messages"] == 2


def test_a_fetch_with_a_malformed_held_list_is_ignored(pair):
    a, _ = pair
    a.serve(lambda robot, kind, since: [(0, b"a0")])
    with raw_session(int(a.listen_endpoints[0].rsplit(":", 1)[1])) as raw:
        key = fetch_key("lab", "a", "submap", "a")
        held = ",".join(str(2 * i) for i in range(300))  # more ranges than anyone sends
        for bad in [f"{key}?since=0;held=3-1", f"{key}?since=0;held={held}"]:
            assert [r.ok for r in raw.get(bad, timeout=WAIT)] == []
        good = [r.ok.payload.to_bytes() for r in raw.get(f"{key}?since=0", timeout=WAIT)]
        assert good == [b"a0"]
    assert a.stats()["ignored"] == 2


def test_fetch_answers_keep_to_the_budget(tmp_path: Path):
    """Five 1,000 B answers at 2,000 B/s, one second of burst: the last leaves 1.5 s or more
    after the first."""
    from gmmap.fleet.net.outbox import Budget

    port_a = listen_port()
    with (
        Store(tmp_path / "a.db") as store,
        Transport(tconfig("lab", "a", port=port_a)) as a,
    ):
        for seq in range(5):
            store.put_submap("a", seq, bytes(1000), own=True)
        a.serve(store.fetch_provider, budget=Budget(2000.0))
        with Transport(tconfig("lab", "b", connect=[endpoint(port_a)])) as b:
            assert b.wait_for_peers(["a"], WAIT)
            start = time.monotonic()
            got = b.fetch("a", "submap", 0, timeout=WAIT)
            elapsed = time.monotonic() - start
    assert [seq for seq, _ in got] == list(range(5))
    assert elapsed >= (5 * 1000 - 2000) / 2000 - 0.1


def test_fetch_unknown_names_the_robots_a_newcomer_never_met(tmp_path: Path):
    port_a = listen_port()
    with (
        Store(tmp_path / "a.db") as store,
        Transport(tconfig("lab", "a", port=port_a)) as a,
    ):
        a.serve(store.fetch_provider, store.robots)
        store.put_submap("a", 0, b"own", own=True)
        store.put_submap("gone", 0, b"g0")
        store.put_submap("gone", 1, b"g1")
        with Transport(tconfig("lab", "b", connect=[endpoint(port_a)])) as b:
            assert b.wait_for_peers(["a"], WAIT)
            got = b.fetch_unknown({"a", "b"}, timeout=WAIT)
            assert got == {"gone": [(0, b"g0"), (1, b"g1")]}
            assert b.fetch_unknown({"a", "b", "gone"}, timeout=WAIT) == {}


def test_fetch_without_servers_returns_empty(pair):
    _, b = pair
    start = time.monotonic()
    assert b.fetch("a", timeout=1.0) == []  # a never called serve()
    assert time.monotonic() - start < 5.0


def test_slow_provider_does_not_block_messages(pair):
    a, b = pair
    started, release = threading.Event(), threading.Event()

    def slow(robot, kind, since):
        started.set()
        release.wait(WAIT)
        return [(0, b"late")]

    inbox = Inbox()
    a.serve(slow)
    a.subscribe(inbox)
    assert wait_until(b.has_listeners)
    result = queue.Queue()
    threading.Thread(target=lambda: result.put(b.fetch("z", timeout=WAIT)), daemon=True).start()
    assert started.wait(WAIT)
    b.publish("submap", 0, b"message")
    assert inbox.get() == ("b", "submap", 0, b"message")  # while the provider still waits
    release.set()
    assert result.get(timeout=WAIT) == [(0, b"late")]


def test_bad_arguments_and_closed_transport():
    with Transport(tconfig("lab", "a")) as a:
        for args in [("sub/map", 0, b"x"), ("submap", -1, b"x"), ("submap", 0, "str")]:
            with pytest.raises(TransportConfigError):
                a.publish(*args)
        with pytest.raises(TransportConfigError):
            a.fetch("*")
        with pytest.raises(TransportConfigError):
            a.subscribe("not callable")
    assert a.closed
    a.close()  # idempotent
    with pytest.raises(TransportError, match="closed"):
        a.publish("submap", 0, b"x")
