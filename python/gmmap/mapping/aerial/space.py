"""Free space in 3D from what crosses the wire: spherical horizons beside the GMM submaps.

The 3D form of `gmmap.mapping.frontier`'s horizons, for an aerial robot: from a viewpoint on
the robot's path, how far the sensor saw free space in each of ``AZIMUTHS x ELEVATIONS``
directions (10° cells over the whole sphere): the nearest return in the cell, or a range the
sensor vouches for where its beams crossed the cell and returned nothing (a LiDAR's minimum
range: nothing returned may be something too near); 0 where no beam crossed it (a 360°
LiDAR's ±45° leaves the poles unseen). One byte per cell (10 cm steps) and 6 for the viewpoint
(cm, int16), deflated: most cells of a ±45° sensor are unseen and cost almost nothing.

A cell holds its nearest return, so a doorway seen down a corridor, narrower than a cell,
vanishes behind the wall beside it. Where some beam of a cell went on at least ``GAP`` m past
the nearest return, the cell also carries that farthest return: space there was glimpsed, not
seen free, and a frontier in front of it (`gmmap.mapping.aerial.explorer`) sends the robot to
look. A second byte per cell, 0 where there is no gap, which deflate makes nearly free.

Known free space is the union of the horizons' star-shaped volumes and the ball of ``BODY``
about each viewpoint (the robot flew there). Frontiers are found on a transient lattice over
that space (`frontier_points`): known-free points beside a point that is neither known free
nor near a surface of the team's mixtures. The lattice is the explorer's scratch work, never
sent.
"""

from __future__ import annotations

import math
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.mapping.frame import Frame
from gmmap.mapping.frontier import BACK, BODY, MAX_CODE, RANGE_STEP, code_ranges, range_codes

AZIMUTHS, ELEVATIONS = 36, 18  # 10° cells
BLIND = 2.5  # metres within which an unswept direction's space counts as blind, not unknown
GAP = 1.0  # metres past a cell's nearest return its farthest must reach to be kept


@dataclass
class SphereHorizon:
    """Free range (m) per direction cell from ``origin`` (x, y, z), NaN where not seen; cell
    (e, a) spans elevations [-90 + 10 e, -80 + 10 e)° and azimuths [10 a, 10 a + 10)°."""

    origin: np.ndarray
    ranges: np.ndarray  # (ELEVATIONS, AZIMUTHS)
    far: np.ndarray | None = None  # farthest return where ``GAP`` past the nearest, else NaN

    def __post_init__(self) -> None:
        if self.far is None:
            self.far = np.full(self.ranges.shape, np.nan)

    def moved(self, T: np.ndarray) -> SphereHorizon:
        """This horizon in another frame: ``T`` (4x4, levelled: a rotation about z). Rotating by
        whole cells keeps the ranges exact; the rest (< 5°) is the error accepted."""
        yaw = math.atan2(T[1, 0], T[0, 0])
        shift = round(yaw / (2 * math.pi / AZIMUTHS))
        origin = T[:3, :3] @ self.origin + T[:3, 3]
        return SphereHorizon(origin, np.roll(self.ranges, shift, 1), np.roll(self.far, shift, 1))


def cells(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(elevation cell, azimuth cell, length) of (N, 3) offsets."""
    e, _, a, r = _cells(d)
    return e, a, r


def _cells(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`cells`, and the elevation cell nearest each offset's but its own."""
    r = np.linalg.norm(d, axis=1)
    el = np.arcsin(np.clip(d[:, 2] / np.maximum(r, 1e-12), -1, 1))
    at = (el + math.pi / 2) / math.pi * ELEVATIONS
    e = np.clip(at.astype(int), 0, ELEVATIONS - 1)
    beside = np.clip(np.where(at - e >= 0.5, e + 1, e - 1), 0, ELEVATIONS - 1)
    az = np.arctan2(d[:, 1], d[:, 0])
    a = np.floor(az / (2 * math.pi) * AZIMUTHS).astype(int) % AZIMUTHS
    return e, beside, a, r


def sphere_horizon(
    points: np.ndarray, origin: np.ndarray, swept: np.ndarray, reach: float
) -> SphereHorizon:
    """The horizon of one scan's (N, 3) points (map frame) from ``origin``: ``swept`` says which
    cells the sensor's beams cross, free to ``reach`` where they met nothing."""
    ranges = np.where(swept, min(reach, MAX_CODE * RANGE_STEP), np.nan)
    far = np.full(swept.shape, np.nan)
    if len(points):
        e, a, r = cells(np.asarray(points, float) - origin)
        near, most = np.full(swept.shape, np.inf), np.zeros(swept.shape)
        np.minimum.at(near, (e, a), r)
        np.maximum.at(most, (e, a), r)
        hit = np.isfinite(near)
        ranges[hit] = near[hit]
        gap = hit & (most >= near + GAP)
        far[gap] = np.minimum(most[gap], MAX_CODE * RANGE_STEP)
    return SphereHorizon(np.asarray(origin, float).copy(), ranges, far)


def swept_cells(fov_down: float, fov_up: float) -> np.ndarray:
    """The cells a spinning LiDAR's beams cross whole, between those elevations (degrees): a
    cell half outside the field would claim free space past the floor its lowest beam met."""
    low = np.arange(ELEVATIONS) * 180 / ELEVATIONS - 90
    rows = (low >= fov_down - 1e-9) & (low + 180 / ELEVATIONS <= fov_up + 1e-9)
    return np.repeat(rows[:, None], AZIMUTHS, axis=1)


class SphereRecorder:
    """The horizons of a robot's path since its last submap, in its map frame: one per
    ``spacing`` metres flown, from the first scan there."""

    def __init__(self, swept: np.ndarray, reach: float, spacing: float) -> None:
        self.swept, self.reach, self.spacing = swept, reach, spacing
        self.closed: list[SphereHorizon] = []
        self._last: np.ndarray | None = None

    def add(self, frame: Frame) -> None:
        origin = frame.pose[:3, 3]
        if self._last is None or np.linalg.norm(origin - self._last) >= self.spacing:
            self.closed.append(sphere_horizon(frame.world_points(), origin, self.swept, self.reach))
            self._last = origin.copy()

    def again(self) -> None:
        """The next scan makes a horizon wherever it is (a goal reached: what is past it?)."""
        self._last = None

    def take(self, anchor: np.ndarray) -> list[SphereHorizon]:
        """The horizons so far in ``anchor``'s frame; the next submap starts afresh."""
        inverse = np.linalg.inv(anchor)
        out = [h.moved(inverse) for h in self.closed]
        self.closed = []
        return out


def encode_spheres(horizons: Sequence[SphereHorizon]) -> bytes:
    """Wire form: count, then per horizon int16 cm x, y, z and uint8 codes of the nearest and
    of the far returns (0: none); deflated."""
    raw = bytearray(struct.pack("<H", len(horizons)))
    for h in horizons:
        if h.ranges.shape != (ELEVATIONS, AZIMUTHS) or h.far.shape != h.ranges.shape:
            raise InvalidInputError(f"a sphere horizon has {ELEVATIONS}x{AZIMUTHS} cells")
        xyz = np.clip(np.round(h.origin * 100), -32768, 32767).astype("<i2")
        raw += xyz.tobytes() + range_codes(h.ranges).tobytes() + range_codes(h.far).tobytes()
    return zlib.compress(bytes(raw), 9)


def decode_spheres(data: bytes) -> list[SphereHorizon]:
    """The horizons of `encode_spheres`; FileFormatError on anything else."""
    try:
        raw = zlib.decompress(data)
        (n,) = struct.unpack_from("<H", raw)
    except (zlib.error, struct.error) as exc:
        raise FileFormatError(f"not a sphere-horizon block: {exc}") from exc
    n_cells = ELEVATIONS * AZIMUTHS
    size = 6 + 2 * n_cells
    if len(raw) != 2 + n * size:
        raise FileFormatError(f"sphere-horizon block of {len(raw)} bytes, expected {2 + n * size}")
    out = []
    for i in range(n):
        at = 2 + i * size
        origin = np.frombuffer(raw, "<i2", 3, at).astype(float) / 100
        near, far = np.frombuffer(raw, np.uint8, 2 * n_cells, at + 6).reshape(2, ELEVATIONS, -1)
        out.append(SphereHorizon(origin, code_ranges(near), code_ranges(far)))
    return out


class SphereSpace:
    """The union of spherical horizons: what is known free in 3D."""

    def __init__(self, horizons: Sequence[SphereHorizon]) -> None:
        self.horizons = list(horizons)
        self.origins = np.array([h.origin for h in self.horizons]).reshape(-1, 3)
        self.ranges = np.array([h.ranges for h in self.horizons]).reshape(-1, ELEVATIONS, AZIMUTHS)
        self.far = np.array([h.far for h in self.horizons]).reshape(self.ranges.shape)

    def __len__(self) -> int:
        return len(self.horizons)

    def inside(self, points: np.ndarray, shrink: float = 0.0, body: bool = True) -> np.ndarray:
        """(N, H) whether each point is inside each horizon: nearer than its cell's free range
        less ``shrink`` (or within ``BODY`` of the viewpoint, unless ``body`` is False)."""
        pts = np.atleast_2d(np.asarray(points, float))
        out = np.zeros((len(pts), len(self)), dtype=bool)
        for j, origin in enumerate(self.origins):
            e, beside, a, r = _cells(pts - origin)
            free = self._free(j, e, beside, a) - shrink
            out[:, j] = np.nan_to_num(free, nan=-1.0) > r
            if body:
                out[:, j] |= r < BODY
        return out

    def _free(
        self, j: int | np.ndarray, e: np.ndarray, beside: np.ndarray, a: np.ndarray
    ) -> np.ndarray:
        """Free range of horizon(s) ``j`` in cells (e, a) of `_cells`, NaN where unseen."""
        # A cell's beams sample a few elevations in it (every 2.9° for 32 beams over ±45°):
        # past its top beam a ceiling may be nearer than any beam met. So the half of a cell
        # next to another claims no farther than that one either.
        own = self.ranges[j, e, a]
        return np.where(np.isnan(own), np.nan, np.fmin(own, self.ranges[j, beside, a]))

    def blind(self, points: np.ndarray) -> np.ndarray:
        """Whether each (N, 3) point lies within ``BLIND`` of a viewpoint in a direction its
        sensor never sweeps (under and over a ±45° LiDAR): space that moving on will show,
        not a frontier to fly to."""
        pts = np.atleast_2d(np.asarray(points, float))
        out = np.zeros(len(pts), dtype=bool)
        for j in np.unique(np.concatenate(cKDTree(self.origins).query_ball_point(pts, BLIND))):
            e, a, r = cells(pts - self.origins[int(j)])
            out |= np.isnan(self.ranges[int(j)][e, a]) & (r < BLIND)
        return out

    def glimpsed(self, points: np.ndarray, margin: float = 0.3) -> np.ndarray:
        """(N,): for each point, the viewpoint some beam of which saw past it, -1 if none.

        Glimpsed: between a cell's nearest and farthest returns, ``margin`` m clear of both,
        unless a nearer viewpoint's cell holding it met a surface in front of it and saw
        nothing past (a cell grazing a wall also holds space behind the wall). Where to look
        from: `look_outs`."""
        pts = np.atleast_2d(np.asarray(points, float))
        seer, by = np.full(len(pts), -1), np.full(len(pts), np.inf)
        for j in np.flatnonzero(~np.isnan(self.far).all(axis=(1, 2))):
            todo = np.flatnonzero(seer < 0)
            e, a, r = cells(pts[todo] - self.origins[j])
            near, far = self.ranges[j][e, a], self.far[j][e, a]
            hit = (r > near + margin) & (r < far - margin)
            by[todo[hit]], seer[todo[hit]] = r[hit], j
        some = np.flatnonzero(seer >= 0)
        for j in range(len(self)):
            e, a, r = cells(pts[some] - self.origins[j])
            near, far = self.ranges[j][e, a], self.far[j][e, a]
            seer[some[(near < r - margin) & np.isnan(far) & (r < by[some])]] = -1
        return seer

    def look_outs(self, points: np.ndarray, owners: np.ndarray) -> np.ndarray:
        """(N, 3): on the line from viewpoint ``owners[i]`` to each point, ``BACK`` m short of
        where that viewpoint's known free space along it ends (or of the point); NaN where
        that is within ``BACK`` of the viewpoint."""
        origins = self.origins[owners]
        d = np.atleast_2d(points) - origins
        e, beside, a, r = _cells(d)
        reach = np.minimum(self._free(owners, e, beside, a), r) - BACK  # NaN: never seen
        reach[~(reach > BACK)] = np.nan
        return origins + (reach / np.maximum(r, 1e-9))[:, None] * d

    def contains(self, points: np.ndarray, shrink: float = 0.0, body: bool = True) -> np.ndarray:
        """Whether each (N, 3) point is known free."""
        return self.inside(points, shrink, body).any(axis=1)

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """Corners of a box holding every horizon's known free space."""
        reach = np.nan_to_num(self.ranges, nan=BODY).max(axis=(1, 2))
        return (self.origins - reach[:, None]).min(axis=0), (self.origins + reach[:, None]).max(
            axis=0
        )
