"""Free space and frontiers from what crosses the wire: GMM submaps plus free-space horizons.

A GMM says where surfaces are, not where the sensor looked: space without components may be
free or never seen. The smallest addition that says which is a *horizon*: from a viewpoint on
the robot's path, how far the sensor saw free space in each of ``bins`` horizontal directions,
through the height band the robot's body occupies. Bytes: 4 for the viewpoint (cm, int16, in
the submap's anchor frame) and one per direction (0: not seen; k: free for k x 10 cm), about 76
per viewpoint before deflate. Free space is the union of the horizons' star-shaped polygons;
a direction's free range is the nearest return in the band (an obstacle), else the farthest
floor return (free that far, nothing in the band), never a guess about a direction not seen.

Frontiers are where known free space meets space nobody has seen: just past the end of a
direction that did not end on a surface (the GMM occupancy field tells which did), and along
occlusion edges, beside a direction whose neighbour saw farther or was not seen at all (a
doorway, a depth camera's narrow view). Each comes with a *target*, a point inside the same
horizon, so the straight line from the horizon's viewpoint to the target is observed free
space: exploration routes run between viewpoints, without a grid. The disc of ``BODY`` about
a viewpoint counts as free whatever was seen: the robot stood there.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.mapping.frame import Frame
from gmmap.math.gmm import Gmm

RANGE_STEP = 0.1  # metres per range unit on the wire
BODY = 0.4  # metres about a viewpoint known free whatever was seen: the robot stood there
MAX_CODE = 255
BACK = 0.4  # metres a frontier's target lies inside the horizon that sees it
SEEN_MARGIN = 0.2  # metres inside a horizon a surface must lie to contradict it
MAX_INVENTED = 0.3  # metres along one direction a view joining a horizon may invent
SAME_GOAL = 1.0  # metres within which a frontier's goal is the one a route heads for
BEHIND = (0.5, 1.0, 1.5)  # metres past a frontier point looked at for unknown space
Blocked = Callable[[np.ndarray], np.ndarray]  # (N, 2) → bool (N,): occupied per the map


@dataclass
class Horizon:
    """Free range (m) per direction from ``origin`` (x, y), NaN where not seen; direction b
    covers [b, b + 1) x 2pi / bins about +z, in the frame ``origin`` is in."""

    origin: np.ndarray
    ranges: np.ndarray

    def moved(self, T: np.ndarray) -> Horizon:
        """This horizon in another frame: ``T`` (4x4, levelled: a rotation about z)."""
        yaw = math.atan2(T[1, 0], T[0, 0])
        shift = round(yaw / (2 * math.pi / len(self.ranges)))
        origin = T[:2, :2] @ self.origin + T[:2, 3]
        # Rotating by whole bins keeps the ranges exact; the remainder (< half a bin) is the
        # error this representation accepts.
        return Horizon(origin, np.roll(self.ranges, shift))


def horizon_from(
    points_xyz: np.ndarray,
    origin: np.ndarray,
    band: tuple[float, float],
    bins: int,
    floor: float | None = 0.05,
) -> np.ndarray:
    """Free range per direction (NaN: not seen) from ``origin`` (x, y), for (N, 3) points in a
    levelled frame whose z = 0 is the floor: the nearest return in ``band``, else the farthest
    floor return (z under ``floor``; None: where the floor is is unknown, and a direction
    without a return in the band is not seen); returns above the band say nothing about it."""
    z = np.asarray(points_xyz)[:, 2]
    low = z < (-np.inf if floor is None else max(floor, band[0]))
    hit = (z >= band[0]) & (z <= band[1]) & ~low
    out = np.full(bins, np.nan)
    # Directions and ranges of the returns that say something only: a depth camera's frame is
    # 300,000 points, a few percent of them in the band.
    says = low | hit
    d = np.asarray(points_xyz, dtype=np.float64)[says, :2] - origin
    if not len(d):
        return out
    turns = np.arctan2(d[:, 1], d[:, 0]) / (2 * math.pi) * bins
    b = np.floor(turns).astype(int) % bins
    r = np.hypot(d[:, 0], d[:, 1])
    which = hit[says]
    for mask, fill, reduce in ((~which, 0.0, np.maximum), (which, np.inf, np.minimum)):
        best = np.full(bins, fill)
        reduce.at(best, b[mask], r[mask])
        seen = (best > 0) & np.isfinite(best)
        out[seen] = best[seen]
    # A direction the view only grazed (the edge of a camera's field of view) is not seen: a
    # surface in the part it missed may lie nearer than what the rest saw.
    return np.where(_spanned(turns - np.floor(turns), b, bins), out, np.nan)


def _spanned(offset: np.ndarray, b: np.ndarray, bins: int, edge: float = 0.2) -> np.ndarray:
    """Per direction, whether returns reach within ``edge`` of a bin's width of both its sides
    (``offset``: each return's place across its bin ``b``, 0 to 1)."""
    first, last = np.full(bins, np.inf), np.full(bins, -np.inf)
    np.minimum.at(first, b, offset)
    np.maximum.at(last, b, offset)
    return (first <= edge) & (last >= 1 - edge)


def _samples(h: Horizon, fractions: tuple[float, ...] = (0.3, 0.6, 0.9)) -> np.ndarray:
    """(N, 2) points inside ``h``: along each seen direction's middle, at ``fractions`` of its
    free range."""
    bins = np.flatnonzero(np.isfinite(h.ranges))
    angle = (bins + 0.5) * 2 * math.pi / len(h.ranges)
    r = (h.ranges[bins][:, None] * np.asarray(fractions)[None]).ravel()
    angle = np.repeat(angle, len(fractions))
    return h.origin + np.c_[np.cos(angle) * r, np.sin(angle) * r]


def distortion(before: Horizon, view: Horizon, merged: Horizon) -> float:
    """The share of free space lost or invented when ``view`` (a frame's horizon from its own
    position) joins ``before`` as ``merged`` (the same frame seen from ``before``'s viewpoint):
    the larger of the share of the view's samples outside ``merged`` and the share of
    ``merged``'s samples outside both ``before`` and the view."""
    lost = _samples(view)
    invented = _samples(merged)
    shares = []
    if len(lost):
        shares.append(float(np.mean(~FreeSpace([merged]).contains(lost, body=False))))
    if len(invented):
        known = FreeSpace([before, view]).contains(invented, body=False)
        shares.append(float(np.mean(~known)))
    return max(shares, default=0.0)


def invented_run(before: Horizon, view: Horizon, merged: Horizon, step: float = 0.1) -> float:
    """The longest stretch (m) of one of ``merged``'s directions (its middle) that neither
    ``before`` nor ``view`` saw free: a wall between the view's position and the viewpoint,
    which a share of samples hardly weighs, being thin (`distortion`). Only the directions
    the view changed can hold one: the rest lie inside ``before``."""
    bins = np.flatnonzero(np.isfinite(merged.ranges) & (merged.ranges != before.ranges))
    if not len(bins):
        return 0.0
    steps = np.arange(step, np.nanmax(merged.ranges[bins]) + step / 2, step)
    angle = (bins + 0.5) * 2 * math.pi / len(merged.ranges)
    u = np.c_[np.cos(angle), np.sin(angle)]
    pts = merged.origin + u[:, None, :] * steps[None, :, None]
    inside = steps[None, :] < merged.ranges[bins][:, None]
    known = FreeSpace([before, view]).contains(pts.reshape(-1, 2)).reshape(inside.shape)
    run, best = np.zeros(len(bins)), np.zeros(len(bins))
    for column in (inside & ~known).T:  # longest run of unknown samples per direction
        run = np.where(column, run + step, 0.0)
        best = np.maximum(best, run)
    return float(best.max())


def merge_ranges(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Two views from (about) one viewpoint: the nearer free range where both saw a direction
    (a return in one is an obstacle the other may have missed)."""
    return np.where(np.isnan(a), b, np.where(np.isnan(b), a, np.fmin(a, b)))


def encode_horizons(horizons: Sequence[Horizon]) -> bytes:
    """Wire form: count, bins, then per horizon int16 cm x, y and uint8 codes; deflated."""
    bins = len(horizons[0].ranges) if horizons else 0
    raw = bytearray(struct.pack("<HH", len(horizons), bins))
    for h in horizons:
        if len(h.ranges) != bins:
            raise InvalidInputError("every horizon of a submap has the same number of bins")
        x, y = (int(np.clip(round(v * 100), -32768, 32767)) for v in h.origin)
        raw += struct.pack("<hh", x, y) + range_codes(h.ranges).tobytes()
    return zlib.compress(bytes(raw), 9)


def range_codes(ranges: np.ndarray) -> np.ndarray:
    """Free ranges (m, NaN: not seen) as the wire's bytes: 0 not seen, k free for k x 10 cm."""
    codes = np.clip(np.floor(np.nan_to_num(ranges) / RANGE_STEP), 1, MAX_CODE)
    return np.where(np.isnan(ranges), 0, codes).astype(np.uint8)


def code_ranges(codes: np.ndarray) -> np.ndarray:
    """The free ranges of `range_codes`' bytes."""
    return np.where(codes == 0, np.nan, codes.astype(float) * RANGE_STEP)


def clear_lines(space, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether each segment a→b ((N, 2) or (N, 3) ends) lies inside ``space``'s known free
    space (anything with ``contains(points, shrink)``): a route, not a safe line (the planner
    keeps the robot off surfaces on the way)."""
    steps = max(2, int(np.ceil(np.linalg.norm(b - a, axis=1).max(initial=0) / 0.2)) + 1)
    t = np.linspace(0, 1, steps)
    pts = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, a.shape[1])
    return space.contains(pts, shrink=0.1).reshape(len(a), steps).all(axis=1)


def seen_through(
    horizons: Sequence[Horizon],
    anchor: np.ndarray,
    gmm: Gmm,
    band: tuple[float, float],
    reach: float = 0.0,
) -> float:
    """The share of ``gmm``'s weight in ``band`` (components by their means, or within ``reach``
    vertical standard deviations of it; ``gmm`` in the frame of ``anchor``, the pose of the
    submap the horizons belong to) that lies inside those horizons by `SEEN_MARGIN`: surfaces
    where that robot's rays went through. A component counts when its mean and the points 1
    sigma either way along its longest horizontal axis do: EM spans a doorway with one component
    of the wall, whose mean lies in the doorway (random-office:101, 16-beam LiDAR: by means
    alone, 27 of 168 right matches put over 2 % there)."""
    R, t = anchor[:3, :3], anchor[:3, 3]
    means = gmm.means @ R.T + t
    if reach > 0:
        up = R[2] @ gmm.covariances @ R[2]  # each component's vertical variance
        half = reach * np.sqrt(np.maximum(up, 0.0))
        level = (means[:, 2] + half >= band[0]) & (means[:, 2] - half <= band[1])
    else:
        level = (means[:, 2] >= band[0]) & (means[:, 2] <= band[1])
    total = float(gmm.weights[level].sum())
    if not horizons or total <= 0:
        return 0.0
    flat = np.einsum("ij,kjl,ml->kim", R, gmm.covariances[level], R)[:, :2, :2]
    val, vec = np.linalg.eigh(flat)
    axis = vec[:, :, 1] * np.sqrt(np.maximum(val[:, 1], 0.0))[:, None]
    centre = means[level, :2]
    probes = np.stack([centre, centre + axis, centre - axis], axis=1).reshape(-1, 2)
    space = FreeSpace([h.moved(anchor) for h in horizons])
    inside = space.contains(probes, shrink=SEEN_MARGIN, body=False).reshape(-1, 3).all(axis=1)
    return float(gmm.weights[level][inside].sum()) / total


def decode_horizons(data: bytes) -> list[Horizon]:
    """The horizons of `encode_horizons`; FileFormatError on anything else."""
    try:
        raw = zlib.decompress(data)
        n, bins = struct.unpack_from("<HH", raw)
    except (zlib.error, struct.error) as exc:
        raise FileFormatError(f"not a horizon block: {exc}") from exc
    size = 4 + bins
    if bins < 4 or len(raw) != 4 + n * size:
        raise FileFormatError(f"horizon block: {len(raw)} bytes for {n} x {bins} bins")
    out = []
    for i in range(n):
        x, y = struct.unpack_from("<hh", raw, 4 + i * size)
        codes = np.frombuffer(raw, np.uint8, bins, 4 + i * size + 4)
        out.append(Horizon(np.array([x, y]) / 100.0, code_ranges(codes)))
    return out


class HorizonRecorder:
    """The horizons of a robot's path since its last submap, in the frame of the poses it is
    given (an exploring robot's map frame, or a submap's anchor frame)."""

    def __init__(
        self,
        bins: int,
        spacing: float,
        band: tuple[float, float],
        floor: float | None = 0.05,
        max_distortion: float | None = None,
    ) -> None:
        self.bins, self.spacing, self.band, self.floor = bins, spacing, band, floor
        self.max_distortion = max_distortion
        self.closed: list[Horizon] = []
        self.current: Horizon | None = None

    def add(self, frame: Frame) -> None:
        self.observe(frame.points, frame.pose)

    def observe(self, points: np.ndarray, pose: np.ndarray) -> None:
        """Sensor-frame ``points`` seen from ``pose`` (into this recorder's frame). A view
        joins the current horizon as if seen from its viewpoint; with ``max_distortion``, one
        that would then lose or invent more than that share of free space (a doorway between
        the two viewpoints), or invent over `MAX_INVENTED` along one direction (a wall between
        them), starts a horizon of its own instead."""
        pts = np.asarray(points, dtype=np.float64) @ pose[:3, :3].T + pose[:3, 3]
        origin = pose[:2, 3].copy()
        if self.current is not None and np.linalg.norm(origin - self.current.origin) > self.spacing:
            self._close()
        if self.current is None:
            self.current = Horizon(origin, np.full(self.bins, np.nan))
        seen = horizon_from(pts, self.current.origin, self.band, self.bins, self.floor)
        merged = Horizon(self.current.origin, merge_ranges(self.current.ranges, seen))
        if self.max_distortion is not None and np.linalg.norm(origin - merged.origin) > 0:
            own = Horizon(origin, horizon_from(pts, origin, self.band, self.bins, self.floor))
            if (
                distortion(self.current, own, merged) > self.max_distortion
                or invented_run(self.current, own, merged) > MAX_INVENTED
            ):
                self._close()
                merged = own
        self.current = merged

    def _close(self) -> None:
        if self.current is not None:
            self.closed.append(self.current)
        self.current = None

    def all(self) -> list[Horizon]:
        return self.closed + ([self.current] if self.current is not None else [])

    def take(self, anchor: np.ndarray) -> list[Horizon]:
        """The horizons so far, moved into ``anchor``'s frame; the next submap starts afresh
        (its first viewpoint is where this one's last was)."""
        inverse = np.linalg.inv(anchor)
        out = [h.moved(inverse) for h in self.all()]
        self.closed, self.current = [], None
        return out


@dataclass
class Frontier:
    """A cluster of frontier points: ``goal`` (a target inside known free space), the horizon
    whose viewpoint sees it in a straight line, ``size`` (points: a proxy for the unknown
    area it opens) and ``open`` (those of its points with unknown space behind them, see
    `FreeSpace.frontiers`)."""

    goal: np.ndarray
    horizon: int
    size: int
    open: int = 0


def preferred(fronts: list[Frontier], min_size: int, heading: np.ndarray | None) -> list[Frontier]:
    """The frontiers worth choosing among: open ones (``open`` >= ``min_size``) if any, else
    large ones, else all. Small ones only once no large one is left: the far end of a corridor
    seen lengthwise is a few probes wide (random-office:101: one robot said "done" at 70 %);
    open ones first: a sliver between two horizons against a mapped wall hides nothing. The
    one within ``SAME_GOAL`` of ``heading`` (the goal a robot heads for) stays whatever its
    kind: kinds change as peers' submaps arrive and peers' goals come and go, and robots went
    back and forth across a hall (random-office:102). A lone robot passes None: a frontier that lost
    its open points as it came nearer hides little (random-office:101 alone took 159.8 s to
    90 % keeping such goals, 98.8 s dropping them)."""
    tier = (
        [f for f in fronts if f.open >= min_size]
        or [f for f in fronts if f.size >= min_size]
        or fronts
    )
    if heading is None:
        return tier
    near = [f for f in fronts if np.linalg.norm(f.goal - heading) < SAME_GOAL]
    return tier + [f for f in near if all(f is not t for t in tier)]


class FreeSpace:
    """The union of horizons (all in one frame)."""

    def __init__(self, horizons: Sequence[Horizon]) -> None:
        self.horizons = list(horizons)
        self.bins = len(self.horizons[0].ranges) if self.horizons else 72
        self.origins = np.array([h.origin for h in self.horizons]).reshape(-1, 2)
        self.ranges = np.array([h.ranges for h in self.horizons]).reshape(-1, self.bins)

    def __len__(self) -> int:
        return len(self.horizons)

    def _bin(self, angle: np.ndarray) -> np.ndarray:
        return np.floor(angle / (2 * math.pi) * self.bins).astype(int) % self.bins

    def contains(
        self, xy: object, shrink: float = 0.0, near: float = 30.0, body: bool = True
    ) -> np.ndarray:
        """Whether each (N, 2) point is known free: inside some horizon by ``shrink`` m (or,
        with ``body``, within ``BODY`` of its viewpoint)."""
        pts = np.atleast_2d(np.asarray(xy, dtype=np.float64))
        inside = np.zeros(len(pts), dtype=bool)
        if not len(self) or not len(pts):
            return inside
        for start in range(0, len(pts), 2048):
            inside[start : start + 2048] = self.seen_by(
                pts[start : start + 2048], shrink, near, body
            ).any(axis=1)
        return inside

    def seen_by(
        self, xy: np.ndarray, shrink: float = 0.0, near: float = 30.0, body: bool = True
    ) -> np.ndarray:
        """(N, H): whether each point is inside each horizon by ``shrink`` m, so that the
        straight line from that horizon's viewpoint to it is known free (star-shaped); with
        ``body``, the disc of ``BODY`` about its viewpoint counts whatever was seen."""
        d = np.atleast_2d(xy)[:, None, :] - self.origins[None]
        r = np.hypot(d[..., 0], d[..., 1])
        b = self._bin(np.arctan2(d[..., 1], d[..., 0]))
        lim = self.ranges[np.arange(len(self))[None], b]
        lim = np.nan_to_num(lim, nan=-1.0)
        return (r < (np.fmax(lim, BODY) if body else lim) - shrink) & (r < near)

    def frontiers(
        self, blocked: Blocked, spacing: float = 0.25, back: float = BACK, link: float = 0.75
    ) -> list[Frontier]:
        """Frontier clusters: points just outside every horizon and not ``blocked``, each with
        a target ``back`` m inside the horizon it was found from; points closer than ``link``
        belong to one cluster. A point is *open* when the space ``BEHIND`` m past it, away from
        its target, is neither known free nor blocked: unknown space lies there, not a sliver
        between two horizons against a mapped wall."""
        probes, targets, owner, ends = self._probes(spacing, back)
        if not len(probes):
            return []
        # Cheapest test first: most probes lie inside some other horizon.
        keep = ~self.contains(probes, shrink=-0.05)
        probes, targets, owner, ends = probes[keep], targets[keep], owner[keep], ends[keep]
        keep = ~blocked(probes)
        # A direction that ended on a surface has nothing unseen past it, however thin the
        # field has grown a probe's width behind a far wall.
        at_end = np.flatnonzero(keep & ~np.isnan(ends[:, 0]))
        if len(at_end):
            keep[at_end] = ~blocked(ends[at_end])
        probes, targets, owner = probes[keep], targets[keep], owner[keep]
        if not len(probes):
            return []
        # A target against a surface moves towards its viewpoint, along the same observed line,
        # as little as clears it: from nearer, an opening spans more directions (a door seen at
        # a slant from 2 m closes in 5° bins, and a robot there could not see past it).
        origins = self.origins[owner]
        stuck = blocked(targets)
        first = targets.copy()
        for back_m in (0.25, 0.5, 1.0, 1.5, 2.5, 4.0):
            if not stuck.any():
                break
            idx = np.flatnonzero(stuck)
            ray = first[idx] - origins[idx]
            f = np.clip(1.0 - back_m / np.maximum(np.linalg.norm(ray, axis=1), 1e-9), 0.25, 1.0)
            targets[idx] = origins[idx] + f[:, None] * ray
            stuck[idx] = blocked(targets[idx])
        keep = ~stuck
        probes, targets, owner = probes[keep], targets[keep], owner[keep]
        if not len(probes):
            return []
        # Single linkage: a long occlusion edge is one frontier, however far it runs.
        pairs = cKDTree(probes).query_pairs(link, output_type="ndarray")
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), (len(probes),) * 2)
        _, label = connected_components(graph, directed=False)
        is_open = self._open(probes, targets, blocked)
        out = []
        for c in np.unique(label):
            idx = np.flatnonzero(label == c)
            centre = probes[idx].mean(axis=0)
            pick = idx[np.argmin(np.linalg.norm(probes[idx] - centre, axis=1))]
            out.append(Frontier(targets[pick], int(owner[pick]), len(idx), int(is_open[idx].sum())))
        return out

    def _open(self, probes: np.ndarray, targets: np.ndarray, blocked: Blocked) -> np.ndarray:
        """Whether each probe has unknown space behind it (`frontiers`)."""
        away = unit(probes - targets)
        is_open = np.ones(len(probes), dtype=bool)
        for d in BEHIND:  # the occupancy field is the costly test: only where still open
            idx = np.flatnonzero(is_open)
            ahead = probes[idx] + d * away[idx]
            free = self.contains(ahead, shrink=-0.05)
            if not free.all():
                free[~free] = blocked(ahead[~free])
            is_open[idx[free]] = False
        return is_open

    def _probes(self, spacing: float, back: float) -> tuple[np.ndarray, ...]:
        """Candidate frontier points with their targets, horizons and ends: past the end of
        every seen direction (its end: where its range ends, past which a surface there lies),
        and along every occlusion edge (a direction beside a farther seen one, or beside one
        not seen at all) on the nearer side, each target mirrored into the farther direction
        at the same range (no end: NaN)."""
        width = 2 * math.pi / self.bins
        r = self.ranges
        seen = ~np.isnan(r)
        h, b = np.nonzero(seen)
        # Three probes per direction, so that a far frontier is as dense as a near one.
        h, b = np.repeat(h, 3), np.repeat(b, 3)
        centre = (b + 0.5 + np.tile([-1 / 3, 0.0, 1 / 3], len(h) // 3)) * width
        u = np.stack([np.cos(centre), np.sin(centre)], -1)
        probes = [self.origins[h] + (r[h, b] + 0.3)[:, None] * u]
        targets = [self.origins[h] + np.maximum(r[h, b] - back, 0.0)[:, None] * u]
        owner = [h]
        ends = [self.origins[h] + (r[h, b] + RANGE_STEP)[:, None] * u]
        near = np.nan_to_num(r, nan=0.0)
        for shift in (-1, 1):
            far = np.roll(r, -shift, axis=1)  # the neighbour's range
            edge = ~np.isnan(far) & (far - back > near + 0.3 + spacing)
            h, b = np.nonzero(edge)
            if not len(h):
                continue
            boundary = (b + (shift > 0)) * width
            steps = np.arange(0.0, far[h, b].max(), spacing)
            s = np.maximum(near[h, b], BODY)[:, None] + 0.3 + steps[None]
            ok = s < (far[h, b] - back)[:, None]
            rows, cols = np.nonzero(ok)
            dist = s[rows, cols]
            hh, bb = h[rows], boundary[rows]
            side = lambda a: np.stack([np.cos(a), np.sin(a)], -1)  # noqa: E731
            probes.append(self.origins[hh] + dist[:, None] * side(bb - shift * 0.3 * width))
            targets.append(self.origins[hh] + dist[:, None] * side(bb + shift * 0.3 * width))
            owner.append(hh)
            ends.append(np.full((len(hh), 2), np.nan))
        return np.vstack(probes), np.vstack(targets), np.concatenate(owner), np.vstack(ends)


def unit(v: np.ndarray) -> np.ndarray:
    """Vectors along the last axis scaled to length 1 (zero ones stay zero)."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)
