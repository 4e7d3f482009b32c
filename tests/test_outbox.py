"""The outbox (`gmmap.fleet.net.outbox`): priority order, bundles and the byte budget."""

import threading
import time

import pytest

from conftest import wait
from gmmap.errors import InvalidInputError, TransportError
from gmmap.fleet.net.keys import data_key
from gmmap.fleet.net.outbox import Budget, Outbox
from gmmap.options import RobotOptions

SENDER = ("fleet", "r")


def test_a_backlog_leaves_the_latest_advert_first_then_the_newest_submaps() -> None:
    gate, sent = threading.Event(), []

    def publish(kind: str, seq: int, payload: bytes, to) -> None:
        gate.wait(5)  # the link is busy until the backlog is queued
        sent.append((kind, seq) if to is None else (kind, seq, to))

    box = Outbox(publish, Budget(None), "have", SENDER)
    box.put("submap", 0, b"x")  # taken at once, held up by the busy link
    time.sleep(0.05)
    for seq in (1, 2, 3):
        box.put("submap", seq, b"x")
    box.put("have", 0, b"{}", frozenset({"p"}))
    box.put("have", 1, b"{}", frozenset({"q"}))
    box.put("have", 2, b"{}", frozenset({"q"}))  # replaces the one to q, not the one to p
    assert box.pending() == 6
    box.put("have", 3, b"{}")  # to all: replaces both
    assert box.pending() == 5
    box.put("have", 4, b"{}", frozenset({"p"}))  # the one to all waits on
    gate.set()
    assert box.flush(5)
    box.close()
    assert sent == [
        ("submap", 0),
        ("have", 3),
        ("have", 4, frozenset({"p"})),
        ("submap", 3),
        ("submap", 2),
        ("submap", 1),
    ]


def test_the_budget_holds_payload_and_keys() -> None:
    """2,000 B/s with a second of burst: 10 messages of 500 B and their keys take more than
    1.5 s, and each one's cost is its payload plus its key."""
    costs: list[int] = []
    budget = Budget(2000.0)
    take = budget.take
    budget.take = lambda n, stopped=lambda: False: costs.append(n) or take(n, stopped)
    box = Outbox(lambda kind, seq, payload, to: None, budget, "have", SENDER)
    start = time.monotonic()
    for seq in range(10):
        box.put("submap", seq, b"x" * 500)
    assert box.flush(10)
    elapsed = time.monotonic() - start
    box.close()
    key = len(data_key(*SENDER, "submap", 9))
    assert costs[0] == 500 + key and len(costs) == 10
    assert elapsed >= (sum(costs) - 2000) / 2000 - 0.1


def test_a_closed_budget_wait_gives_up() -> None:
    budget = Budget(10.0)
    assert budget.take(10)
    assert not budget.take(1000, stopped=lambda: True)


def test_a_failed_publish_is_dropped_and_the_rest_go() -> None:
    sent = []

    def publish(kind: str, seq: int, payload: bytes, to) -> None:
        if seq == 1:
            raise TransportError("the link is gone")
        sent.append(seq)

    box = Outbox(publish, Budget(None), "have", SENDER)
    for seq in range(3):
        box.put("submap", seq, b"x")
    assert box.flush(5)
    box.close()
    assert sorted(sent) == [0, 2]


def _timed_box(bundle: int, wait: float) -> tuple[Outbox, list]:
    sent: list = []
    publish = lambda kind, seq, payload, to: sent.append((kind, seq, time.monotonic()))  # noqa: E731
    return Outbox(publish, Budget(None), "have", SENDER, bundle, wait), sent


def test_submaps_wait_until_a_bundle_is_full_then_leave_together() -> None:
    box, sent = _timed_box(bundle=3, wait=30.0)
    box.put("submap", 0, b"x")
    box.put("submap", 1, b"x")
    time.sleep(0.3)
    assert sent == [] and box.pending() == 2
    box.put("submap", 2, b"x")
    assert wait(lambda: len(sent) == 3)
    assert [s[1] for s in sent] == [2, 1, 0]  # newest first, back to back
    assert sent[-1][2] - sent[0][2] < 0.1
    box.close()


def test_a_bundle_leaves_when_its_oldest_has_waited_long_enough() -> None:
    box, sent = _timed_box(bundle=3, wait=0.4)
    start = time.monotonic()
    box.put("submap", 0, b"x")
    assert wait(lambda: len(sent) == 1)
    assert sent[0][2] - start >= 0.35


@pytest.mark.parametrize("how", ["advert", "release", "flush"])
def test_an_advert_or_the_end_of_the_frames_sends_what_waits(how: str) -> None:
    box, sent = _timed_box(bundle=3, wait=30.0)
    box.put("submap", 0, b"x")
    time.sleep(0.1)
    if how == "advert":
        box.put("have", 0, b"{}")
    elif how == "release":
        box.release()
    else:
        assert box.flush(5)
    assert wait(lambda: box.pending() == 0)
    expected = [("have", 0), ("submap", 0)] if how == "advert" else [("submap", 0)]
    assert [s[:2] for s in sent] == expected
    box.put("submap", 1, b"x")
    if how == "advert":  # an advert sends what waits; the next submap waits again
        time.sleep(0.2)
        assert box.pending() == 1
    else:  # the frames ended: nothing waits any more
        assert wait(lambda: len(sent) == 2)
    box.close()


def test_a_bundle_asked_for_leaves_now_and_the_next_waits_again() -> None:
    box, sent = _timed_box(bundle=3, wait=30.0)
    box.put("submap", 0, b"x")
    box.put("submap", 1, b"x")
    box.put("have", 0, b"{}")  # an advert goes first, and sends what waits
    assert wait(lambda: box.pending() == 0)
    box.put("submap", 2, b"x")
    box.put("submap", 3, b"x")
    assert box.held("submap") == {2, 3} and box.held("have") == set()
    box.now()  # a peer's fetch asked for them
    assert wait(lambda: box.pending() == 0)
    assert [s[1] for s in sent if s[0] == "submap"] == [1, 0, 3, 2]
    box.put("submap", 4, b"x")
    time.sleep(0.2)
    assert box.held("submap") == {4}  # bundling again
    box.close()


@pytest.mark.parametrize("bad", [0, -1, 1.5])
def test_a_bad_bundle_is_refused(bad) -> None:
    with pytest.raises(InvalidInputError):
        RobotOptions(bundle=bad)
    with pytest.raises(InvalidInputError):
        RobotOptions(bundle_wait=float(bad) - 2)


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan"), float("inf")])
def test_a_bad_budget_is_refused(bad: float) -> None:
    with pytest.raises(InvalidInputError):
        RobotOptions(budget=bad)


def test_robots_on_a_shared_channel_take_equal_shares_within_their_budget():
    from gmmap.fleet.net.outbox import AIR_SHARE, air_share

    assert air_share(None, 3, None) is None and air_share(None, 3, 800.0) == 800.0
    assert air_share(500.0, 1, None) == AIR_SHARE * 500.0
    assert air_share(500.0, 5, None) == AIR_SHARE * 100.0  # a fifth each: nobody starves
    assert air_share(500.0, 2, 50.0) == 50.0  # never above the robot's own budget


def test_a_budget_takes_its_new_rate_at_once():
    budget = Budget(None)
    budget.set_rate(1_000.0)
    assert budget.take(1_000)  # the burst of the new rate
    start = time.monotonic()
    assert budget.take(200)  # then 200 B at 1,000 B/s
    assert time.monotonic() - start >= 0.15
    budget.set_rate(None)
    assert budget.take(10**9)


def test_a_budget_that_follows_a_changing_rate_still_sends_a_message_above_its_burst():
    rates = iter([10.0, 2_000.0, 20.0] * 1000)
    budget = Budget(10.0)
    budget.take(10)  # the burst is spent
    budget.follow(lambda: next(rates))  # a rate that changes at every look
    start = time.monotonic()
    # 300 B: 30 bursts at the lowest rate; saved toward the message however the rate moves.
    assert budget.take(300, lambda: time.monotonic() - start > 5.0)
    budget.follow(None)
    budget.set_rate(None)
    assert budget.take(10**9)
