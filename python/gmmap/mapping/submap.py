"""GMM submaps (paper IV-A): frames gathered in a point buffer, one mixture per submap.

A `SubmapBuilder` (the paper's PtBuffer) moves each frame by its odometry pose into the
submap's anchor frame (the first frame's pose, turned upright when the map frame's ``up`` is
known) and adds it to a voxel buffer (exact centroids, 5 cm by default). A frame that would add
too few new voxels (``min_novelty``) is skipped. The submap is fitted and its components
selected after F accepted frames or, by space, at the frame whose odometry has travelled
``submap_distance`` m or turned ``submap_angle``° since the submap began (`BuildOptions`).
Strategies:

- ``points`` (the paper's Point-to-GMM, default): one GMM fitted to the buffered points.
- ``gmm-merge`` (the earlier baseline): one GMM per frame with K / F components, the frames'
  mixtures concatenated with equal weight per frame.
- ``per-frame`` (no submap): every accepted frame becomes a submap of its own.

Model selection (``gmmap.math.select``) then merges redundant components; for the strategies
that fit points, ``refine_iter`` EM iterations with full covariances follow, started from the merged
mixture. This goes beyond the paper: merging alone trades likelihood for size, while merging
then refining keeps fewer components *and* fits better, because full covariances follow
oblique surfaces that axis-aligned ones cannot.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path

import numpy as np

from gmmap import _core
from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.mapping.frame import Frame
from gmmap.mapping.frontier import Horizon, HorizonRecorder, code_ranges, range_codes
from gmmap.math.em import fit_gmm
from gmmap.math.fileio import load_npz, save_npz
from gmmap.math.gmm import Gmm
from gmmap.math.points import voxel_filter
from gmmap.math.select import select_components
from gmmap.options import BuildOptions, PlaceOptions, SelectOptions

FILE_FORMAT = "gmmap submap"
FILE_VERSION = 1
# A submap's free-space horizons: every 5° from a viewpoint every metre of path, as exploring
# robots' (`gmmap.options.ExploreOptions`).
HORIZON_BINS = 72
HORIZON_SPACING = 1.0


@dataclass
class Submap:
    """One robot's submap: a GMM in its anchor frame, where the anchor sits in the robot's map.

    ``points`` (the buffered voxel centroids, anchor frame) stay on the robot: they are for
    baselines and evaluation and are never sent. ``gt_anchor`` is the anchor's ground-truth pose
    in the dataset's world frame when the frames carry one. ``stamps``: a built submap's are its
    first and last frames' (one, for one frame), the anchor's and where it ends; the frames in
    between would cost 4 bytes each on the wire and no receiver could use them, their poses
    not being sent. ``horizons``: the free space its frames saw (`gmmap.mapping.frontier`), in
    the anchor frame, at the heights ``horizon_band`` about the anchor; None where not recorded.
    """

    robot: str
    seq: int
    anchor: np.ndarray
    stamps: np.ndarray
    n_points: int
    gmm: Gmm
    points: np.ndarray | None = None
    gt_anchor: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    horizons: list[Horizon] | None = None
    horizon_band: tuple[float, float] | None = None

    def save(self, path: str | os.PathLike, with_points: bool = True) -> None:
        arrays = dict(
            self.gmm.arrays(),
            robot=np.array(self.robot),
            seq=np.array(self.seq),
            anchor=self.anchor,
            stamps=self.stamps,
            n_points=np.array(self.n_points),
            stats=np.array(json.dumps(self.stats)),
        )
        if self.gt_anchor is not None:
            arrays["gt_anchor"] = self.gt_anchor
        if with_points and self.points is not None:
            arrays["points"] = self.points.astype(np.float32)
        if self.horizons is not None and self.horizon_band is not None:
            arrays["horizon_band"] = np.array(self.horizon_band, dtype=np.float64)
            arrays["horizon_origins"] = np.array([h.origin for h in self.horizons]).reshape(-1, 2)
            arrays["horizon_codes"] = np.array(
                [range_codes(h.ranges) for h in self.horizons], dtype=np.uint8
            ).reshape(len(self.horizons), -1)
        save_npz(path, FILE_FORMAT, FILE_VERSION, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Submap:
        d = load_npz(path, FILE_FORMAT, FILE_VERSION)
        return cls(
            str(d["robot"]),
            int(d["seq"]),
            d["anchor"],
            d["stamps"],
            int(d["n_points"]),
            Gmm.from_arrays(d, path),
            d.get("points"),
            d.get("gt_anchor"),
            json.loads(str(d["stats"])),
            *_load_horizons(d),
        )


def _load_horizons(d) -> tuple[list[Horizon] | None, tuple[float, float] | None]:
    """A saved submap's horizons and their band; (None, None) where it has none."""
    if "horizon_band" not in d:
        return None, None
    low, high = (float(v) for v in d["horizon_band"])
    origins, codes = d.get("horizon_origins"), d.get("horizon_codes")
    if origins is None or codes is None or len(origins) != len(codes):
        raise FileFormatError("submap file: horizons without their viewpoints or codes")
    return [Horizon(o, code_ranges(c)) for o, c in zip(origins, codes, strict=True)], (low, high)


def level(pose: np.ndarray, up: np.ndarray | None) -> np.ndarray:
    """The pose turned so its z axis is ``up`` and its x axis the pose's most horizontal axis."""
    if up is None:
        return pose.copy()
    up = np.asarray(up, float) / np.linalg.norm(up)
    R = pose[:3, :3]
    forward = R[:, int(np.argmin(np.abs(R.T @ up)))]
    x = forward - (forward @ up) * up
    x /= np.linalg.norm(x)
    out = pose.copy()
    out[:3, :3] = np.column_stack([x, np.cross(up, x), up])
    return out


class SubmapBuilder:
    """Turns frames into submaps: call ``add`` per frame, ``flush`` at the end."""

    def __init__(
        self,
        robot: str = "robot",
        options: BuildOptions | None = None,
        select: SelectOptions | None = None,
    ) -> None:
        self.robot = robot
        self.options = options or BuildOptions()
        self.selection = select or SelectOptions()
        self.seq = 0
        self.frames_seen = 0
        self.frames_skipped = 0
        self._last_pose: np.ndarray | None = None
        self._reset()

    def _reset(self) -> None:
        self.buffer = _core.VoxelBuffer(self.options.voxel_size)
        self.anchor: np.ndarray | None = None
        self.gt_anchor: np.ndarray | None = None
        self.stamps: list[float] = []
        self.frame_gmms: list[Gmm] = []
        band = self.options.horizon_band
        self.horizons = (
            HorizonRecorder(HORIZON_BINS, HORIZON_SPACING, band, floor=None)
            if band is not None and self.options.up is not None
            else None
        )
        self.busy_s = 0.0
        self.travelled = 0.0  # metres of odometry path since the submap began
        self.turned = 0.0  # degrees turned since the submap began

    @property
    def frames_per_submap(self) -> int:
        o = self.options
        return 1 if o.strategy == "per-frame" else o.frames_per_submap

    def add(self, frame: Frame) -> Submap | None:
        """Adds a frame; returns a finished submap when this frame completes one."""
        start = time.perf_counter()
        self.frames_seen += 1
        self._move(frame.pose)
        if self.anchor is None:
            self.anchor = level(frame.pose, self.options.up)
            if frame.gt_pose is not None:
                self.gt_anchor = frame.gt_pose @ np.linalg.inv(frame.pose) @ self.anchor
        T = np.linalg.inv(self.anchor) @ frame.pose
        points = np.ascontiguousarray(frame.points, dtype=np.float32)
        if self.horizons is not None:
            self.horizons.observe(points, T)
        novelty = self.options.min_novelty if len(self.buffer) else 0.0
        try:
            _, _, accepted = self.buffer.offer(points, T, novelty)
        except ValueError as exc:
            raise InvalidInputError(f"frame at {frame.stamp}: {exc}") from exc
        if accepted:
            self.stamps.append(frame.stamp)
            if self.options.strategy == "gmm-merge":
                self.frame_gmms.append(self._fit_frame(points, T))
        else:
            self.frames_skipped += 1
        self.busy_s += time.perf_counter() - start
        if not (self.stamps and self._full()):
            return None
        carry = self._overshoot()
        submap = self._emit()
        self.travelled, self.turned = carry
        return submap

    def state(self) -> dict:
        """What `resume` needs to go on where this builder is, right after a submap: the pose
        of the frame that closed it and the motion carried past its limit (JSON-ready)."""
        last = None if self._last_pose is None else self._last_pose.tolist()
        return {"travelled": self.travelled, "turned": self.turned, "last_pose": last}

    def resume(self, state: dict) -> None:
        """Go on from a `state` (a robot restarting on its store), so that the next submaps
        close where the uninterrupted builder's would have."""
        self.travelled, self.turned = float(state["travelled"]), float(state["turned"])
        last = state.get("last_pose")
        self._last_pose = None if last is None else np.array(last, dtype=float)

    def _move(self, pose: np.ndarray) -> None:
        """Adds the motion from the previous frame to this submap's: from the frame that closed
        the last submap on, so that no step between submaps is lost at a low rate."""
        last, self._last_pose = self._last_pose, pose
        if last is None:
            return
        step = np.linalg.inv(last) @ pose
        self.travelled += float(np.linalg.norm(step[:3, 3]))
        cos = (np.trace(step[:3, :3]) - 1.0) / 2.0
        self.turned += math.degrees(math.acos(min(1.0, max(-1.0, cos))))

    def _limits(self) -> tuple[bool, bool]:
        """Whether the submap's path and its turning have reached their limits (by space)."""
        o = self.options
        return (
            bool(o.submap_distance and self.travelled >= o.submap_distance),
            bool(o.submap_angle and self.turned >= o.submap_angle),
        )

    def _overshoot(self) -> tuple[float, float]:
        """The motion past the limit that closed the submap, which the next one starts with:
        so boundaries fall every ``submap_distance`` m of path whatever the frame rate."""
        o = self.options
        far, turned = self._limits()
        if far:
            return self.travelled % o.submap_distance, 0.0
        if turned:
            return 0.0, self.turned % o.submap_angle
        return 0.0, 0.0

    def _full(self) -> bool:
        """Whether the submap closes here: by space when it is set, else by frame count."""
        return len(self.stamps) >= self.frames_per_submap or any(self._limits())

    def flush(self) -> Submap | None:
        """The partial submap of the frames added since the last one (None if there are none)."""
        return self._emit() if self.stamps else None

    def _fit_frame(self, points: np.ndarray, T: np.ndarray) -> Gmm:
        o = self.options
        local = points.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        k = max(1, o.n_components // o.frames_per_submap)
        return fit_gmm(
            voxel_filter(local, o.voxel_size), k, o.covariance, o.max_iter, o.tol, o.seed
        )

    def _emit(self) -> Submap:
        o = self.options
        start = time.perf_counter()
        points = self.buffer.centroids()
        rng = np.random.default_rng([o.seed, self.seq])
        held = rng.random(len(points)) < o.holdout
        train = points[~held] if (~held).sum() >= 1 else points
        if o.strategy == "gmm-merge":
            gmm = concatenate(self.frame_gmms)
        else:
            gmm = fit_gmm(train, o.n_components, o.covariance, o.max_iter, o.tol, o.seed)
        before = gmm
        if o.select:
            gmm = select_and_refine(gmm, train, o, self.selection)
        stats = {
            "frames": len(self.stamps),
            "points": len(points),
            "components_before": len(before),
            "components_after": len(gmm),
            "bytes_float32": gmm.float32_bytes,
            "time_s": self.busy_s + time.perf_counter() - start,
        }
        if held.any():
            stats["heldout_ll_before"] = before.score(points[held])
            stats["heldout_ll_after"] = gmm.score(points[held])
        submap = Submap(
            self.robot,
            self.seq,
            self.anchor,
            np.array(self.stamps[:1] + self.stamps[1:][-1:]),  # first and last
            len(points),
            gmm,
            points,
            self.gt_anchor,
            stats,
            *self._seen(),
        )
        self.seq += 1
        self._reset()
        return submap

    def _seen(self) -> tuple[list[Horizon] | None, tuple[float, float] | None]:
        """The horizons that saw anything, and their band; (None, None) where none did (a
        camera looking down at a desk has no return at its own height)."""
        views = [] if self.horizons is None else self.horizons.all()
        views = [h for h in views if not np.isnan(h.ranges).all()]
        return (views, self.options.horizon_band) if views else (None, None)


def select_and_refine(
    gmm: Gmm, points: np.ndarray, options: BuildOptions, select: SelectOptions | None = None
) -> Gmm:
    """Model selection, then (for strategies that fit points) a few EM iterations with full
    covariances from the merged mixture: the survivors re-fit the points they now cover, which
    wins back what the merges cost (see benchmarks/selection.py). The refit is kept only when
    it takes no more bytes than the fitted mixture (full covariances cost 3 floats more)."""
    merged = select_components(gmm, select)
    if options.refine_iter == 0 or options.strategy == "gmm-merge":
        return merged
    refined = fit_gmm(
        points, covariance="full", max_iter=options.refine_iter, tol=options.tol, init=merged
    )
    # Full covariances cost 3 floats more each: keep the refit only if it is no larger.
    return refined if refined.float32_bytes <= gmm.float32_bytes else merged


def concatenate(gmms: Sequence[Gmm], shares: Sequence[float] | None = None) -> Gmm:
    """Mixtures joined, each with total weight proportional to its share (default: equal, the
    GMM-merge baseline's normalisation)."""
    shares = np.ones(len(gmms)) if shares is None else np.asarray(shares, dtype=float)
    w = np.concatenate([g.weights * share for g, share in zip(gmms, shares, strict=True)])
    return Gmm(
        w / w.sum(),
        np.concatenate([g.means for g in gmms]),
        np.concatenate([g.covariances for g in gmms]),
    )


def build_submaps(
    frames: Iterable[Frame],
    robot: str = "robot",
    options: BuildOptions | None = None,
    select: SelectOptions | None = None,
) -> Iterator[Submap]:
    """Submaps of a frame sequence, the last partial one included."""
    builder = SubmapBuilder(robot, options, select)
    for frame in frames:
        submap = builder.add(frame)
        if submap is not None:
            yield submap
    last = builder.flush()
    if last is not None:
        yield last


def submap_path(out: Path, seq: int) -> Path:
    return out / f"submap_{seq:06d}.npz"


def write_submaps(submaps: list[Submap], out: str | os.PathLike, **info: object) -> dict:
    """Writes each submap (points included: the folder is the robot's own) and ``index.json``
    with the robot's name, each submap's statistics and ``info``; returns the index."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for s in submaps:
        s.save(submap_path(out, s.seq))
    keys = (
        "frames",
        "points",
        "components_before",
        "components_after",
        "bytes_float32",
        "heldout_ll_before",
        "heldout_ll_after",
        "time_s",
    )
    index = {
        "robot": submaps[0].robot if submaps else None,
        **{k: (asdict(v) if is_dataclass(v) else v) for k, v in info.items()},
        "submaps": [{"seq": s.seq, **{k: s.stats.get(k) for k in keys}} for s in submaps],
    }
    (out / "index.json").write_text(json.dumps(index, indent=1))
    return index


def read_submaps(folder: str | os.PathLike) -> list[Submap]:
    """The submaps of a folder written by ``write_submaps``, in sequence order."""
    folder = Path(folder)
    if not (folder / "index.json").is_file():
        raise FileNotFoundError(f"{folder}: no index.json (not a submap folder from gmmap build)")
    index = json.loads((folder / "index.json").read_text())
    return [Submap.load(submap_path(folder, s["seq"])) for s in index["submaps"]]


def local_map(submaps: Sequence[Submap], frame: np.ndarray) -> Gmm:
    """One mixture of ``submaps`` in the anchor ``frame`` of their robot's map, each submap
    weighted by its point count."""
    inverse = np.linalg.inv(frame)
    parts = [s.gmm.transform(inverse @ s.anchor) for s in submaps]
    return concatenate(parts, [max(s.n_points, 1) for s in submaps])


def horizons_in(views: Iterable[tuple[Submap, list[Horizon] | None]], inverse: np.ndarray):
    """The horizons of each (submap, its horizons) in the frame ``inverse`` maps its map to."""
    return [h.moved(inverse @ s.anchor) for s, hs in views for h in hs or ()]


def chain_of(key: tuple[str, int], held: dict, options: PlaceOptions) -> list[Submap]:
    """Submap ``held[key]`` and its chain: its robot's submaps in ``held`` within k of it, k the
    least up to ``options.chain`` whose horizons see ``options.chain_view`` of the directions
    round it (a depth camera's view is narrow; a 360° LiDAR's needs none). Where its horizons
    are unknown, the submap alone."""
    s = held[key]
    if not s.horizons:
        return [s]
    own = [t for (robot, _), t in held.items() if robot == key[0]]
    inverse = np.linalg.inv(s.anchor)
    chain, seen = [], np.zeros(len(s.horizons[0].ranges), bool)
    for k in range(options.chain + 1):
        ring = [t for t in own if abs(t.seq - key[1]) == k]
        chain += ring
        for h in horizons_in([(t, t.horizons) for t in ring], inverse):
            seen |= ~np.isnan(h.ranges)
        if seen.mean() >= options.chain_view:
            break
    return sorted(chain, key=lambda t: t.seq)
