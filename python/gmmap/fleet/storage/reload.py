"""A restarted robot's state from its store (`gmmap.fleet.node.robot`): its own and received
submaps decoded and held by the mapper, and the pairs it had judged; pairs never judged are
left to the matching stage."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

from gmmap.errors import DecodeError
from gmmap.fleet.storage.records import match_of
from gmmap.fleet.storage.store import Store
from gmmap.fleet.wire.codec import decode
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.submap import Submap

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Reloaded:
    """How many submaps were held again, those still to judge, and the own ones by seq with
    the bytes each took on the wire."""

    held: int
    pending: list[Submap]
    own: dict[int, tuple[Submap, int]]


def reload(store: Store, mapper: Mapper, inner: Callable[[bytes], bytes], name: str) -> Reloaded:
    """Holds in ``mapper`` what ``store`` holds (``inner``: a stored message's encoded
    submap); what does not decode is dropped with a warning, and so is an edge it was in."""
    held, own = [], {}
    for rec in store.submaps():
        try:
            s = decode(inner(rec.payload))
        except DecodeError:
            log.warning("%s: stored %s/%d does not decode; dropped", name, rec.robot, rec.seq)
            continue
        held.append(s)
        if rec.own:
            own[s.seq] = (s, len(rec.payload))
    pending = mapper.hold(held)
    for e in store.edges():
        nodes = ((e.target_robot, e.target_seq), (e.source_robot, e.source_seq))
        if all(n in mapper.submaps for n in nodes):
            mapper.add_match(match_of(e))
        else:  # one of its submaps did not decode: judged again if it arrives again
            log.warning("%s: stored edge %s → %s lacks a submap; dropped", name, *nodes)
    return Reloaded(len(held), pending, own)
