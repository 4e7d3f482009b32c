"""Where a robot's fetches start and who answers them (`gmmap.fleet.sharing.arrivals`)."""

from gmmap.fleet.sharing.arrivals import QUIET_S, Arrivals


def test_a_fetch_starts_at_the_first_gap_of_what_arrived_or_was_stored() -> None:
    a = Arrivals()
    assert a.since("r", []) == 0
    assert a.add("r", 0) and a.add("r", 2) and not a.add("r", 2)
    assert a.since("r", []) == 1
    assert a.since("r", [1]) == 3  # stored, or still queued: both count


def test_a_present_robot_that_stays_silent_is_fetched_through_the_others() -> None:
    now = [0.0]
    a = Arrivals(clock=lambda: now[0])
    a.met("r")
    assert a.relayed("r", present=[]) and not a.relayed("r", present=["r"])
    now[0] = 1.0
    assert a.unanswered("r", asked=0.5)  # present, but its link stalled
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
    a.met("s")
    assert a.quiet(["r", "s"]) == ["r"]
    a.add("r", 0, direct=True)
    assert not a.relayed("r", present=["r"])


def test_a_robot_heard_while_it_left_a_fetch_unanswered_is_slow_not_silent() -> None:
    now = [0.0]
    a = Arrivals(clock=lambda: now[0])
    a.met("r")
    now[0] = 1.0
    a.add("r", 0, direct=True)  # arrived while the fetch asked at 0.5 waited
    assert not a.unanswered("r", asked=0.5)
    assert not a.relayed("r", present=["r"])


def test_what_a_talking_robot_sent_after_its_latest_is_on_its_way() -> None:
    now = [0.0]
    a = Arrivals(clock=lambda: now[0])
    a.met("r")
    assert not a.on_its_way("r", 0)  # nothing from r since it joined: no guide
    a.add("r", 0, direct=True)
    a.add("r", 1, direct=True)
    assert a.on_its_way("r", 2)  # newer than its latest: queued behind on its link
    assert not a.on_its_way("r", 1)  # a gap below what it sent: a fetch fills it
    now[0] = QUIET_S + 1
    assert not a.on_its_way("r", 2)  # quiet: it may be out of reach
    a.add("r", 2, direct=True)
    a.met("r")  # joined again: what it sent meanwhile never came
    assert not a.on_its_way("r", 3)


def test_nothing_is_on_its_way_where_robots_do_not_bundle() -> None:
    a = Arrivals(patient=False)  # links that come and go: a quiet gap more likely a cut link
    a.met("r")
    a.add("r", 0, direct=True)
    assert not a.on_its_way("r", 1)


def test_on_a_shared_channel_all_a_talking_robot_lacks_is_on_its_way() -> None:
    """Paced to its share of the air, a robot sends its newest first and the rest behind."""
    now = [0.0]
    a = Arrivals(clock=lambda: now[0], shared_channel=True)
    a.met("r")
    assert a.on_its_way("r", 0)  # it just joined: it talks
    a.add("r", 5, direct=True)
    assert a.on_its_way("r", 0)  # older than its latest, still on its way
    now[0] = QUIET_S + 1
    assert not a.on_its_way("r", 0)  # quiet: now a fetch
