"""Adverts of what each robot holds (`gmmap.fleet.sharing.holdings`)."""

from gmmap.fleet.sharing.holdings import (
    FINAL,
    LINGER,
    MAPPING,
    MAX_BYTES,
    Advert,
    Holdings,
    decode,
    describe,
    encode,
)


def test_an_advert_round_trips_and_anything_else_is_ignored() -> None:
    counts = {"robot_1": 7, "robot_0": 9}
    for state in (MAPPING, LINGER, FINAL):
        for reach in ([], ["robot_1"], ["b", "a"], ["robot_0", "zed"]):
            for done in ({}, {"robot_0": 9}, {"robot_1": 7, "far": 3}):
                got = decode(encode(counts, state, reach, done))
                assert got == Advert(counts, state, tuple(sorted(reach)), done)
    # state, 2 robots, each its name and count, 1 heard: robot_1 by index, none done
    assert encode(counts, LINGER, ["robot_1"]) == (
        b"\x01\x02\x07robot_0\x09\x07robot_1\x07\x01\x01\x00"
    )
    # 2 done: robot_0 by index, then one named past the counted ones, each with its total
    assert encode(counts, LINGER, [], {"robot_0": 9, "z": 4}).endswith(
        b"\x00\x02\x00\x09\x02\x01z\x04"
    )
    five = {f"robot_{i}": 40 for i in range(5)}
    assert len(encode(five, LINGER, ["robot_1"])) == 50
    assert len(encode(five, LINGER, ["robot_1"], five)) == 60
    good = encode(counts, LINGER, ["zed"])
    for bad in (
        b"",
        b"not an advert",
        b"\x03" + good[1:],  # no such state
        good[:-1],  # truncated
        good + b"\x00",  # trailing bytes
        b"\x00\x02\x07robot_0\x01\x07robot_0\x02\x00",  # a robot named twice
        b"\x00\x01\x09bad name!\x01\x00",
        b"\x00\x01\x02\xff\xfe\x01\x00",  # not UTF-8
        b"\x00\x01\x01a\x01\x01\x05\x00",  # a heard index past the names
        b"\x00\x01\x01a\x01\x00\x01\x00",  # a robot done, without its total
        b"\x00\x01\x01a\x01\x00\x01\x03\x01",  # a done index past the names
        b"\x00\x01\x01a" + b"\xff" * 10 + b"\x01\x00",  # a count past 64 bits
        b"\x00\xff\x7f",  # more robots than allowed
        b"\x00" * (MAX_BYTES + 1),
    ):
        assert decode(bad) is None, bad
    h = Holdings()
    assert not h.update("robot_1", b"[]")
    assert h.lacking({"robot_0": 1}, ["robot_1"]) == {"robot_1": {"they_lack": -1, "we_lack": -1}}


def test_lacking_names_the_peers_that_differ_present_or_gone_without_a_final_advert() -> None:
    h = Holdings()
    assert h.update("b", encode({"a": 3, "b": 5}))
    assert h.update("c", encode({"a": 5, "b": 5, "c": 2}))
    mine = {"a": 5, "b": 5}
    both = {"b": {"they_lack": 2, "we_lack": 0}, "c": {"they_lack": 0, "we_lack": 2}}
    assert h.lacking(mine, ["b", "c"]) == both
    # c vanished without a final advert (a partition, a crash): still waited for.
    assert h.lacking(mine, ["b"]) == both
    h.update("b", encode(mine, FINAL))
    h.update("c", encode({"a": 5, "b": 5, "c": 2}, FINAL))
    assert h.lacking(mine, ["b"]) == {}  # b is even; c is done and gone
    assert h.lacking(mine, ["c"]) == {"c": {"they_lack": 0, "we_lack": 2}}  # present still
    h.meet("d")  # met, then gone before it said anything: waited for
    assert h.lacking(mine, []) == {"d": {"they_lack": -1, "we_lack": -1}}
    assert describe(h.lacking(mine, [])) == "d (no advert yet)"


def test_news_goes_at_most_once_a_second_and_anything_every_30_s() -> None:
    from gmmap.fleet.sharing.holdings import ADVERT_EVERY_S, SETTLE_S, advert_due

    assert not advert_due(10.0, True, told_at=10.0 - SETTLE_S / 2)
    assert advert_due(10.0, True, told_at=10.0 - SETTLE_S)
    assert not advert_due(10.0, False, told_at=9.0)  # nothing new
    assert advert_due(10.0, False, told_at=10.0 - ADVERT_EVERY_S)


def test_a_peer_is_caught_up_on_its_first_advert_after_it_joined() -> None:
    h = Holdings()
    h.meet("a")
    assert not h.caught_up("a")  # no advert yet: still to come
    assert h.update("a", encode({"a": 3}))
    assert h.caught_up("a") and not h.caught_up("a")
    h.meet("a")  # it left and came back
    assert h.update("a", encode({"a": 4})) and h.caught_up("a")


def test_news_is_told_to_peers_only_when_it_changes_what_they_conclude() -> None:
    """A lingering robot tells that it lingers at once. Then it tells a lingering peer when it
    now holds all that peer holds, and any peer when it holds more of a robot out of the
    peer's reach than the peer and its last advert hold; partial catching up is no news."""
    h = Holdings()
    told = {"a": 3, "b": 1}
    assert h.is_news(told, told, MAPPING, [])  # we told we were mapping: now we linger
    h.update("m", encode({"a": 1}, MAPPING, reach=["a"]))
    assert not h.is_news({"a": 9, "b": 1}, told, LINGER, ["m"])  # a reaches m itself
    assert h.is_news({"a": 3, "b": 2}, told, LINGER, ["m"])  # only we can hand b's on to m
    h.update("p", encode({"a": 5, "b": 2}, LINGER, reach=["a"]))
    assert not h.is_news({"a": 4, "b": 1}, told, LINGER, ["p"])  # still behind p
    assert h.is_news({"a": 5, "b": 2}, told, LINGER, ["p"])  # p need not wait for us
    assert h.is_news({"a": 3, "b": 3}, told, LINGER, ["p"])  # p can fetch b's third from us
    assert not h.is_news({"a": 6, "b": 1}, told, LINGER, ["p"])  # a reaches p itself
    assert not h.is_news({"a": 5, "b": 2}, told, LINGER, [])  # p lingers, but is gone


def test_a_robot_relays_for_a_peer_that_does_not_hear_all_it_holds() -> None:
    h = Holdings()
    h.update("p", encode({"a": 1}, LINGER, reach=["a", "q"]))
    assert not h.relaying({"a": 2, "q": 1}, ["p"])  # p hears a and q itself
    assert h.relaying({"a": 2, "r": 1}, ["p"])  # only we can hand r's on to p
    assert not h.relaying({"a": 2, "r": 1}, [])  # p is gone


def test_news_for_a_lingering_peer_waits_for_the_robots_it_hears_to_linger() -> None:
    """p cannot end before m's last submaps and news of them, so telling p now that we hold
    all it holds would only be told again; once m lingers, it is news."""
    h = Holdings()
    told = {"a": 3, "m": 1}
    h.update("p", encode({"a": 5, "m": 1}, LINGER, reach=["a", "m"]))
    h.update("m", encode({"m": 1}, MAPPING, reach=["a", "p"]))
    assert not h.is_news({"a": 5, "m": 1}, told, LINGER, ["p", "m"])
    assert h.is_news({"a": 5, "m": 1}, told, LINGER, ["p"])  # m went out of our reach
    h.update("m", encode({"a": 5, "m": 1}, LINGER, reach=["a", "p"]))
    assert h.is_news({"a": 5, "m": 1}, told, LINGER, ["p", "m"])


def test_a_mapping_robot_gone_quiet_neither_holds_news_back_nor_reaches_our_peers() -> None:
    """m's session outlives its link (a rendezvous): it last said it maps and sent us nothing
    lately. p cannot be waiting on m's news, and what we hold of m only we can hand on."""
    h = Holdings()
    told = {"a": 3, "m": 8}
    h.update("p", encode({"a": 5, "m": 8}, LINGER, reach=["a", "m"]))
    h.update("m", encode({"m": 5}, MAPPING, reach=["a", "p"]))
    assert not h.is_news({"a": 5, "m": 10}, told, LINGER, ["p", "m"])  # m still talks to us
    assert h.is_news({"a": 5, "m": 10}, told, LINGER, ["p", "m"], quiet=["m"])
    assert h.is_news({"a": 5, "m": 8}, told, LINGER, ["p", "m"], quiet=["m"])  # p may end
    h.update("m", encode({"m": 10}, LINGER, reach=["a", "p"]))
    told = {"a": 3, "m": 10}
    assert not h.is_news({"a": 4, "m": 10}, told, LINGER, ["p", "m"], quiet=["m"])  # m lingers


def test_a_robot_is_at_rest_once_every_robot_its_peers_hear_is_done_mapping() -> None:
    h = Holdings()
    assert h.at_rest("a")  # alone
    h.meet("p")
    assert not h.at_rest("a")  # p said nothing yet
    h.update("p", encode({"p": 2}, LINGER, reach=["a", "q"]))
    assert not h.at_rest("a")  # p hears q, of which we know nothing
    h.update("q", encode({"q": 1}, MAPPING, reach=["p"]))
    assert not h.at_rest("a")  # q still maps: p may come to hold what we lack
    h.update("q", encode({"q": 2}, FINAL, reach=["p"]))
    assert h.at_rest("a")


def test_a_robot_knows_who_is_done_mapping_from_its_peers_and_their_adverts() -> None:
    """A chain a - p - q: a never hears q, and learns from p's advert that q is done with 4
    submaps; a waits until it is done itself, knows all others to be, and holds their last."""
    h = Holdings()
    h.meet("p")
    assert h.finished("a", MAPPING, {"a": 3}) == {}
    assert h.unfinished("a", {"a": 3}, {"a": 3}) == ["p"]  # met, not a word yet
    h.update("p", encode({"a": 3, "p": 2, "q": 1}, MAPPING, reach=["a", "q"]))
    done = h.finished("a", LINGER, {"a": 3})
    assert done == {"a": 3}
    assert h.unfinished("a", done, {"a": 3, "p": 2, "q": 1}) == ["p", "q"]
    h.update("p", encode({"a": 3, "p": 2, "q": 4}, LINGER, ["a", "q"], {"p": 2, "q": 4}))
    done = h.finished("a", LINGER, {"a": 3, "p": 2, "q": 1})
    assert done == {"a": 3, "p": 2, "q": 4}
    assert h.unfinished("a", done, {"a": 3, "p": 2, "q": 1}) == ["q"]  # q's last to come
    assert h.unfinished("a", done, {"a": 3, "p": 2, "q": 4}) == []


def test_that_a_robot_out_of_a_peers_reach_is_done_is_news_to_that_peer() -> None:
    h = Holdings()
    told = {"a": 3, "q": 4}
    h.update("p", encode(told, LINGER, reach=["a"]))  # p hears only us, not q
    done = {"a": 3, "q": 4}
    assert h.is_news(told, told, LINGER, ["p"], done=(done, {"a": 3}))
    assert not h.is_news(told, told, LINGER, ["p"], done=(done, done))  # told already
    h.update("p", encode(told, LINGER, ["a"], {"q": 4}))
    assert not h.is_news(told, told, LINGER, ["p"], done=(done, {"a": 3}))  # p knows
    h.update("p", encode(told, LINGER, reach=["a", "q"]))
    assert not h.is_news(told, told, LINGER, ["p"], done=(done, {"a": 3}))  # p hears q
