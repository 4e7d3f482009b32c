"""Which submaps a fleet lost: built, in reach of a peer at some moment after, and never
delivered to it (`gmmap demo`'s ``lost``). On links that come and go (rendezvous links) a
submap built after its robot left everyone's reach for good cannot be delivered by any
protocol: it counts as ``out_of_reach``, not as lost. Where contacts are brief, `lasting` and
`reachable`'s ``hold`` tell the losses that contacts long enough to open a session, and for
a robot in between to hand a submap on, could have prevented.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from gmmap.fleet.storage.store import Store


def lost(reports: dict[str, dict]) -> dict[str, int]:
    """Per robot, its submaps that some peer never received, counted once per peer: on links
    that stay (every robot in reach of every other, directly or through the robots in
    between), all are in reach; on rendezvous links see `lost_in_reach`."""
    built = {n: r["submaps_built"] for n, r in reports.items()}
    return {
        n: sum(max(0, built[n] - r["held"].get(n, 0)) for p, r in reports.items() if p != n)
        for n in sorted(reports)
    }


def links_up(
    up: Callable[[int, int, int], bool], pairs: Sequence[tuple[int, int]], n: int, frames: int
) -> np.ndarray:
    """(frames, n, n) bools: robots i and j linked at frame k (``up(i, j, k)``, i < j, for the
    linked ``pairs``)."""
    linked = np.zeros((frames, n, n), dtype=bool)
    for i, j in pairs:
        for k in range(frames):
            linked[k, i, j] = linked[k, j, i] = up(i, j, k)
    return linked


def lasting(linked: np.ndarray, frames: int) -> np.ndarray:
    """``linked`` (`links_up`) with only the contacts that last at least ``frames`` frames:
    a contact shorter than it takes a session to open and an advert to cross is no chance
    for a protocol that opens sessions. The links as they end count as lasting."""
    kept = np.zeros_like(linked)
    n = linked.shape[1]
    for i in range(n):
        for j in range(i + 1, n):
            up = linked[:, i, j]
            edges = np.flatnonzero(np.diff(np.concatenate([[0], up.astype(int), [0]])))
            for start, end in zip(edges[::2], edges[1::2], strict=True):
                if end - start >= frames or end == len(up):
                    kept[start:end, i, j] = kept[start:end, j, i] = True
    return kept


def reachable(linked: np.ndarray, origin: int, frame: int, hold: int = 0) -> set[int]:
    """The robots that a submap of ``origin`` finished at ``frame`` can reach hop by hop as the
    links come and go (after the last frame the links stay as they ended, as the robots do).
    With ``hold`` 0 a hop takes no time (any number within a frame): no protocol can do
    better. Else the origin's own hops still take none (it sends each submap at once), but a
    robot in between hands it on only over a link up for ``hold`` frames in a row while it
    holds it: time for an advert to cross and the submap to be asked for."""
    n = linked.shape[1]
    start = min(max(frame, 0), len(linked) - 1)
    got = np.zeros(n, dtype=bool)
    got[origin] = True
    run = np.zeros((n, n), dtype=int)  # frames each link has been up while its first end held
    for up in linked[start:]:
        if hold:
            run = np.where(up & got[:, None], run + 1, 0)
            got = got | up[origin] | (run >= hold).any(axis=0)
        else:
            got = _closure(got, up)
    got = _closure(got, linked[-1])  # the links as they ended: time enough for any hop
    return {int(i) for i in np.flatnonzero(got)} - {origin}


def _closure(got: np.ndarray, up: np.ndarray) -> np.ndarray:
    while True:
        more = got | up[got].any(axis=0)
        if (more == got).all():
            return got
        got = more


def lost_in_reach(
    stores: Mapping[str, Path],
    linked: np.ndarray,
    frame_at: Callable[[float], int],
    hold: int = 0,
) -> tuple[dict[str, int], dict[str, int]]:
    """Per robot (``stores``: name → store, in robot order), its submaps that some peer in
    reach after them never received (``lost``) and those no peer could reach
    (``out_of_reach``), counted once per peer. A submap can leave once it is in its robot's
    store: the frame the robots were at then (``frame_at``: Unix time → frame) is where its
    reach (`reachable`, each hop taking ``hold`` frames) starts."""
    names = list(stores)
    held: dict[str, set[tuple[str, int]]] = {}
    built: dict[str, dict[int, float]] = {}  # own submaps: seq -> when it was stored
    for name, path in stores.items():
        with Store(path, durable=False) as store:
            records = store.submaps()
        held[name] = {(r.robot, r.seq) for r in records}
        built[name] = {r.seq: r.received for r in records if r.own}
    lost = dict.fromkeys(names, 0)
    out_of_reach = dict.fromkeys(names, 0)
    for i, name in enumerate(names):
        for seq, stored in built[name].items():
            reach = reachable(linked, i, frame_at(stored), hold)
            for j, peer in enumerate(names):
                if j != i and (name, seq) not in held[peer]:
                    counts = lost if j in reach else out_of_reach
                    counts[name] += 1
    return lost, out_of_reach
