"""The fetch stage (`gmmap.fleet.sharing.fetching`): which quiet robots a mapping robot asks the
robots in between about, and how."""

import queue
from types import SimpleNamespace

from gmmap.fleet.sharing.fetching import Fetcher
from gmmap.fleet.sharing.holdings import LINGER, MAPPING
from gmmap.fleet.sharing.shared import Shared


class Node(Fetcher):
    """The fetcher of a robot "a" whose peers ``present`` are, of which ``quiet`` sent nothing
    of late."""

    def __init__(
        self,
        present,
        quiet,
        states=None,
        held=None,
        state=MAPPING,
        adverts=None,
        latest=None,
        shared_channel=False,
    ):
        self.asked: list[tuple] = []
        self.answers: dict[str | None, list] = {}  # what a fetch via each robot returns
        held = {"b": 3, "c": 3} if held is None else held
        super().__init__(
            Shared(
                robot="a",
                store=SimpleNamespace(
                    count=lambda r, kind: held.get(r, 0),
                    seqs=lambda r: list(range(held.get(r, 0))),
                ),
                transport=SimpleNamespace(peers=lambda: list(present), fetch=self._fetch_answer),
                door=SimpleNamespace(admit=lambda *a: True),
                arrivals=SimpleNamespace(
                    relayed=lambda r, p: r in quiet,
                    quiet=lambda p: [r for r in p if r in quiet],
                    since=lambda r, seqs: len(seqs),
                    held=lambda r, seqs: set(seqs),
                    add=lambda r, s: True,
                    now=lambda: 0.0,
                    on_its_way=lambda r, since: False,
                    latest=lambda r: (latest or {}).get(r, -1),
                    patient=False,
                    shared_channel=shared_channel,
                    unanswered=lambda r, asked: False,
                ),
                holdings=SimpleNamespace(
                    states=lambda: states or {}, adverts=lambda: adverts or {}
                ),
                fetch_queue=queue.Queue(),
                counts={"fetched": 0},
                enqueue=lambda item: None,
                lossy=latest is not None,  # the newest seq each robot sent us itself
                state=state,
            )
        )

    def _fetch_answer(self, robot, kind, since, relay=False, via=None, held=()):
        self.asked.append((robot, since, relay, via))
        self.held = set(held)
        return self.answers.get(via, [])


def test_a_quiet_robot_is_asked_about_while_another_is_heard() -> None:
    assert Node(["b", "c"], quiet={"b"}).stalled() == ["b"]


def test_on_a_shared_channel_no_one_is_asked_about_a_quiet_robot() -> None:
    """It went quiet for every robot in range: no peer holds more of it to ask for."""
    assert Node(["b", "c"], quiet={"b"}, shared_channel=True).stalled() == []


def test_nothing_is_asked_when_no_one_is_heard_or_we_do_not_map() -> None:
    assert Node(["b", "c"], quiet={"b", "c"}).stalled() == []  # no robot in between
    assert Node(["b", "c"], quiet={"b"}, state=LINGER).stalled() == []  # adverts do it then


def test_a_lingering_robot_or_one_never_heard_is_not_asked_about() -> None:
    assert Node(["b", "c"], quiet={"b"}, states={"b": LINGER}).stalled() == []
    assert Node(["b", "c"], quiet={"b"}, held={"c": 2}).stalled() == []


def test_a_probe_asks_the_robots_in_between_without_an_advert() -> None:
    node = Node(["b", "c"], quiet={"b"})
    node.fetch({"b"})  # no advert says anyone holds more: no query
    assert node.asked == []
    node.fetch(set(node.stalled()), probe=True)
    assert node.asked == [("b", 3, True, None)]  # from its first gap, every holder answering


def test_on_a_lossy_link_a_gap_behind_a_robots_newest_submap_is_fetched_from_it() -> None:
    node = Node(["b", "c"], quiet=set(), held={"b": 3}, latest={"b": 5})
    node.fetch({"b"})  # b's submap 5 came, 3 and 4 did not: b holds them
    assert node.asked == [("b", 3, False, None)]
    node = Node(["b", "c"], quiet=set(), held={"b": 3})
    node.fetch({"b"})  # on a link that holds what it cannot carry yet, nothing to ask
    assert node.asked == []


def test_a_relayed_fetch_asks_the_one_peer_we_hear_holding_the_most() -> None:
    adverts = {"b": {"b": 9}, "c": {"b": 5}, "d": {"b": 6}, "e": {"b": 6}}
    node = Node(["b", "c", "d", "e"], quiet={"b"}, state=LINGER, adverts=adverts)
    node.answers["d"] = [(3, b"3")]
    node.fetch({"b"})
    assert node.asked == [("b", 3, True, "d")]  # b is quiet; d and e hold 6, d comes first
    assert node.held == {0, 1, 2}  # what arrived: the answer leaves it out
    node.answers.clear()
    node.asked.clear()
    node.fetch({"b"})  # d answers nothing (its link stalled): every peer is asked
    assert node.asked == [("b", 3, True, "d"), ("b", 3, True, None)]


def test_own_submaps_waiting_for_their_bundle_leave_now_not_in_the_answer() -> None:
    from gmmap.fleet.sharing import linkstats

    asked_now: list[bool] = []
    node = SimpleNamespace(
        robot="a",
        store=SimpleNamespace(fetch_provider=lambda r, k, since: [(0, b"0"), (1, b"1"), (2, b"2")]),
        outbox=SimpleNamespace(held=lambda kind: {2}, now=lambda: asked_now.append(True)),
    )
    provide = linkstats.provider(node)
    assert provide("a", "submap", 0) == [(0, b"0"), (1, b"1")]  # 2 leaves with its bundle
    assert asked_now == [True]
    assert provide("b", "submap", 0) == [(0, b"0"), (1, b"1"), (2, b"2")]  # not ours
    assert asked_now == [True]
