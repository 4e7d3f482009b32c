"""The mapping pipeline: submaps in, matches, optimised poses, frames between robots and maps out.

One `Mapper` is what a robot node runs online and what ``gmmap merge`` runs over whole folders:
it holds the submaps (own and received), describes them for place recognition (from the GMMs
only), verifies each candidate pair once by registration, keeps the robust pose graph and,
after `optimize`, the `TfGraph` of frames between robots and a global map per group. It never
sees ground truth; evaluation compares its outputs with it from the outside (`gmmap.eval`).

Matching is deterministic for a given set of held submaps: the submaps given to one `add` are
all held first, then each queries the others in (robot, seq) order, and every pair is judged
once, in the direction of the first query that found it. Fed the same submaps in one call, a
robot node and an offline merge judge the same pairs alike and optimise the same graph. Live,
submaps arrive one by one, so a pair is judged when the later of its two arrives, against
what is held then; `Mapper.rejudged` judges everything held again in one call, which is how
a robot ends with the maps an offline merge of its submaps gives, whatever the arrival order.

Thread safety: one lock guards the held state; registration (the slow part) runs outside it,
so one thread can match while another optimises.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.mapping.backend import BackendResult, PoseGraph
from gmmap.mapping.calibration import Calibration, features
from gmmap.mapping.confusion import Confusion, confusion
from gmmap.mapping.frontier import Horizon, seen_through
from gmmap.mapping.globalmap import GlobalMap, build_global_map
from gmmap.mapping.place import (
    Candidate,
    Match,
    PlaceDatabase,
    descriptor_for,
    distinct,
    turned,
)
from gmmap.mapping.submap import Submap, chain_of, horizons_in, local_map
from gmmap.mapping.tfgraph import TfGraph
from gmmap.math.gmm import Gmm
from gmmap.math.register import Registration, register

Node = tuple[str, int]
Progress = Callable[[str], None]
REACH = 2.0  # vertical standard deviations by which a surface reaches a built submap's rays
RAY_BAND = 0.05  # metres about the middle of a built submap's horizon band its rays are taken at
# Metres to which a built submap's horizons are trusted: farther, a 5° direction is wider than a
# pole or a door jamb its rays passed by. On the simulated office (seed 0), 4 m refuses 2-7 % of
# right alignments and catches 60-85 % of wrong ones (each sensor); uncapped 11-35 % and 69-100 %.
FREE_RANGE = 4.0


class Mapper:
    """See the module docstring. ``config`` supplies the place, register, backend and select
    sections."""

    def __init__(self, config: Config | None = None) -> None:
        self.config = config or Config()
        self.db = PlaceDatabase(
            descriptor_for(self.config.place),
            options=self.config.place,
            registration=self.config.register,
        )
        self.graph = PoseGraph(self.config.backend)
        self.calibration = Calibration.load(self.config.place.calibration)
        self.submaps: dict[Node, Submap] = {}
        self.matches: list[Match] = []  # every pair judged here, accepted or not, in order
        self.edge_matches: dict[int, Match] = {}  # backend edge id → the match it came from
        self.result: BackendResult | None = None
        self.frames = TfGraph()
        self._judged: set[frozenset[Node]] = set()
        # (query, candidate, their chains' lengths) → its registration before refinement:
        # deterministic, so reusable.
        self._registrations: dict[tuple[Node, Node, tuple[int, int]], Registration] = {}
        self._confusions: dict[Node, Confusion] = {}
        # Each submap's chain (`_members`) and its mixture, with how many submaps were held
        # when they were made.
        self._chains: dict[Node, tuple[int, list[Submap], Gmm]] = {}
        # Free space each submap's robot saw (its horizons, anchor frame), where given.
        self.horizons: dict[Node, list[Horizon]] = {}
        self._lock = threading.Lock()

    # ---- input ------------------------------------------------------------------------------

    def add(
        self,
        submaps: Iterable[Submap],
        progress: Progress | None = None,
        horizons: Mapping[Node, list[Horizon]] | None = None,
    ) -> list[Match]:
        """Holds ``submaps`` and verifies their unjudged candidate pairs; the accepted matches
        become pose-graph edges. ``horizons``: the free space their robots saw, where known
        (exploring robots share it), which a match must not fill. Returns the new matches."""
        with self._lock:
            self.horizons.update(horizons or {})
        new = self.hold(submaps)
        matches = self.verify(new, progress)
        for m in matches:
            self.add_match(m)
        return matches

    def hold(self, submaps: Iterable[Submap]) -> list[Submap]:
        """Describes ``submaps`` and adds their anchors to the graph; returns those not yet
        held, in (robot, seq) order."""
        new = []
        with self._lock:
            for s in sorted(submaps, key=lambda s: (s.robot, s.seq)):
                key = (s.robot, s.seq)
                if key in self.submaps:
                    continue
                self.submaps[key] = s
                self.db.add(s.robot, s.seq, s.gmm)
                self.graph.add_submap(s.robot, s.seq, s.anchor)
                new.append(s)
        return new

    def verify(self, submaps: Sequence[Submap], progress: Progress | None = None) -> list[Match]:
        """Each of ``submaps`` queries the held submaps of other robots; each candidate pair not
        judged before is registered (once) and judged. Adds no edges (see `add_match`)."""
        matches = []
        for i, s in enumerate(submaps):
            judged = [self._verified(s, c) for c in self._candidates(s)]
            judged = [self._unseen(s, m) if m.accepted else m for m in judged]
            with self._lock:
                anchors = {key: self.submaps[key].anchor for key in self._keys(judged)}
            judged = distinct(judged, anchors, self.config.place)
            judged = [self._unconfused(m) if m.accepted else m for m in judged]
            judged = [self._untwinned(s, m) if m.accepted else m for m in judged]
            judged = [self._refined(s, m) if m.accepted else m for m in judged]
            matches.extend(self._calibrated(self._pinned(m)) if m.accepted else m for m in judged)
            if progress and ((i + 1) % 10 == 0 or i + 1 == len(submaps)):
                accepted = sum(m.accepted for m in matches)
                progress(f"place recognition: {i + 1}/{len(submaps)} submaps, {accepted} verified")
        with self._lock:
            self.matches.extend(matches)
        return matches

    def _verified(self, s: Submap, c: Candidate) -> Match:
        pair = ((s.robot, s.seq), (c.robot, c.seq))
        # Live, a chain grows as its robot's later submaps arrive: a registration is reused
        # only by the same chains.
        chains = tuple(len(self._members(node)) for node in pair)
        reg = self._registrations.get((*pair, chains))
        if reg is None:
            reg = self._registrations[(*pair, chains)] = self.register_pair(s, pair[1])
        least = self.config.place.chain_min_confidence if max(chains) > 1 else None
        return self.db.judge(pair[0], c, reg, least)

    def register_pair(self, query: Submap, key: Node) -> Registration:
        """What verification registers ``query`` onto held submap ``key`` with: no initial
        guess, then the basins that fill either robot's seen free space dropped."""
        source, target = self._chain((query.robot, query.seq)), self._chain(key)
        return self._free_basin(query, key, self.db.register_pair(source, target))

    def _members(self, key: Node) -> list[Submap]:
        """Held submap ``key`` and its chain among the submaps held now (`chain_of`)."""
        return self._chain_of(key)[0]

    def _chain(self, key: Node) -> Gmm:
        """What verification registers held submap ``key`` as: it alone, or its chain
        (`_members`) merged in its anchor frame."""
        return self._chain_of(key)[1]

    def _chain_of(self, key: Node) -> tuple[list[Submap], Gmm]:
        """``key``'s chain and its mixture, made once per count of held submaps: verification
        asks for them for every basin and lookalike it checks."""
        with self._lock:
            held = len(self.submaps)
            cached = self._chains.get(key)
            if cached is not None and cached[0] == held:
                return cached[1], cached[2]
            members = chain_of(key, self.submaps, self.config.place)
            s = self.submaps[key]
        gmm = s.gmm if len(members) == 1 else local_map(members, s.anchor)
        with self._lock:
            self._chains[key] = (held, members, gmm)
        return members, gmm

    def _free_basins(self, query: Submap, key: Node, reg: Registration) -> tuple | None:
        """``reg``'s basins that put at most ``max_seen_through`` of either submap's surfaces
        where the other's robot saw free space, best first; None where that is unknown."""
        limit = self.config.place.max_seen_through
        if limit is None or not reg.basins:
            return None
        shares = [self._seen_through(query, key, T) for T, _ in reg.basins]
        if shares[0] is None:  # either robot's free space unknown
            return None
        return tuple(b for b, share in zip(reg.basins, shares, strict=True) if share <= limit)

    def _free_basin(self, query: Submap, key: Node, reg: Registration) -> Registration:
        """``reg`` with the basins that fill either robot's seen free space dropped
        (`_free_basins`): the best one left leads and the next one left is the alternative.
        Where alike places score higher than the right alignment, the wrong ones fill what
        was seen free."""
        free = self._free_basins(query, key, reg)
        if not free:
            return reg
        alternative = free[1][1] if len(free) > 1 else 0.0
        if free[0][0] is reg.basins[0][0]:
            return replace(reg, alternative_confidence=alternative, basins=free)
        source, target = self._chain((query.robot, query.seq)), self._chain(key)
        # Its information and confidence where it ends, at the search's finest scale.
        scale = self.config.register.global_scales[-1:]
        r = register(source, target, free[0][0], scales=scale, options=self.config.register)
        return replace(
            r,
            iterations=reg.iterations + r.iterations,
            time_s=reg.time_s + r.time_s,
            alternative_confidence=alternative,
            basins=free,
        )

    def _plausible(self, query: Submap, key: Node, reg: Registration) -> float:
        """The upright confidence of ``reg``'s best basin that fills no seen free space
        (`_free_basins`; every basin where unknown), 0 where none is left: a lookalike
        verification could take."""
        upright = reg.upright
        free = self._free_basins(query, key, reg)
        if free is None:
            return upright
        # Basins hold their upright C relative to the best one's C (`gmmap.math.register`).
        return free[0][1] * upright / reg.confidence if free and reg.confidence > 0 else 0.0

    def _free_view(self, key: Node) -> tuple[list[Horizon], np.ndarray, tuple, float] | None:
        """The free space held submap ``key``'s robot saw, over its chain (`_members`): the
        horizons (its anchor frame), the anchor, the heights (map frame) they hold and the
        `seen_through` reach; None where unknown. An exploring robot's (given to `add`) are at
        the heights its body occupies, a built submap's about its anchor."""
        members = self._members(key)
        with self._lock:
            s = self.submaps[key]
            given = {(m.robot, m.seq): self.horizons.get((m.robot, m.seq)) for m in members}
        inverse = np.linalg.inv(s.anchor)
        if given[key] is not None:
            views = [(m, given[(m.robot, m.seq)]) for m in members]
            return horizons_in(views, inverse), s.anchor, self.config.planner.z_band, 0.0
        if s.horizons is None or s.horizon_band is None:
            return None
        views = [(m, m.horizons) for m in members]
        # Its rays ran about the sensor's height: a surface counts where it spans that height
        # (a table top under the rays does not).
        z = float(s.anchor[2, 3]) + sum(s.horizon_band) / 2
        near = [
            Horizon(h.origin, np.minimum(h.ranges, FREE_RANGE)) for h in horizons_in(views, inverse)
        ]
        return near, s.anchor, (z - RAY_BAND, z + RAY_BAND), REACH

    def _seen_through(self, query: Submap, key: Node, T: np.ndarray) -> float | None:
        """The larger share of either submap's surfaces (query's moved by ``T`` onto held
        submap ``key``) inside the free space the other's robot saw; None where either's free
        space is unknown."""
        mine, theirs = self._free_view((query.robot, query.seq)), self._free_view(key)
        if mine is None or theirs is None:
            return None
        source, target = self._chain((query.robot, query.seq)), self._chain(key)
        return max(
            seen_through(*mine[:2], target.transform(np.linalg.inv(T)), *mine[2:]),
            seen_through(*theirs[:2], source.transform(T), *theirs[2:]),
        )

    def _unseen(self, query: Submap, m: Match) -> Match:
        """``m`` refused where it puts more than ``max_seen_through`` of either submap's
        surfaces inside the free space the other's robot saw (both known): a wall where rays
        went through, as a place alike turned round gives."""
        limit = self.config.place.max_seen_through
        key = (m.candidate.robot, m.candidate.seq)
        share = None if limit is None else self._seen_through(query, key, m.registration.transform)
        if share is None:
            return m
        return replace(m, accepted=share <= limit, seen_through=share)

    def _unconfused(self, m: Match) -> Match:
        """``m`` refused unless its confidence is clearly above (``max_confusion``) what either
        submap reaches against places its own robot knows are elsewhere, as verification would
        take them, and above (``max_any_confusion``) any alignment there at all
        (`gmmap.mapping.confusion`); all on the upright parts, as a search ranks solutions."""
        options = self.config.place
        mine = self._confusion(m.query)
        theirs = self._confusion((m.candidate.robot, m.candidate.seq))
        c = m.registration.upright
        plausible = max(mine.plausible, theirs.plausible) / c if c > 0 else 0.0
        every = max(mine.level, theirs.level) / c if c > 0 else 0.0
        accepted = plausible < options.max_confusion and every < options.max_any_confusion
        return replace(m, accepted=accepted, confusion=every, plausible_confusion=plausible)

    def _untwinned(self, query: Submap, m: Match) -> Match:
        """``m`` refused when its alignment turned half round scores within
        ``max_turned`` of it (`gmmap.mapping.place.turned`): a symmetric place."""
        limit = self.config.place.max_turned
        if limit is None:
            return m
        source = self._chain((query.robot, query.seq))
        target = self._chain((m.candidate.robot, m.candidate.seq))
        ratio = turned(source, target, m.registration, self.config.register)
        return replace(m, accepted=ratio < limit, turned=ratio)

    def _confusion(self, key: Node) -> Confusion:
        """The confusion of held submap ``key``, computed once, against what is held then."""
        if key not in self._confusions:
            with self._lock:
                held = dict(self.submaps)
            probes = self.config.place.confusion_probes
            query = held[key]
            self._confusions[key] = confusion(
                key,
                held,
                self.db,
                probes,
                lambda other, reg: self._plausible(query, other, reg),
                self._chain,
            )
        return self._confusions[key]

    def rejudged(self, progress: Progress | None = None) -> Mapper:
        """A fresh mapper over the same submaps, judged in one call and optimised, as an offline
        merge judges them; registrations already made are reused. Live, what each judgement
        saw depended on the order the submaps arrived in; this result does not."""
        fresh = Mapper(self.config)
        with self._lock:
            held = list(self.submaps.values())
            fresh._registrations = dict(self._registrations)
            fresh.horizons = dict(self.horizons)
        fresh.add(held, progress)
        fresh.optimize()
        return fresh

    def _refined(self, query: Submap, m: Match) -> Match:
        """``m`` with its pose (the query's chain's) refined against the candidate's local map
        (its chain and ±``refine_neighbours``), or rejected when that moves it more than
        ``max_refine_shift``; its confidence stays the verification's."""
        options = self.config.place
        k = options.refine_neighbours
        if k == 0:
            return m
        c = m.candidate
        chain = {s.seq for s in self._members((c.robot, c.seq))}
        with self._lock:
            near = [
                s for (robot, seq), s in self.submaps.items()
                if robot == c.robot and (abs(seq - c.seq) <= k or seq in chain)
            ]  # fmt: skip
            frame = self.submaps[(c.robot, c.seq)].anchor
        local = local_map(near, frame)
        source = self._chain((query.robot, query.seq))
        r = register(source, local, m.registration.transform, options=self.config.register)
        shift = np.linalg.norm(r.transform[:3, 3] - m.registration.transform[:3, 3])
        if shift > options.max_refine_shift:
            return replace(m, accepted=False)
        refined = replace(
            m.registration,
            transform=r.transform,
            information=r.information,
            time_s=m.registration.time_s + r.time_s,
        )
        return replace(m, registration=refined)

    def _pinned(self, m: Match) -> Match:
        """``m`` refused when its alignment leaves a direction nearly free: its translation
        information's `Registration.conditioning` under ``min_conditioning``. Two corridors
        that coincide anywhere along their length coincide at a wrong place as well as a
        right one."""
        if m.registration.conditioning >= self.config.place.min_conditioning:
            return m
        return replace(m, accepted=False)

    def _calibrated(self, m: Match) -> Match:
        """``m`` with its `Match.probability`, refused under ``min_probability`` (when set) or
        where the calibration never saw its like."""
        p = self.calibration.probability(features(m))
        floor = self.config.place.min_probability
        refused = floor is not None and (p is None or p < floor)
        return replace(m, probability=p, accepted=m.accepted and not refused)

    @staticmethod
    def _keys(matches: Sequence[Match]) -> set[Node]:
        return {(m.candidate.robot, m.candidate.seq) for m in matches}

    def _candidates(self, s: Submap) -> list[Candidate]:
        with self._lock:
            found = self.db.query(s.robot, s.seq, s.gmm, others_only=True)
            fresh = []
            for c in found:
                pair = frozenset({(s.robot, s.seq), (c.robot, c.seq)})
                if pair not in self._judged:
                    self._judged.add(pair)
                    fresh.append(c)
            return fresh

    def add_match(self, m: Match) -> int | None:
        """Adds an accepted match as a pose-graph edge (its id), or only records a rejected
        one as judged (None). Both submaps must be held."""
        target, source = (m.candidate.robot, m.candidate.seq), m.query
        with self._lock:
            self._judged.add(frozenset({target, source}))
            if not m.accepted:
                return None
            if target not in self.submaps or source not in self.submaps:
                raise InvalidInputError(f"match {source} → {target}: submap not held")
            r = m.registration
            edge = self.graph.add_match(target, source, r.transform, r.information, r.confidence)
            self.edge_matches[edge] = m
            return edge

    # ---- output -----------------------------------------------------------------------------

    def optimize(self) -> BackendResult:
        """Solves the pose graph and refreshes the frames between robots."""
        with self._lock:
            if not self.submaps:
                raise InvalidInputError("nothing to optimise: no submap held")
            result = self.graph.optimize()
            self.result, self.frames = result, TfGraph.from_result(result)
        return result

    def group_of(self, robot: str) -> list[str]:
        return next((g for g in self.frames.groups() if robot in g), [robot])

    def global_map(self, robot: str) -> GlobalMap | None:
        """The merged map of ``robot``'s group in its reference frame (None before `optimize`)."""
        result = self.result
        if result is None:
            return None
        group = self.group_of(robot)
        poses = {k: v for k, v in result.poses.items() if k[0] in group}
        with self._lock:
            held = [s for k, s in self.submaps.items() if k in poses]
        return build_global_map(held, poses, self.frames.reference(group), self.config.select)

    def global_maps(self, progress: Progress | None = None) -> dict[str, GlobalMap]:
        """One global map per group, by its reference robot."""
        maps = {}
        for group in self.frames.groups():
            if progress:
                progress(f"merging the global map of {', '.join(group)}")
            gmap = self.global_map(group[0])
            if gmap is not None:
                maps[gmap.reference] = gmap
        return maps

    def report(self) -> dict:
        """Frames, groups and edge counts (no ground truth): what ``gmmap merge`` prints."""
        b = self.result
        if b is None:
            raise InvalidInputError("report before optimize")
        robots = sorted({r for r, _ in self.submaps})
        return {
            "reference": self.frames.reference(self.frames.groups()[0]),
            "robots": [
                {
                    "name": r,
                    "reference": self.frames.reference(r),
                    "to_reference": np.asarray(self.frames.to_reference(r)).tolist(),
                    "submaps": sum(1 for x, _ in self.submaps if x == r),
                }
                for r in robots
            ],
            "groups": self.frames.groups(),
            "candidates": len(self.matches),
            "verified": sum(m.accepted for m in self.matches),
            "accepted_edges": len(b.accepted),
            "rejected_edges": len(b.rejected),
            "rejected_by": {
                why: list(b.rejected.values()).count(why) for why in {*b.rejected.values()}
            },
            "backend_time_s": b.time_s,
        }
