"""Every setting of gmmap, each defined once with its one default: the sections of `gmmap.config`.

One frozen dataclass per stage of the data flow (build, select, register, place, backend, planner,
explore); the fleet's sections are defined in `gmmap.fleet_options`, the ROS one in
`gmmap.ros_options` and the simulator's in `gmmap.sim_options`, and re-exported here. The stages
take their section; the Rust core receives every value it uses from here. This module imports
nothing heavy (no GTSAM, no Zenoh), so a core install can read, validate and dump a configuration.
Each field's meaning is its ``#:`` comment, beside it or right above it (`gmmap.config_doc`); plain
``#`` comments say why.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

from gmmap.errors import InvalidInputError
from gmmap.fleet_options import (
    LinkOptions,
    RobotOptions,
    SecurityOptions,
    StationOptions,
    TransportOptions,
)
from gmmap.ros_options import RosOptions
from gmmap.sim_options import SENSORS, SimOptions

__all__ = [
    "SENSORS",
    "BackendOptions",
    "BuildOptions",
    "LinkOptions",
    "PlaceOptions",
    "PlannerOptions",
    "RegisterOptions",
    "RobotOptions",
    "RosOptions",
    "SecurityOptions",
    "SelectOptions",
    "SimOptions",
    "StationOptions",
    "TransportOptions",
    "drift_overrides",
]

STRATEGIES = ("points", "gmm-merge", "per-frame")
COVARIANCES = ("diag", "full")


@dataclass(frozen=True)
class BuildOptions:
    """How submaps are built (`gmmap.mapping.submap`).

    Submaps by space: a submap closes at the frame whose odometry has travelled
    ``submap_distance`` m of path or turned ``submap_angle``° since the last one closed, and
    ``frames_per_submap`` only caps its accepted frames. Every frame's motion counts, skipped or
    not, and the overshoot carries over, so the same smooth path sampled at 2, 10 or 30 Hz
    closes its submaps at the same places (a swaying sensor's path and turns sum to more the
    faster they are sampled: its submaps close sooner at a higher rate). 2 m or 90°: 20 frames
    of the simulated robots (5 Hz, 0.5 m/s) while they drive, as in the paper's simulation.
    Against 20 frames whatever the rate, on the simulated office (3 robots, seeds 0-2): the 360°
    LiDAR (32 beams over ±45°, 2 Hz, swaying) joins all 3 robot pairs in every seed instead of
    1, 0 and 0, the 16-beam LiDAR all 3 as before with more matches verified right (17-19 of
    18-21), and TUM fr1_xyz against its 10 and 5 Hz second sessions joins at 0.5 cm / 0.26° and
    0.9 cm / 0.44° instead of 2.0 cm / 0.94° and 0.7 cm / 0.73°. Distance and angle 0 or null:
    by frame count alone, the paper's protocol (`by_frames`: its Table I used 5 frames, its
    simulation 20). ``horizon_band``: each submap also records the free space its frames saw
    at these heights about its (levelled) anchor, 72 directions from a viewpoint every metre
    (`gmmap.mapping.frontier`), which registration and verification test matches against.
    Full covariances: registration across robots is more accurate with them
    (fr1_xyz halves, fast rotation) and the refit after selection produces full ones anyway.
    """

    frames_per_submap: int = 100  #: Accepted frames per submap; the most when by distance or angle
    submap_distance: float | None = 2.0  #: Odometry path (m) that closes a submap; 0 or null: off
    submap_angle: float | None = 90.0  #: Degrees turned that close a submap; 0 or null: off
    voxel_size: float = 0.05  #: Point-buffer voxel size (m)
    strategy: str = "points"  #: Fitting: points (one GMM), gmm-merge (one per frame) or per-frame
    n_components: int = 100  #: Components fitted per submap, before model selection
    covariance: str = "full"  #: Covariance type of the fitted components: diag or full
    min_novelty: float = 0.05  #: Skip a frame unless this fraction of its voxels is new
    select: bool = True  #: Adaptive model selection: merge redundant components (section select)
    refine_iter: int = 10  #: EM iterations (full covariances) after selection; 0: none
    holdout: float = 0.0  #: Fraction of buffered points withheld from fitting, for evaluation
    up: tuple[float, float, float] | None = (0.0, 0.0, 1.0)  #: Map frame's up; null: no levelling
    #: Heights (m) about the anchor whose free space each submap records; null: none
    horizon_band: tuple[float, float] | None = (-0.25, 0.25)
    max_iter: int = 100  #: EM iterations of a submap's fit, at most
    tol: float = 1e-3  #: EM convergence tolerance of a submap's fit
    seed: int = 0  #: Seed of the EM fit and of the holdout draw

    def __post_init__(self) -> None:
        if self.strategy not in STRATEGIES:
            raise InvalidInputError(f"strategy must be one of {STRATEGIES}, got {self.strategy!r}")
        if self.covariance not in COVARIANCES:
            raise InvalidInputError(f"covariance must be one of {COVARIANCES}")
        if self.frames_per_submap < 1 or self.n_components < 1:
            raise InvalidInputError("frames_per_submap and n_components must be >= 1")
        for name in ("submap_distance", "submap_angle"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"{name} must be >= 0 or null (0: off), got {value}")
        if not 0.0 <= self.holdout < 1.0 or not 0.0 <= self.min_novelty <= 1.0:
            raise InvalidInputError("holdout must be in [0, 1) and min_novelty in [0, 1]")
        if not self.voxel_size > 0:
            raise InvalidInputError(f"voxel_size must be > 0, got {self.voxel_size}")
        band = self.horizon_band
        if band is not None and not (len(band) == 2 and -10 < band[0] < band[1] < 10):
            raise InvalidInputError(f"horizon_band must be (low, high) within ±10 m, got {band}")

    def by_frames(self, frames: int) -> BuildOptions:
        """These options with submaps of ``frames`` accepted frames each, not by space: the
        paper's protocol, for experiments that compare with it."""
        return replace(self, frames_per_submap=frames, submap_distance=None, submap_angle=None)


@dataclass(frozen=True)
class SelectOptions:
    """Thresholds of the model selection (`gmmap.math.select`), for submaps and global maps.

    The defaults come from the sweep in ``benchmarks/selection.py`` (TUM fr1_xyz, fr3 cabinet,
    KITTI, the simulated office): on the indoor submaps they merge a third or more of 100
    components. Merging alone then costs 0.07-0.1 nats of held-out log-likelihood per point;
    the submap builder's refit afterwards (``BuildOptions.refine_iter``) more than wins it back.
    """

    flat_ratio: float = 0.1  #: Flat: least variance under this share of the middle one
    max_distance: float = 2.0  #: Only components whose means are closer than this (m) are compared
    kl_threshold: float = 16.0  #: Pairs under this symmetric Kullback-Leibler divergence merge

    def __post_init__(self) -> None:
        if not (math.isfinite(self.max_distance) and self.max_distance > 0):
            raise InvalidInputError(f"max_distance must be > 0, got {self.max_distance}")
        for name in ("flat_ratio", "kl_threshold"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"{name} must be finite and >= 0, got {value}")


@dataclass(frozen=True)
class RegisterOptions:
    """GMM-to-GMM registration (`gmmap.math.register`).

    Ladders are standard deviations (m) added to every covariance, coarse to fine. From a guess
    the ladder starts at 20 cm: a guess 10-20° off (a fast-turning camera, a rough yaw) ends
    within GICP's error from there (`gmmap eval registration --guess-error 10-20`), and from
    5 cm it does not always. A global search starts wider, where the yaw starts are compared,
    and ends at 1 cm rather than 0: the sharpest components of smeared depth submaps hold
    single matches degrees off (fr1_xyz against itself re-sampled at 10 Hz: the merged frame
    2.0 cm instead of 2.6 cm; global mode 0.95 cm / 0.64°, all pairs within 5 cm / 2°).
    ``information_scale`` None: the smaller component count (each component one independent
    measurement). ``confidence_scale``: the widening under which C is measured, so that it
    reflects shared geometry rather than how sharply each side was fitted.

    A global search starts from the best maxima of translation votes over ``yaw_starts`` yaws
    (`gmmap.math.register`): two submaps that overlap in part align far from their centroids.
    ``level_planes`` false: it also searches without the level planes (floor, ceiling, table
    tops) and ranks its solutions by what is left, since those planes line up under any yaw
    and horizontal shift (`gmmap.math.register`).
    """

    #: From a guess: std devs (m) added to every covariance, coarse to fine
    local_scales: tuple[float, ...] = (0.2, 0.1, 0.05, 0.0)
    #: Without a guess (global search): std devs (m) added, coarse to fine
    global_scales: tuple[float, ...] = (0.2, 0.1, 0.03, 0.01)
    max_iter: int = 10  #: Levenberg-Marquardt iterations per scale
    # From a guess, scales >= 10 cm (but the last) see the mixtures merged in cells of this
    # many times the scale (`gmmap.math.register`); 0: the whole mixtures at every scale.
    coarse_cell: float = 2.0  #: From a guess, coarse scales merge mixtures in cells of this × scale
    yaw_starts: int = 24  #: Rotations about +z a global search tries
    search_cell: float = 0.5  #: Global search: spacing and blur (m) of its translation votes
    search_starts: int = 24  #: Global search: the votes' best maxima optimised at the coarse scale
    refine_starts: int = 2  #: Global search: distinct coarse solutions refined to the finest scale
    level_planes: bool = False  #: Let floors and ceilings rank global solutions and lookalikes
    dof: int = 6  #: Degrees of freedom: 6, or 4 (x, y, z and yaw only: ground robots)
    information_scale: float | None = None  #: Measurements counted; null: smaller component count
    confidence_scale: float = 0.05  #: σ (m) added to every covariance to measure the confidence C
    tol: float = 1e-5  #: A scale ends when the step is smaller (radians + metres)
    cutoff: float = 4.0  #: Component pairs farther apart than this many σ are skipped

    def __post_init__(self) -> None:
        if self.dof not in (4, 6):
            raise InvalidInputError(f"dof must be 4 or 6, got {self.dof}")
        for name in ("local_scales", "global_scales"):
            ladder = getattr(self, name)
            if not ladder or not all(math.isfinite(s) and s >= 0 for s in ladder):
                raise InvalidInputError(f"{name} must be finite values >= 0, got {ladder}")
        if not (math.isfinite(self.coarse_cell) and self.coarse_cell >= 0):
            raise InvalidInputError("coarse_cell must be finite and >= 0")
        if not (math.isfinite(self.confidence_scale) and self.confidence_scale >= 0):
            raise InvalidInputError("confidence_scale must be finite and >= 0")
        if self.max_iter < 1 or min(self.yaw_starts, self.refine_starts, self.search_starts) < 1:
            raise InvalidInputError("max_iter, yaw_starts, refine_starts, search_starts: >= 1")
        if not (self.cutoff > 0 and self.tol > 0 and 0 <= self.search_cell < math.inf):
            raise InvalidInputError("cutoff, tol > 0 and a finite search_cell >= 0")
        if self.information_scale is not None and not self.information_scale > 0:
            raise InvalidInputError("information_scale must be > 0 (or null)")


DESCRIPTORS = ("shape", "learned")


@dataclass(frozen=True)
class PlaceOptions:
    """Place recognition and verification (`gmmap.mapping.place`). ``max_distance``: the paper's
    d_thr on cosine distance; ``min_confidence``: C_thr; ``top_k`` candidates verified per
    query; a robot's ``skip_recent`` latest own submaps are not candidates (they overlap the
    query by construction).

    C_thr 0.55 with ``max_ambiguity`` 0.7: true cross-session matches of one desk (fr1_xyz
    against itself at 10 Hz) score C 0.58-0.91, the best other basin 0.3-0.4 of C. A match
    alone does not join two maps: simulated corridor views turned 180° score as high (C up to
    0.87), hence `BackendOptions.min_matches` and ``max_conflict`` (a query that candidates
    put at two places of one map is rejected).

    ``sure_confidence`` 0.85: from this C on, ``max_ambiguity`` is waived (the other tests
    stay): 360° LiDAR scans of alike rooms leave right matches a second basin at 0.8 of C,
    wrong ones score C 0.87 at most (simulated office; docs/guide/merging.md).

    ``max_seen_through`` 0.02: where both submaps come with horizons (exploring robots), a
    match may put at most this share of either's surfaces where the other's rays went
    through; random-office:101: right matches ≤ 0.009, wrong ≥ 0.025 but one (explore.md).

    ``max_turned`` 0.9: each accepted match's half-turned twin is probed (`place.turned`); on
    the simulated LiDARs it refused 7 wrong verified matches and 1 right one (right twins
    0.75-0.87 C, wrong flips' twins 0.9-0.95 C: a lower limit refuses right ones).

    ``refine_neighbours``: an accepted match's pose is refined against the candidate and its
    robot's held submaps up to this many sequence numbers away, as one mixture in the
    candidate's frame (submap to local map). One submap pins rotation poorly where the overlap
    is partial: on fr1_xyz's sessions and halves 3 of 135 verified matches end 3.7-5.9° off,
    none after refining over ±2 (median 2.5 cm / 1.0° → 1.8 cm / 0.8°). 0: no refinement. A
    match the refinement moves more than ``max_refine_shift`` m is rejected: right ones move
    at most 9 cm there (2.3 cm simulated), fr3 cabinet's 0.57 m / 27° wrong one 0.28 m.

    ``min_conditioning`` 0.004: a match must pin its freest direction of translation, after
    refinement, at least this fraction as firmly as its firmest (`Registration.conditioning`):
    two bare corridors coincide at any offset along them. Simulated office, 3 robots: wrong
    verified matches 0.00001-0.004, right ones 0.003-0.06; TUM fr1_xyz's 0.005-0.05. Chosen
    on seeds 0-2; on seeds 3-4 it refuses all 15 wrong verified matches and 1 of 82 right.

    ``min_probability`` null: every match carries `Match.probability` (`gmmap.mapping
    .calibration`), none is refused on it: held out (benchmarks/calibration.py), 0.5 refuses 3
    more wrong matches and 4 right ones, 2 of them TUM's real ones, which it undervalues.
    """

    # "shape": the training-free D2 descriptor; "learned": PointNetVLAD
    # (`gmmap.mapping.learned`), with ``weights`` (null: the ones shipped with gmmap).
    descriptor: str = "shape"  #: Place descriptor: shape (training-free) or learned (PointNetVLAD)
    weights: str | None = None  #: Learned descriptor's weights; null: those shipped with gmmap
    top_k: int = 5  #: Candidates verified per query
    # The candidates' cosine distance limit; null: the descriptor's own (shape 0.1; learned:
    # set by its training run).
    max_distance: float | None = None  #: Candidates' cosine distance limit; null: descriptor's
    min_confidence: float = 0.55  #: Least confidence C of an accepted match (the paper's C_thr)
    # Reject when another basin scores this close to the best (alternative / confidence):
    # the geometry is ambiguous, e.g. a corridor seen end for end.
    max_ambiguity: float = 0.7  #: Score falls to 0 as the best other basin rises from this·C to C
    sure_confidence: float | None = 0.85  #: From this C on, max_ambiguity is waived; null: never
    # Another verified candidate of the query, elsewhere in that robot's map (`place.distinct`).
    max_conflict: float = 0.8  #: Reject if a candidate elsewhere in that map verifies this close
    conflict_distance: float = 1.0  #: Elsewhere, for max_conflict: more than this far (m)
    conflict_angle: float = 10.0  #: ... or turned more than this (degrees)
    skip_recent: int = 2  #: A robot's latest own submaps, not candidates (they overlap the query)
    resample_points: int = 4096  #: Points sampled from a mixture to describe it (PointNetVLAD's)
    use_yaw_hint: bool = False  #: Verify from the descriptor's yaw instead of the full yaw search
    # A narrow view (a depth camera's) is registered as a chain: its robot's submaps about
    # it, out to ±chain, until their horizons see chain_view of the directions round it.
    chain: int = 5  #: Register a narrow view with its robot's submaps up to ±this; 0: alone
    chain_view: float = 0.95  #: ... until their horizons see this share of directions
    chain_min_confidence: float = 0.3  #: Least C of a match where either side is a chain
    refine_neighbours: int = 2  #: Refine a match over the candidate robot's submaps ±this; 0: off
    max_refine_shift: float = 0.15  #: Reject a match the refinement moves more than this (m)
    # `gmmap.mapping.confusion`: the best C each submap reaches against its own robot's
    # submaps that odometry puts apart (up to confusion_probes of them): its lookalikes that
    # fill no free space its robot saw must stay under max_confusion·C, all under
    # max_any_confusion·C.
    max_confusion: float = 0.85  #: Refuse a match unless plausible lookalikes stay under this·C
    max_any_confusion: float = 1.0  #: Refuse a match unless every lookalike stays under this·C
    confusion_probes: int = 3  #: Own distant submaps confusion is measured against; 0: no test
    max_turned: float | None = 0.9  #: Refuse if the half-turned match scores this·C; null: off
    min_conditioning: float = 0.004  #: Refuse a match pinned this loosely in some direction; 0: off
    max_seen_through: float | None = 0.02  #: Refuse if this share of surfaces meets seen free space
    # Refuse a match less likely right (`gmmap.mapping.calibration`) or unknown; null: off
    min_probability: float | None = None  #: Refuse a match less likely right than this; null: off
    calibration: str | None = None  #: The calibration's JSON; null: the one shipped with gmmap

    def __post_init__(self) -> None:
        if (
            self.top_k < 1
            or self.resample_points < 2
            or min(self.skip_recent, self.chain, self.refine_neighbours, self.confusion_probes) < 0
        ):
            raise InvalidInputError(
                "top_k >= 1, resample_points >= 2, skip_recent, chain, refine_neighbours and "
                "confusion_probes >= 0"
            )
        far = self.max_distance
        if not 0 <= self.chain_view <= 1 or not 0 <= self.chain_min_confidence <= 1:
            raise InvalidInputError("chain_view and chain_min_confidence must be in [0, 1]")
        if not 0 <= self.min_confidence <= 1 or not (far is None or 0 <= far <= 2):
            raise InvalidInputError("min_confidence in [0, 1], max_distance in [0, 2] or null")
        if self.descriptor not in DESCRIPTORS:
            raise InvalidInputError(
                f"place.descriptor must be one of {', '.join(DESCRIPTORS)}, got {self.descriptor!r}"
            )
        if not self.max_refine_shift > 0:
            raise InvalidInputError(f"max_refine_shift must be > 0, got {self.max_refine_shift}")
        if self.max_turned is not None and not (
            math.isfinite(self.max_turned) and self.max_turned > 0
        ):
            raise InvalidInputError(f"max_turned must be > 0 or null, got {self.max_turned}")
        sure = self.sure_confidence
        if not 0 < self.max_ambiguity <= 1 or not (sure is None or 0 < sure <= 1):
            raise InvalidInputError(
                f"max_ambiguity in (0, 1], sure_confidence in (0, 1] or null, got "
                f"{self.max_ambiguity} and {sure}"
            )
        least, seen = self.min_probability, self.max_seen_through
        if not 0 <= self.min_conditioning < 1 or not all(
            v is None or 0 <= v <= 1 for v in (least, seen)
        ):
            raise InvalidInputError(
                f"min_conditioning in [0, 1), min_probability and max_seen_through in [0, 1] "
                f"or null, got {self.min_conditioning}, {least} and {seen}"
            )
        if not (self.max_conflict > 0 and self.conflict_distance > 0 and self.conflict_angle > 0):
            raise InvalidInputError("max_conflict, conflict_distance, conflict_angle must be > 0")


@dataclass(frozen=True)
class BackendOptions:
    """Noise models, robustness switches and thresholds of the pose graph
    (`gmmap.mapping.backend`).

    The odometry parameters mean what `gmmap.math.drift.Drift`'s do (floors > 0 so a robot
    standing still still gives an invertible factor). A match's covariance gets the match
    floors added in quadrature, because registration information (component counts as
    independent measurements) is optimistic: the curvature says millimetres, while verified
    cross-robot matches on real data are off by a median 2.7 cm / 0.95° (fr1_xyz halves). With
    the floors at that accuracy every match counts about alike, and the merged frame of the
    fr1_xyz halves comes to 2.3 cm / 1.0° instead of 3.8 cm / 1.5° with 1 cm / 0.3° floors.
    """

    translation: float = 0.02  #: Odometry translation σ per metre travelled, each axis
    translation_floor: float = 0.001  #: Odometry translation σ per step (m; > 0 for a still robot)
    rotation_per_rad: float = 0.02  #: Odometry rotation σ per radian turned (rad)
    rotation_per_m: float = 0.005  #: Odometry rotation σ per metre travelled (rad)
    rotation_floor: float = 0.001  #: Odometry rotation σ per step (rad; > 0 for a still robot)
    match_sigma_translation: float = 0.05  #: Match translation σ (m) where it has no information
    match_sigma_rotation: float = 0.02  #: Match rotation σ (rad) where it has no information
    match_floor_translation: float = 0.03  #: Translation σ (m) added in quadrature to every match
    match_floor_rotation: float = 0.017  #: Rotation σ (rad) added in quadrature to every match
    pcm: bool = True  #: Pairwise consistency maximisation: keep each robot pair's consistent set
    # χ² quantile of the pairwise test. Lenient on purpose: with m true matches between two
    # robots about m²(1 − p)/2 true pairs fail and the clique loses up to one match per failed
    # pair, while random wrong matches sit at d² in the thousands; GNC judges what passes.
    pcm_probability: float = 0.999  #: χ² quantile of PCM's pairwise consistency test
    pcm_exact_budget: int = 5_000  #: Branch-and-bound nodes of PCM's exact search, per robot pair
    # Two robots' maps join only once their mutually consistent matches hold min_matches
    # matches, or min_strong_matches of confidence >= strong_confidence (a match given without
    # a confidence counts as strong), resting on at least min_submaps submaps of each robot;
    # fewer are held back ("pending") until more arrive. One match is never enough by
    # default: PCM cannot test it, and a corridor seen end for end scores as high as a true
    # match (simulated depth cameras: C up to 0.87 at 2-12 m off). Matches that rest on one
    # submap are one registration repeated: a query misplaced 8.8 m along a corridor matched
    # the other robot's three consecutive submaps there, and the three agreed (simulated
    # office, depth camera, seed 3 of benchmarks/merge_sweep.py); min_submaps refuses that
    # join and lets three matches join elsewhere (docs/guide/merging.md).
    min_matches: int = 3  #: Consistent matches before two robots' maps join
    min_strong_matches: int = 3  #: ... or this many strong ones (confidence >= strong_confidence)
    strong_confidence: float = 0.75  #: Confidence from which a match counts as strong
    min_submaps: int = 2  #: ... resting on at least this many submaps of each robot
    # ... and only while the consistent set is at least this share of all the matches verified
    # between them: most verified matches disagreeing is ambiguous geometry (a floor that fills
    # every mixture, a symmetric object seen from the other side), not two matched places.
    min_consistent_share: float = 0.5  #: Join only while consistent matches are this share of all
    # ... and only while no path through a third robot, both of whose matches are strong and
    # more confident than their median match, puts them elsewhere: this far (m) or turned
    # this much (degrees) at the path's submap (`gmmap.mapping.consistency.contradicted`).
    # Odometry drift between the path's submaps must stay under these (simulated LiDAR
    # fleets: at most 0.5 m and 3.5° on true paths; a corridor seen end for end: 180°).
    path_distance: float = 2.0  #: A path via a third robot this far off (m) contradicts a join
    path_angle_deg: float = 15.0  #: ... or turned this much (degrees)
    gnc: bool = True  #: Graduated non-convexity: the solve judges matches and drops outliers
    gnc_probability: float = 0.99  #: χ² quantile of GNC's inlier threshold
    prior_sigma: float = 1e-4  #: σ of the reference prior (m and rad)
    max_iterations: int = 100  #: Levenberg-Marquardt iterations, per GNC step

    @classmethod
    def for_drift(cls, drift: float, **options: Any) -> BackendOptions:
        """Odometry noise of `Drift.per_metre` (drift), the other ``options`` as given: the
        default 0.02 is wheel odometry; motion-capture poses (TUM's ground truth) are nearer
        0.002."""
        return cls(**drift_overrides(drift), **options)

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if isinstance(value, bool):
                continue
            if not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"BackendOptions.{name} must be finite and >= 0")
        for name in ("translation_floor", "rotation_floor", "prior_sigma"):
            if getattr(self, name) <= 0:
                raise InvalidInputError(f"BackendOptions.{name} must be > 0")
        for name in ("min_matches", "min_strong_matches", "min_submaps"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise InvalidInputError(f"BackendOptions.{name} must be an integer >= 1")
        if not 0 <= self.strong_confidence <= 1:
            raise InvalidInputError("BackendOptions.strong_confidence must be in [0, 1]")
        if not 0 <= self.min_consistent_share <= 1:
            raise InvalidInputError("BackendOptions.min_consistent_share must be in [0, 1]")
        for name in ("pcm_probability", "gnc_probability"):
            if not 0 < getattr(self, name) < 1:
                raise InvalidInputError(f"BackendOptions.{name} must be in (0, 1)")
        if self.match_sigma_translation <= 0 or self.match_sigma_rotation <= 0:
            raise InvalidInputError("BackendOptions.match_sigma_* must be > 0")


def drift_overrides(drift: float) -> dict[str, float]:
    """The drift model's fields for one drift figure (`gmmap.math.drift.Drift.per_metre`, the
    odometry fields of `BackendOptions`): ``drift`` per metre per axis and rad per radian
    turned, a quarter of it in rad per metre."""
    return {"translation": drift, "rotation_per_rad": drift, "rotation_per_m": drift / 4}


@dataclass(frozen=True)
class PlannerOptions:
    """Robot size and the planner's rule (`gmmap.mapping.planner`). Heights are in the map frame
    (floor at z = 0)."""

    robot_radius: float = 0.2  #: Robot radius (m)
    margin: float = 0.05  #: Clearance (m) beyond the radius (A* baseline inflates one 5 cm cell)
    z_band: tuple[float, float] = (0.05, 1.2)  #: Heights the robot's body occupies
    step: float = 0.1  #: Metres per step
    g_thr: float = 1.5  #: Directional gradient threshold (occupancy per metre)
    min_support: float = 0.05  #: Density, relative to the map's median, of a full obstacle
    max_occupancy: float = 0.5  #: The level at radius + margin from a surface; never entered
    goal_tolerance: float = 0.15  #: Distance (m) from the goal that counts as arrived
    directions: int = 12  #: Headings tried around the goal's direction (12: every 30°)
    max_steps: int = 2000  #: Steps before giving up
    stuck_window: int = 80  #: Steps without progress towards the goal before giving up

    def __post_init__(self) -> None:
        if not (self.robot_radius > 0 and self.step > 0 and self.goal_tolerance > 0):
            raise InvalidInputError("robot_radius, step and goal_tolerance must be positive")
        if self.z_band[1] <= self.z_band[0]:
            raise InvalidInputError(f"z_band must be (low, high), got {self.z_band}")
        if self.directions < 4 or self.directions % 2:
            raise InvalidInputError("directions must be an even number >= 4")
        if not 0 < self.max_occupancy < 1:
            raise InvalidInputError("max_occupancy must be in (0, 1)")


@dataclass(frozen=True)
class ExploreOptions:
    """Exploration (`gmmap.mapping.explore`): free-space horizons added to each shared submap,
    frontiers, the route graph between viewpoints, and how robots share goals. The simulator's
    robots, world and sensor are the ``sim`` section's; the run ends when no robot has a
    frontier left or after ``time_budget`` s of simulated time. A frame binned from the
    current horizon's viewpoint that would lose or invent over ``max_distortion`` of its own
    view's free space (a door between the two), or invent over 0.3 m along one direction (a
    wall between the two), starts a horizon of its own."""

    bins: int = 72  #: Directions per free-space horizon (72: every 5°, one byte each)
    horizon_spacing: float = 1.0  #: Metres of path between two horizons' viewpoints
    #: Share of free space a view may lose or invent binned from the viewpoint; null: any
    max_distortion: float | None = 0.2
    link_radius: float = 2.5  #: Viewpoints this close join the route graph if known free between
    #: Frontier points (open ones first) a cluster needs to be a goal while a larger one is left
    min_frontier: int = 3
    claim_radius: float = 2.0  #: A frontier this close to a peer's goal is left to the peer
    replan_s: float = 4.0  #: Seconds of travel between two goal choices
    turn_rate: float = 0.8  #: Turning rate (rad/s) of the simulated robots
    time_budget: float = 300.0  #: Simulated seconds before a run ends

    def __post_init__(self) -> None:
        if self.bins < 8 or self.bins > 720:
            raise InvalidInputError(f"explore.bins must be in [8, 720], got {self.bins}")
        if not (self.horizon_spacing > 0 and self.link_radius > 0 and self.claim_radius >= 0):
            raise InvalidInputError("explore.horizon_spacing, link_radius > 0, claim_radius >= 0")
        if not (self.replan_s > 0 and self.turn_rate > 0 and self.time_budget > 0):
            raise InvalidInputError("explore.replan_s, turn_rate and time_budget must be > 0")
        if self.min_frontier < 1:
            raise InvalidInputError("explore.min_frontier must be >= 1")
        if self.max_distortion is not None and not 0 <= self.max_distortion <= 1:
            raise InvalidInputError(
                f"explore.max_distortion must be in [0, 1] or null, got {self.max_distortion}"
            )
