"""Adverts of what each robot holds (`gmmap.fleet.holdings`)."""

import json

from gmmap.fleet.holdings import MAX_BYTES, Holdings, decode, describe, encode


def test_an_advert_round_trips_and_anything_else_is_ignored() -> None:
    counts = {"robot_1": 7, "robot_0": 9}
    assert decode(encode(counts)) == counts
    assert encode(counts) == b'{"robot_0":9,"robot_1":7}'
    for bad in (
        b"not json",
        b"\xff\xfe",
        b"[1, 2]",
        b'{"robot_0": -1}',
        b'{"robot_0": 1.5}',
        b'{"robot_0": true}',
        b'{"bad name!": 1}',
        json.dumps({f"r{i}": 1 for i in range(2000)}).encode(),
        b" " * (MAX_BYTES + 1),
    ):
        assert decode(bad) is None, bad
    h = Holdings()
    assert not h.update("robot_1", b"[]")
    assert h.lacking({"robot_0": 1}, ["robot_1"]) == {"robot_1": {"they_lack": -1, "we_lack": -1}}


def test_lacking_names_the_peers_in_reach_that_differ() -> None:
    h = Holdings()
    assert h.update("b", encode({"a": 3, "b": 5}))
    assert h.update("c", encode({"a": 5, "b": 5, "c": 2}))
    mine = {"a": 5, "b": 5}
    assert h.lacking(mine, ["b", "c"]) == {
        "b": {"they_lack": 2, "we_lack": 0},
        "c": {"they_lack": 0, "we_lack": 2},
    }
    assert h.lacking(mine, []) == {}  # no one in reach: nothing to wait for
    h.update("b", encode(mine))
    assert h.lacking(mine, ["b"]) == {}
    assert describe({"d": {"they_lack": -1, "we_lack": -1}}) == "d (no advert yet)"
