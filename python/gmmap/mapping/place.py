"""Place recognition from GMM submaps alone (paper V-A).

Every robot describes the submaps it holds (its own and those it received) locally: nothing but
the GMM crosses the network. A GMM is Monte-Carlo resampled to a fixed, seeded number of points
and a descriptor turns those points into a unit vector; candidates are the nearest descriptors by
cosine distance, and each candidate is verified by registration, whose geometric confidence C
decides (the paper's C_thr).

A descriptor is anything with ``describe_points(points) -> vector``, optionally
``candidate_distance`` (its candidates' cosine distance limit) and
``yaw(source_points, target_points) -> radians`` to hint the registration;
``place.descriptor`` picks one (`descriptor_for`): "learned" is the paper's PointNetVLAD on
4,096 resampled points (`gmmap.mapping.learned`). The default, "shape",
`ShapeDescriptor`, needs no training and no download: the D2 shape distribution (Osada et al.
2002) split into horizontal distance and height difference. Both are invariant to a yaw and a
translation of the submap, which is all that separates two robots' levelled anchor frames, and
neither depends on where inside the place the robot stood (a polar Scan-Context grid around the
anchor does, and recalled fewer places in the simulated office; see the issue notes).
Its yaw estimate is Scan Context's (Kim and Kim 2018): the circular shift that best aligns two
polar height grids centred on the points' centroids.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from gmmap import _core
from gmmap.errors import InvalidInputError
from gmmap.math.geometry import pose_distance
from gmmap.math.gmm import Gmm
from gmmap.math.points import as_points
from gmmap.math.register import Registration, apart, register
from gmmap.options import PlaceOptions, RegisterOptions

RESAMPLE_POINTS = PlaceOptions.resample_points
SHAPE_CANDIDATE_DISTANCE = 0.1  # the shape descriptor's cosine distance limit


def resample(gmm: Gmm, n: int = RESAMPLE_POINTS, seed: int = 0) -> np.ndarray:
    """``n`` points Monte-Carlo sampled from ``gmm`` (deterministic for ``seed``)."""
    if len(gmm) == 0:
        raise InvalidInputError("cannot resample an empty GMM")
    return gmm.sample(n, seed)


class Descriptor(Protocol):
    """What the place database needs from a descriptor."""

    def describe_points(self, points: np.ndarray) -> np.ndarray:
        """A finite vector of a fixed length for an (N, 3) cloud in a levelled frame."""
        ...


def _unit(v: np.ndarray) -> np.ndarray:
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


@dataclass(frozen=True)
class ShapeDescriptor:
    """Joint histogram of (horizontal distance, |height difference|) over point pairs.

    ``pairs`` point pairs drawn independently (seeded) from all the points, counted in the Rust
    core: the histogram's noise falls as 1/sqrt(pairs). (All pairs of a 768-point subsample,
    the earlier descriptor, carry the noise of 768 points however many pairs that is: recall@1
    in the simulated office swung by ±10 points with the subsample's seed.) The square root of
    the normalised histogram makes the cosine distance a Hellinger distance. The Scan-Context
    grid for `yaw`: ``rings`` × ``sectors`` cells out to ``max_distance``, each keeping its
    highest point.
    """

    pairs: int = 3_000_000
    distance_bins: int = 24
    max_distance: float = 8.0
    height_bins: int = 8
    max_height: float = 3.0
    rings: int = 20
    sectors: int = 60
    seed: int = 0

    def __post_init__(self) -> None:
        counts = (self.pairs, self.distance_bins, self.height_bins, self.rings, self.sectors)
        if min(counts) < 1 or not (self.max_distance > 0 and self.max_height > 0):
            raise InvalidInputError(
                "ShapeDescriptor needs pairs, bins, rings, sectors >= 1 and "
                "positive max_distance and max_height"
            )

    def describe_points(self, points: np.ndarray) -> np.ndarray:
        p = as_points(points, "points")
        if len(p) < 2:
            raise InvalidInputError(f"a descriptor needs at least 2 points, got {len(p)}")
        hist = _core.pair_histogram(
            np.ascontiguousarray(p, dtype=np.float64),
            self.pairs,
            self.distance_bins,
            self.max_distance,
            self.height_bins,
            self.max_height,
            self.seed,
        )
        return _unit(np.sqrt(hist))

    def polar(self, points: np.ndarray) -> np.ndarray:
        """The Scan-Context grid around the centroid: highest point above the lowest per cell."""
        p = as_points(points, "points")
        d = p[:, :2] - p[:, :2].mean(axis=0)
        ring = np.minimum(
            (np.hypot(d[:, 0], d[:, 1]) / self.max_distance * self.rings).astype(int),
            self.rings - 1,
        )
        angle = np.arctan2(d[:, 1], d[:, 0])
        sector = ((angle + math.pi) / (2 * math.pi) * self.sectors).astype(int) % self.sectors
        grid = np.zeros((self.rings, self.sectors))
        np.maximum.at(grid, (ring, sector), p[:, 2] - p[:, 2].min())
        return grid

    def yaw(self, source: np.ndarray, target: np.ndarray) -> float:
        """The yaw (rad) that turns ``source`` onto ``target``, to one sector, by the circular
        cross-correlation of their polar grids (all shifts at once through the FFT)."""
        a, b = self.polar(source), self.polar(target)
        spectrum = np.conj(np.fft.rfft(a, axis=1)) * np.fft.rfft(b, axis=1)
        corr = np.fft.irfft(spectrum, n=self.sectors)
        shift = int(np.argmax(corr.sum(axis=0)))
        yaw = shift * 2 * math.pi / self.sectors
        return (yaw + math.pi) % (2 * math.pi) - math.pi


def descriptor_for(options: PlaceOptions) -> Descriptor:
    """The descriptor ``options.descriptor`` names: "shape" or "learned" (its weights)."""
    if options.descriptor == "learned":
        from gmmap.mapping.learned import WEIGHTS, LearnedDescriptor

        return LearnedDescriptor(options.weights or str(WEIGHTS))
    return ShapeDescriptor()


@dataclass(frozen=True)
class Candidate:
    robot: str
    seq: int
    distance: float  # cosine distance of the descriptors, in [0, 2]


@dataclass(frozen=True)
class Match:
    """A verified (or rejected) candidate: ``registration.transform`` maps the query submap's
    anchor frame into the candidate's. ``conflict``: the best confidence, relative to this
    one's, of another verified candidate of the same query in the same robot's map that puts
    the query elsewhere (`distinct`); ``confusion``: see `gmmap.mapping.confusion`; ``turned``:
    see `turned`."""

    query: tuple[str, int]
    candidate: Candidate
    registration: Registration
    accepted: bool
    conflict: float = 0.0
    # The higher of the two submaps' `gmmap.mapping.confusion`, relative to this confidence:
    # over every lookalike, and over those that fill no seen free space.
    confusion: float = 0.0
    plausible_confusion: float = 0.0
    # The confidence of this alignment turned half round (`turned`), relative to this one.
    turned: float = 0.0
    # The share of either submap's surfaces this alignment puts where the other's robot saw
    # free space (`gmmap.mapping.frontier.seen_through`); 0 where no horizons are held.
    seen_through: float = 0.0
    # P(right) (`gmmap.mapping.calibration`) of a match that passed the tests up to
    # refinement; None before that, or where the calibration never saw its like.
    probability: float | None = None


def distinct(
    matches: Sequence[Match], anchors: Mapping[tuple[str, int], np.ndarray], options: PlaceOptions
) -> list[Match]:
    """``matches`` (one query's, all its candidates) with each one's `Match.conflict` (the best
    competitor's upright C over its own, `Registration.upright`), accepted only while that
    stays ≤ ``options.max_conflict``.

    Two candidates in one robot's map that both take the query, at places more than
    ``conflict_distance`` m or ``conflict_angle`` degrees apart, cannot both be right: the
    query looks like two places of that map (a corridor like another). The query's anchor as
    each candidate puts it, ``anchor(candidate) · T``, is compared in the candidate robot's
    map. Only competitors that pass verification themselves count: with rejected ones too, a
    robot that receives submaps one by one meets different weak competitors in each arrival
    order, and two LiDAR robots of the demo that meet once joined in only half of the orders.
    """
    placed = [
        anchors[(m.candidate.robot, m.candidate.seq)] @ m.registration.transform for m in matches
    ]
    out = []
    for i, m in enumerate(matches):
        best = 0.0
        for j, o in enumerate(matches):
            if j == i or o.candidate.robot != m.candidate.robot or not o.accepted:
                continue
            t, angle = pose_distance(placed[i], placed[j])
            if t > options.conflict_distance or angle > options.conflict_angle:
                best = max(best, o.registration.upright)
        own = m.registration.upright
        conflict = best / own if own > 0 else 0.0
        accepted = m.accepted and conflict <= options.max_conflict
        out.append(replace(m, accepted=accepted, conflict=conflict))
    return out


def turned(query: Gmm, candidate: Gmm, match: Registration, options: RegisterOptions) -> float:
    """The confidence of ``match``'s alignment turned half round about +z through the query's
    centre and refined from there, relative to ``match``'s own, both on the upright parts
    (`Registration.upright_confidence`: a floor lines up both ways); 0 when the refinement falls
    back into ``match``'s basin (`gmmap.math.register.apart`).

    A corridor seen end for end, or a room with two like halves, lines up both ways. The
    global search holds a second basin only where one of its starts led there, so it often
    misses that twin; probing it directly does not. Close to 1, or above: the place is
    symmetric and this match cannot tell which way round it is.
    """
    own = match.upright
    if own <= 0:
        return 0.0
    T = match.transform
    twin = register(query, candidate, half_turned(query, T), options=options)
    return twin.upright / own if apart(twin.transform, T) else 0.0


def half_turned(query: Gmm, transform: np.ndarray) -> np.ndarray:
    """``transform`` followed by a half turn about +z through where it puts the query's
    centre."""
    centre = transform[:3, :3] @ (query.weights @ query.means) + transform[:3, 3]
    half = np.diag([-1.0, -1.0, 1.0, 1.0])
    half[:2, 3] = 2 * centre[:2]
    return half @ transform


@dataclass
class PlaceDatabase:
    """One robot's descriptors of every submap it holds, own and received."""

    descriptor: Descriptor = field(default_factory=ShapeDescriptor)
    options: PlaceOptions = field(default_factory=PlaceOptions)
    registration: RegisterOptions = field(default_factory=RegisterOptions)
    keys: list[tuple[str, int]] = field(default_factory=list)
    gmms: dict[tuple[str, int], Gmm | None] = field(default_factory=dict)
    _vectors: list[np.ndarray] = field(default_factory=list)
    _index: dict[tuple[str, int], int] = field(default_factory=dict)
    _matrix: np.ndarray | None = None
    _robots: np.ndarray | None = None
    _seqs: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.keys)

    @property
    def max_distance(self) -> float:
        """The candidates' cosine distance limit: the options', else the descriptor's."""
        if self.options.max_distance is not None:
            return self.options.max_distance
        return float(getattr(self.descriptor, "candidate_distance", SHAPE_CANDIDATE_DISTANCE))

    def vector(self, key: tuple[str, int]) -> np.ndarray:
        """The held submap ``key``'s unit descriptor."""
        return self._vectors[self._index[key]]

    def describe(self, gmm: Gmm) -> np.ndarray:
        points = resample(gmm, self.options.resample_points)
        return _unit(np.asarray(self.descriptor.describe_points(points), dtype=float))

    def add(self, robot: str, seq: int, gmm: Gmm | None, vector: np.ndarray | None = None) -> None:
        """Describes and stores a submap (``gmm`` None with a ``vector``: search only)."""
        key = (robot, int(seq))
        if key in self.gmms:
            return
        if vector is None and gmm is None:
            raise InvalidInputError("add needs a GMM or a descriptor vector")
        self._index[key] = len(self.keys)
        self.keys.append(key)
        self.gmms[key] = gmm
        self._vectors.append(self.describe(gmm) if vector is None else _unit(vector))
        self._matrix = None

    def query(
        self, robot: str, seq: int, gmm: Gmm, k: int | None = None, others_only: bool = False
    ) -> list[Candidate]:
        """The ``k`` nearest submaps under ``max_distance``, nearest first, excluding the query
        itself and its robot's ``skip_recent`` submaps before it (``others_only``: all of its
        robot's submaps). A submap already in the database is not described again."""
        key = (robot, int(seq))
        known = key in self.gmms and self.gmms[key] is gmm
        vector = self._vectors[self._index[key]] if known else self.describe(gmm)
        return self.search(vector, robot, seq, k, others_only)

    def search(
        self,
        vector: np.ndarray,
        robot: str = "",
        seq: int = -1,
        k: int | None = None,
        others_only: bool = False,
    ) -> list[Candidate]:
        """`query` with the query's descriptor already computed."""
        if not self.keys:
            return []
        if self._matrix is None:
            self._matrix = np.array(self._vectors)
            self._robots = np.array([r for r, _ in self.keys])
            self._seqs = np.array([q for _, q in self.keys])
        distance = 1.0 - self._matrix @ _unit(np.asarray(vector, dtype=float))
        own = self._robots == robot
        if not others_only:
            own &= (self._seqs >= seq - self.options.skip_recent) & (self._seqs <= seq)
        distance[own] = np.inf
        k = min(k or self.options.top_k, len(distance))
        best = np.argpartition(distance, k - 1)[:k]
        best = best[np.argsort(distance[best], kind="stable")]
        limit = self.max_distance
        return [Candidate(*self.keys[i], float(distance[i])) for i in best if distance[i] <= limit]

    def verify(self, robot: str, seq: int, gmm: Gmm, candidate: Candidate) -> Match:
        """Registers the query onto the candidate with no initial guess (yaw hint from the
        descriptor when it has one) and accepts it when its `score` ≥ ``min_confidence``."""
        target = self.gmms[(candidate.robot, candidate.seq)]
        if target is None:
            raise InvalidInputError(f"{candidate.robot}/{candidate.seq} has no GMM to verify")
        return self.judge((robot, seq), candidate, self.register_pair(gmm, target))

    def judge(
        self,
        query: tuple[str, int],
        candidate: Candidate,
        reg: Registration,
        least: float | None = None,
    ) -> Match:
        """The match of a registered pair, accepted when its `score` ≥ ``least`` (default:
        ``min_confidence``)."""
        least = self.options.min_confidence if least is None else least
        return Match(query, candidate, reg, self.score(reg) >= least)

    def register_pair(self, query: Gmm, target: Gmm) -> Registration:
        """`register` with no initial guess, from the descriptor's yaw hint when it has one."""
        hint = None
        if self.options.use_yaw_hint and hasattr(self.descriptor, "yaw"):
            n = self.options.resample_points
            hint = self.descriptor.yaw(resample(query, n), resample(target, n))
        return register(query, target, yaw_hint=hint, options=self.registration)

    def score(self, reg: Registration) -> float:
        """The confidence C, scaled down to 0 as the best other basin's confidence rises from
        ``max_ambiguity``·C to C (a corridor seen end for end scores near 0); from
        ``sure_confidence`` on, C itself (alike rooms leave right matches a close second)."""
        if reg.confidence <= 0:
            return 0.0
        sure = self.options.sure_confidence
        if sure is not None and reg.confidence >= sure:
            return reg.confidence
        ratio = reg.alternative_confidence / reg.confidence
        margin = 1.0 - self.options.max_ambiguity
        return reg.confidence * (min(1.0, (1.0 - ratio) / margin) if margin > 0 else 1.0)

    def match(self, robot: str, seq: int, gmm: Gmm) -> list[Match]:
        """Candidates for a submap, each verified: accepted and rejected matches."""
        return [self.verify(robot, seq, gmm, c) for c in self.query(robot, seq, gmm)]
