"""Where a robot's fetches start and who answers them (`gmmap.fleet.arrivals`)."""

from gmmap.fleet.arrivals import QUIET_S, Arrivals


def test_a_fetch_starts_at_the_first_gap_of_what_arrived_or_was_stored() -> None:
    a = Arrivals()
    assert a.since("r", []) == 0
    assert a.add("r", 0) and a.add("r", 2) and not a.add("r", 2)
    assert a.since("r", []) == 1
    assert a.since("r", [1]) == 3  # stored, or still queued: both count


def test_a_present_robot_that_stays_silent_is_fetched_through_the_others() -> None:
    a = Arrivals()
    a.met("r")
    assert a.relayed("r", present=[]) and not a.relayed("r", present=["r"])
    a.unanswered("r")  # present, but its link stalled
    assert a.relayed("r", present=["r"])
    a.add("r", 0)  # handed on by a relay: still silent
    assert a.relayed("r", present=["r"])
    a.add("r", 1, direct=True)  # from r itself again
    assert not a.relayed("r", present=["r"])


def test_a_present_robot_quiet_for_a_while_is_fetched_through_the_others() -> None:
    now = [0.0]
    a = Arrivals(clock=lambda: now[0])
    a.met("r")
    now[0] = QUIET_S - 1
    assert not a.relayed("r", present=["r"])
    now[0] = QUIET_S + 1  # a rendezvous link went down: r stays present until its lease ends
    assert a.relayed("r", present=["r"])
    a.add("r", 0, direct=True)
    assert not a.relayed("r", present=["r"])
