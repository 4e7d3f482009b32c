"""What each robot holds, told to its peers, so that a robot ends only once the peers in reach
hold what it holds and it holds what they hold (`gmmap.fleet.node.robot.RobotNode.linger`).

An advert is the message ``gmmap/<fleet>/<robot>/have/<n>``: how many submaps of each robot the
sender holds, its state, the robots it hears directly, and the robots it knows to be done
mapping with how many submaps each built, in a few bytes per robot (`encode`; the layout is in
docs/wire-format.md, "Adverts"). Counts, not sets: a robot's submaps are numbered from 0 and a
peer that holds as many holds the same ones unless a gap is still being filled, which the next
advert shows. The state is ``mapping`` while the sender's own frames last, then ``linger`` while
it waits for its peers, and ``final`` in its last advert: it is done (none is needed where its
last ``linger`` one said all, `Holdings.at_rest`). A peer that vanished without a final one (a
partition, a crash) is still waited for, by its last advert, until the deadline. The robots done
mapping travel on from advert to advert (`Holdings.finished`), so that a robot at one end of a
chain knows when one at the other end, which it never hears, has built its last submap, and
waits until it holds that one too (`Holdings.unfinished`). A malformed or oversized advert is
ignored, never trusted.
"""

from __future__ import annotations

import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from gmmap.errors import DecodeError
from gmmap.fleet.wire.bitstream import _Reader, _Writer

KIND = "have"
# What a robot holds goes to a peer SETTLE_S after it joins (if it holds anything); and while
# the robot lingers, whenever it changes (`Holdings.is_news`) and then rests for SETTLE_S, at
# most once per SETTLE_S (`advert_due`), and every ADVERT_EVERY_S in case one was lost. Each
# advert costs about 10 B of payload per robot it names and two packets per peer.
SETTLE_S = 1.0
ADVERT_EVERY_S = 30.0
FETCH_EVERY_S = 5.0  # at most this often a catch-up fetch, while a peer holds more
PROGRESS_EVERY_S = 5.0
MAX_BYTES = 65_536
MAX_ROBOTS = 1_024
MAX_COUNT = 2**62


MAPPING, LINGER, FINAL = STATES = ("mapping", "linger", "final")


@dataclass(frozen=True)
class Advert:
    """What a peer told: its counts, its state, the robots it hears directly (``reach``) and
    those it knows to be done mapping, with how many submaps each built (``done``)."""

    held: dict[str, int]
    state: str = MAPPING
    reach: tuple[str, ...] = ()
    done: dict[str, int] = field(default_factory=dict)


def encode(
    counts: Mapping[str, int],
    state: str = MAPPING,
    reach: Iterable[str] = (),
    done: Mapping[str, int] | None = None,
) -> bytes:
    if state not in STATES:
        raise ValueError(f"an advert's state is one of {STATES}, not {state!r}")
    w = _Writer()
    w.u8(STATES.index(state))
    names = sorted(counts)
    w.uvarint(len(names))
    for name in names:
        w.name(name)
        w.uvarint(counts[name])
    index = {name: i for i, name in enumerate(names)}
    heard = sorted(reach)
    w.uvarint(len(heard))
    for name in heard:
        _ref(w, name, index)
    done = done or {}
    w.uvarint(len(done))
    for name in sorted(done):
        _ref(w, name, index)
        w.uvarint(done[name])
    return bytes(w.buf)


def _ref(w: _Writer, name: str, index: Mapping[str, int]) -> None:
    """A robot as its index among the counted ones, or, past them, its name."""
    w.uvarint(index.get(name, len(index)))
    if name not in index:
        w.name(name)


def decode(payload: bytes) -> Advert | None:
    """The advert in ``payload``, or None when it is not one."""
    if len(payload) > MAX_BYTES:
        return None
    r = _Reader(payload)
    try:
        state = STATES[r.uvarint("state", len(STATES) - 1)]
        names, counts = [], {}
        for _ in range(r.uvarint("robots", MAX_ROBOTS)):
            names.append(r.name("robot"))
            counts[names[-1]] = r.uvarint("count", MAX_COUNT)
        reach = [_read_ref(r, names) for _ in range(r.uvarint("robots heard", MAX_ROBOTS))]
        done = {}
        for _ in range(r.uvarint("robots done", MAX_ROBOTS)):
            name = _read_ref(r, names)
            done[name] = r.uvarint("built", MAX_COUNT)
        if r.pos != len(payload) or len(counts) != len(names):
            return None  # trailing bytes, or a robot named twice
    except DecodeError:
        return None
    return Advert(counts, state, tuple(reach), done)


def _read_ref(r: _Reader, names: list[str]) -> str:
    i = r.uvarint("robot", len(names))
    return names[i] if i < len(names) else r.name("robot")


class Holdings:
    """The latest advert of every peer (thread-safe: Zenoh's thread writes, the node reads)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._peers: dict[str, Advert] = {}
        self._met: set[str] = set()
        self._fresh: set[str] = set()  # joined, and no advert from it since
        self._seqs: dict[str, int] = {}  # the number of each peer's latest advert

    def meet(self, peer: str) -> None:
        """A peer joined: from now on it is waited for until it says it is done."""
        with self._lock:
            self._met.add(peer)
            self._fresh.add(peer)

    def caught_up(self, peer: str) -> bool:
        """True once for a peer's first advert after it joined (after `update`)."""
        with self._lock:
            first = peer in self._fresh and peer in self._peers
            if first:
                self._fresh.discard(peer)
        return first

    def update(self, peer: str, payload: bytes, seq: int | None = None) -> bool:
        """Takes ``peer``'s advert number ``seq``; False (ignored) if it is not one, or not
        newer than the last taken (a replay, or one overtaken on the way)."""
        advert = decode(payload)
        if advert is None:
            return False
        with self._lock:
            if seq is not None and seq <= self._seqs.get(peer, -1):
                return False
            self._peers[peer] = advert
            if seq is not None:
                self._seqs[peer] = seq
        return True

    def adverts(self) -> dict[str, dict[str, int]]:
        """The latest counts each peer told."""
        with self._lock:
            return {peer: dict(a.held) for peer, a in self._peers.items()}

    def states(self) -> dict[str, str]:
        """The state each peer's latest advert told."""
        with self._lock:
            return {peer: a.state for peer, a in self._peers.items()}

    def is_news(
        self,
        mine: Mapping[str, int],
        told: Mapping[str, int],
        state: str,
        present: Iterable[str],
        quiet: Iterable[str] = (),
        done: tuple[Mapping[str, int], Mapping[str, int]] = ({}, {}),
    ) -> bool:
        """Whether a lingering robot's holdings ``mine`` are news to its peers since its last
        advert (``told``, in ``state``): that advert said it was still mapping; or a present
        peer could fetch from us submaps of a robot out of its reach that neither it nor
        ``told`` holds (only robots in between carry those); or a present peer that lingers
        (so may end on what we told it) now sees us hold all it holds, which it did not,
        unless a robot it hears, and we hear, has not told us it lingers: that robot's last
        submaps are still to come, and the peer cannot end before news of them anyway; or a
        present peer does not know that a robot out of its reach is done mapping (``done``:
        the robots we know to be done, and those we told, each with its total; `finished`).
        Partial catching up is no news, nor are the submaps of robots a peer hears itself: in
        a full mesh an advert a second would cost more than the submaps' own overhead.

        A robot in ``quiet`` (present, but it sent us nothing itself lately) that last said
        it maps has left our reach, whatever its session says (a rendezvous link keeps it
        until Zenoh's lease ends): it is waited for by no one near us, and taken to be out
        of our peers' reach too, so what we hold of it is news to them."""
        if state == MAPPING:
            return True
        present = set(present)
        with self._lock:
            adverts = {p: self._peers[p] for p in present if p in self._peers}
        mapping = {p for p in present if p not in adverts or adverts[p].state == MAPPING}
        gone = mapping & set(quiet)
        mapping -= gone
        finished, told_done = done
        for peer, theirs in adverts.items():
            if peer in gone:
                continue
            held, reach = theirs.held, {peer, *theirs.reach} - gone
            more = any(
                n > max(held.get(r, 0), told.get(r, 0)) for r, n in mine.items() if r not in reach
            )
            covers = all(mine.get(r, 0) >= n for r, n in held.items())
            covered = all(told.get(r, 0) >= n for r, n in held.items())
            ends = theirs.state == LINGER and not mapping & reach
            ended = any(
                n not in (theirs.done.get(r), told_done.get(r))
                for r, n in finished.items()
                if r not in reach
            )
            if more or ended or (ends and covers and not covered):
                return True
        return False

    def finished(self, robot: str, state: str, mine: Mapping[str, int]) -> dict[str, int]:
        """The robots known to be done mapping, each with how many submaps it built: peers
        whose own advert said so, robots a peer's advert said so of, and ``robot`` (we, in
        ``state``, holding ``mine``) once it lingers."""
        with self._lock:
            adverts = dict(self._peers)
        done: dict[str, int] = {}
        for peer, a in adverts.items():
            told = {**a.done, peer: a.held.get(peer, 0)} if a.state != MAPPING else a.done
            for r, n in told.items():
                done[r] = max(done.get(r, 0), n)
        done.pop(robot, None)
        if state != MAPPING:
            done[robot] = mine.get(robot, 0)
        return done

    def unfinished(self, robot: str, done: Mapping[str, int], mine: Mapping[str, int]) -> list[str]:
        """The robots we know of (met, or named in an advert) not known to be done mapping
        (``done``, `finished`), or whose last submaps we do not hold yet: a robot that left
        before those reached it would miss them, and so might the robots beyond it."""
        with self._lock:
            known = set(self._met)
            for a in self._peers.values():
                known.update(a.held, a.reach, a.done)
        known = (known | set(mine)) - {robot}
        return sorted(r for r in known if r not in done or mine.get(r, 0) < done[r])

    def at_rest(self, robot: str) -> bool:
        """Whether every peer ``robot`` met told it is done mapping, and so did every robot
        those peers hear: none of them can come to hold a submap we lack, so a robot that
        leaves holding what they hold needs no final advert, its last one says it all."""
        with self._lock:
            adverts, met = dict(self._peers), set(self._met)
        done = {p for p, a in adverts.items() if a.state != MAPPING}
        heard = {r for a in adverts.values() for r in a.reach} - {robot}
        return done == set(adverts) and met | heard <= done

    def relaying(self, mine: Mapping[str, int], present: Iterable[str]) -> bool:
        """Whether a present peer does not hear directly some robot we hold: we may be its
        way to that robot's submaps (a chain, a rendezvous), so what we hold is news to it
        as it grows, not only once it rests."""
        with self._lock:
            adverts = [(p, self._peers[p]) for p in present if p in self._peers]
        return any(set(mine) - {p, *a.reach} for p, a in adverts)

    def lacking(self, mine: Mapping[str, int], present: Iterable[str]) -> dict[str, dict[str, int]]:
        """Per peer that does not hold what we hold, or holds more: ``they_lack`` and
        ``we_lack``, submaps summed over robots (-1 each while a present peer has not told
        us). The peers are those present and those met that left without a final advert."""
        with self._lock:
            adverts, met = dict(self._peers), set(self._met)
        gone = {p for p in met | set(adverts) if p not in adverts or adverts[p].state != FINAL}
        known = {p: adverts[p].held if p in adverts else None for p in {*present, *gone}}
        out = {}
        for peer, theirs in sorted(known.items()):
            if theirs is None:  # present or met, and silent
                out[peer] = {"they_lack": -1, "we_lack": -1}
                continue
            they = sum(max(0, n - theirs.get(r, 0)) for r, n in mine.items())
            we = sum(max(0, n - mine.get(r, 0)) for r, n in theirs.items())
            if they or we:
                out[peer] = {"they_lack": they, "we_lack": we}
        return out


def advert_due(now: float, news: bool, told_at: float) -> bool:
    """Whether a lingering robot advertises now (times in s): what it holds, when that is
    ``news``, at most once per SETTLE_S after the last advert (``told_at``), and ADVERT_EVERY_S
    after it in any case. News goes at once: a robot in between hands on what it holds, and
    the robots at the ends wait only as long as they hear of more."""
    return (news and now >= told_at + SETTLE_S) or now >= told_at + ADVERT_EVERY_S


def wanted(adverts: Mapping[str, Mapping[str, int]], mine: Mapping[str, int]) -> list[str]:
    """The robots some advert holds more submaps of than ``mine``: the fetches worth a query."""
    return sorted({r for held in adverts.values() for r, n in held.items() if n > mine.get(r, 0)})


def describe(lacking: dict[str, dict[str, int]], unfinished: Iterable[str] = ()) -> str:
    """``lacking`` (`Holdings.lacking`) and ``unfinished`` (`Holdings.unfinished`) as words."""
    why = "still mapping, or its last submaps on the way"
    parts = [f"{r} ({why})" for r in unfinished if r not in lacking]
    for peer, v in sorted(lacking.items()):
        if v["they_lack"] < 0:
            parts.append(f"{peer} (no advert yet)")
        else:
            parts.append(f"{peer} (lacks {v['they_lack']} of ours, holds {v['we_lack']} more)")
    return ", ".join(parts)
