"""What each robot holds, told to its peers, so that a robot ends only once the peers in reach
hold what it holds and it holds what they hold (`gmmap.fleet.robot.RobotNode.linger`).

An advert is the message ``gmmap/<fleet>/<robot>/have/<n>``; its payload is compact JSON,
``{"held":{"robot_0":9,"robot_1":7},"final":false}``: how many submaps of each robot the
sender holds. Counts, not sets: a robot's submaps are numbered from 0 and a peer that holds as
many holds the same ones unless a gap is still being filled, which the next advert shows. A
robot's last advert is ``final``: it is done. A peer that vanished without one (a partition, a
crash) is still waited for, by its last advert, until the deadline. A malformed or oversized
advert is ignored, never trusted.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Iterable, Mapping

from gmmap.names import NAME_RE

KIND = "have"
# What a robot holds goes to a peer SETTLE_S after it joins (if it holds anything); and while
# the robot lingers, whenever it changes, at most once per SETTLE_S (`advert_due`), and every
# ADVERT_EVERY_S in case one was lost. Each advert costs about 80 B of payload and two packets
# per peer.
SETTLE_S = 1.0
ADVERT_EVERY_S = 30.0
FETCH_EVERY_S = 5.0  # at most this often a catch-up fetch, while a peer holds more
PROGRESS_EVERY_S = 5.0
MAX_BYTES = 65_536
MAX_ROBOTS = 1_024


def encode(counts: Mapping[str, int], final: bool = False) -> bytes:
    advert = {"held": dict(sorted(counts.items())), "final": final}
    return json.dumps(advert, separators=(",", ":")).encode()


def decode(payload: bytes) -> tuple[dict[str, int], bool] | None:
    """The counts and the final flag of an advert, or None when it is not one."""
    if len(payload) > MAX_BYTES:
        return None
    try:
        advert = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None
    if not isinstance(advert, dict) or set(advert) != {"held", "final"}:
        return None
    counts, final = advert["held"], advert["final"]
    if not isinstance(counts, dict) or len(counts) > MAX_ROBOTS or type(final) is not bool:
        return None
    for name, n in counts.items():
        if not NAME_RE.fullmatch(name) or type(n) is not int or n < 0:
            return None
    return counts, final


class Holdings:
    """The latest advert of every peer (thread-safe: Zenoh's thread writes, the node reads)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._peers: dict[str, tuple[dict[str, int], bool]] = {}
        self._met: set[str] = set()
        self._fresh: set[str] = set()  # joined, and no advert from it since

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

    def update(self, peer: str, payload: bytes) -> bool:
        advert = decode(payload)
        if advert is not None:
            with self._lock:
                self._peers[peer] = advert
        return advert is not None

    def adverts(self) -> dict[str, dict[str, int]]:
        """The latest counts each peer told."""
        with self._lock:
            return {peer: dict(held) for peer, (held, _) in self._peers.items()}

    def lacking(self, mine: Mapping[str, int], present: Iterable[str]) -> dict[str, dict[str, int]]:
        """Per peer that does not hold what we hold, or holds more: ``they_lack`` and
        ``we_lack``, submaps summed over robots (-1 each while a present peer has not told
        us). The peers are those present and those met that left without a final advert."""
        with self._lock:
            adverts, met = dict(self._peers), set(self._met)
        gone = {p for p in met | set(adverts) if not adverts.get(p, ({}, False))[1]}
        known = {p: adverts[p][0] if p in adverts else None for p in {*present, *gone}}
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


def describe(lacking: dict[str, dict[str, int]]) -> str:
    """``lacking`` (`Holdings.lacking`) as words."""
    parts = []
    for peer, v in sorted(lacking.items()):
        if v["they_lack"] < 0:
            parts.append(f"{peer} (no advert yet)")
        else:
            parts.append(f"{peer} (lacks {v['they_lack']} of ours, holds {v['we_lack']} more)")
    return ", ".join(parts)
