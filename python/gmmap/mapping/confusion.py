"""How alike a submap is to places its own robot knows are elsewhere: a null for verification.

A match's confidence C says how well two mixtures coincide, not how likely that is by chance.
Scenes of floors, ceilings and plain walls (a 360° LiDAR over ±45°, a depth camera in a
corridor) make any two submaps coincide well somewhere, so C alone cannot tell a right match
from a wrong one there. Each robot can measure that chance level itself: its own submaps whose
odometry puts them apart (they do not coincide where odometry places them) are places it knows
to be different, so the best C a submap reaches against those, with no initial guess, is what C
a wrong match of it reaches. `confusion` is that level; `gmmap.mapping.mapper.Mapper` refuses a
match whose C is not clearly above it on either side (`PlaceOptions.max_confusion`). Both are
taken on the mixtures' upright parts (`Registration.upright_confidence`), where level planes,
alike under any shift, do not count.

A lookalike is a wrong match the verification would still take only where it fills no free space
either submap's robot saw: where submaps carry horizons, `confusion` also gives the level over
the lookalikes left once those that do are set aside (`Confusion.plausible`). The Mapper holds a
match to the strict margin against those and to plain superiority over all.

Where a robot never left its place (a desk recording) no own submap lies apart, the confusion is
0 and nothing changes. A robot that closed a loop has apart-by-odometry submaps that overlap;
they raise its confusion, which makes the test stricter, never looser.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from gmmap.mapping.place import PlaceDatabase
from gmmap.mapping.submap import Submap
from gmmap.math.gmm import Gmm
from gmmap.math.register import Registration, confidence

Node = tuple[str, int]

# Two own submaps are apart when their confidence where odometry places them is below this:
# right matches of overlapping submaps score 0.3 and more (the simulated office, TUM fr1_xyz).
APART = 0.1


@dataclass(frozen=True)
class Confusion:
    """The best confidence a submap reaches against places its robot knows are elsewhere:
    ``level`` over every lookalike, ``plausible`` over those that fill no seen free space."""

    level: float = 0.0
    plausible: float = 0.0


def confusion(
    key: Node,
    held: Mapping[Node, Submap],
    db: PlaceDatabase,
    probes: int,
    plausible: Callable[[Node, Registration], float] | None = None,
    gmm: Callable[[Node], Gmm] | None = None,
) -> Confusion:
    """The best no-guess confidence of submap ``key`` against up to ``probes`` of its robot's
    other held submaps that odometry puts apart, the most alike by descriptor first.
    ``plausible(other, registration)``: the confidence of that registration's best solution
    the free space leaves possible (0 where none); None: every solution is. ``gmm(node)``: the
    mixture a held submap is registered as (default: its own)."""
    gmm = gmm or (lambda node: held[node].gmm)
    query = held[key]
    own = [k for k in held if k[0] == key[0] and k != key]
    if probes < 1 or not own:
        return Confusion()
    vector = db.vector(key)
    distance = [1.0 - float(db.vector(k) @ vector) for k in own]
    level, possible, tried = 0.0, 0.0, 0
    for i in np.argsort(distance, kind="stable"):
        other = held[own[i]]
        odometry = np.linalg.inv(other.anchor) @ query.anchor
        if confidence(gmm(key), gmm(own[i]), odometry) >= APART:
            continue
        reg = db.register_pair(gmm(key), gmm(own[i]))
        level = max(level, reg.upright)
        possible = max(possible, reg.upright if plausible is None else plausible(own[i], reg))
        tried += 1
        if tried == probes:
            break
    return Confusion(level, possible)
