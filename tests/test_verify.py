"""Verification with the defaults: partial overlap verified, aliasing not; fast rotation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import yaw_pose
from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.registration import evaluate_registration, pose_errors
from gmmap.io.datasets import BUNDLED_TUM_SLICE
from gmmap.io.datasets.tum import TumRgbd
from gmmap.mapping.confusion import Confusion
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.place import Candidate, Match, PlaceDatabase, distinct
from gmmap.mapping.submap import Submap, build_submaps
from gmmap.math.em import fit_gmm
from gmmap.math.gmm import Gmm
from gmmap.math.register import Registration, register
from gmmap.options import BuildOptions, PlaceOptions


def plane(rng, origin, u, v, size_u, size_v, spacing=0.05) -> np.ndarray:
    a, b = np.meshgrid(np.arange(0, size_u, spacing), np.arange(0, size_v, spacing))
    p = np.asarray(origin) + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    return p + rng.normal(scale=0.005, size=p.shape)


def corridor(rng) -> np.ndarray:
    """Two parallel walls over a floor: the same from either end."""
    x, y, z = np.eye(3)
    return np.vstack([
        plane(rng, (0, -1, 0), x, y, 6, 2),
        plane(rng, (0, -1, 0), x, z, 6, 2),
        plane(rng, (0, 1, 0), x, z, 6, 2),
    ])  # fmt: skip


def fit(points: np.ndarray) -> Gmm:
    return fit_gmm(points, 100, covariance="full", seed=0)


def verify(query: Gmm, target: Gmm, options: PlaceOptions | None = None):
    db = PlaceDatabase(options=options or PlaceOptions())
    db.add("b", 0, target)
    return db.verify("a", 0, query, Candidate("b", 0, 0.0))


def test_a_partial_overlap_is_verified_and_a_flipped_corridor_is_not() -> None:
    # Two 2-frame submaps of the bundled desk recording, 2.7 s apart: they share part of the
    # desk. Their anchors' ground truth gives the right alignment.
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)
    options = BuildOptions(frames_per_submap=2, n_components=60)
    a, b = (next(iter(build_submaps(frames[i : i + 2], "x", options))) for i in (0, 4))
    m = verify(a.gmm, b.gmm)
    t, r = pose_errors(m.registration.transform, np.linalg.inv(b.gt_anchor) @ a.gt_anchor)
    assert m.accepted and t < 0.05 and r < 2.0, (m.registration.confidence, t, r)
    # A corridor and the same corridor seen from its other end: two alignments explain it
    # equally well (the right one and the 180° flip). With sure_confidence off the close
    # second basin refuses it; with it on (C is 1 here) the half-turned twin and the slide
    # test refuse it.
    rng = np.random.default_rng(0)
    hall = corridor(rng)
    flipped = hall @ yaw_pose(180, (6.0, 0.0, 0.0))[:3, :3].T + (6.0, 0.0, 0.0)
    m = verify(fit(hall), fit(flipped), PlaceOptions(sure_confidence=None))
    assert not m.accepted, (m.registration.confidence, m.registration.alternative_confidence)
    held = [submap("a", 0, np.eye(4), hall), submap("b", 0, np.eye(4), flipped)]
    options = PlaceOptions(max_distance=2.0, skip_recent=0)
    (m,) = Mapper(Config(place=options)).add(held)
    assert m.registration.confidence >= options.sure_confidence and not m.accepted


def test_a_sure_match_is_not_held_back_by_a_close_second_basin() -> None:
    """Alike rooms leave a right 360° LiDAR match a second basin near its C: from
    ``sure_confidence`` on, C alone is the score (`Mapper`'s twin, chance and slide tests
    still follow); under it, and with it off, the close second holds the match back."""
    reg = Registration(np.eye(4), 0.9, np.eye(6), 1, 0.0, alternative_confidence=0.85)
    least = PlaceOptions().min_confidence
    assert PlaceDatabase().score(reg) == 0.9
    assert PlaceDatabase(options=PlaceOptions(sure_confidence=None)).score(reg) < least
    assert PlaceDatabase().score(replace(reg, confidence=0.8, alternative_confidence=0.75)) < least
    with pytest.raises(InvalidInputError, match="sure_confidence"):
        PlaceOptions(sure_confidence=1.5)


def test_a_fast_rotation_pair_registers_from_the_identity_within_gicps_error(shared_data):
    """Consecutive 2-frame fr1_xyz submaps started from the truth turned 10-20° (a fast-turning
    camera's motion between submaps, as seen by a guess of the identity): GMM registration ends
    no farther from the truth than GICP, mean and median."""
    pytest.importorskip("small_gicp")
    frames = TumRgbd(shared_data / "tum_fr1_xyz", stride=2)
    r = evaluate_registration(
        frames, 2, ("points", "gicp"), max_pairs=30, options=BuildOptions(), guess_deg=(10, 20)
    )
    gmm, gicp = r["methods"]["points"], r["methods"]["gicp"]
    for key in ("t_error_mean", "t_error_median", "r_error_mean", "r_error_median"):
        assert gmm[key] <= gicp[key], (key, gmm[key], gicp[key])
    assert gmm["success_rate"] >= 0.95


def test_a_query_that_fits_two_places_of_one_map_is_rejected() -> None:
    """Two candidates in robot b's map both take the query, 5 m apart: neither is kept; a
    third at the first one's place agrees with it and does not count against it."""

    def match(seq: int, confidence: float) -> Match:
        reg = Registration(np.eye(4), confidence, np.eye(6), 1, 0.0)
        return Match(("a", 0), Candidate("b", seq, 0.0), reg, True)

    anchors = {("b", 0): np.eye(4), ("b", 1): yaw_pose(0, (5.0, 0, 0)), ("b", 2): np.eye(4)}
    judged = distinct([match(0, 0.8), match(1, 0.75), match(2, 0.7)], anchors, PlaceOptions())
    assert [m.accepted for m in judged] == [False, False, False]
    assert judged[0].conflict == pytest.approx(0.75 / 0.8)
    # A competitor that failed verification itself does not count.
    failed = replace(match(1, 0.75), accepted=False)
    judged = distinct([match(0, 0.8), failed], anchors, PlaceOptions())
    assert judged[0].accepted and judged[0].conflict == 0.0
    # Alone with its agreeing neighbour, the first is kept.
    judged = distinct([match(0, 0.8), match(2, 0.7)], anchors, PlaceOptions())
    assert [m.accepted for m in judged] == [True, True] and judged[0].conflict == 0.0


def room(rng) -> np.ndarray:
    """The corridor closed at one end, with a cabinet: not the same from its other end."""
    x, y, z = np.eye(3)
    end = plane(rng, (0, -1, 0), y, z, 2, 2)
    cabinet = [plane(rng, (1.0, 0.4, 0), x, z, 0.8, 1.2), plane(rng, (1.0, 0.4, 0), y, z, 0.6, 1.2)]
    return np.vstack([corridor(rng), end, *cabinet])


def hall(rng) -> np.ndarray:
    """A wide hall with a low wall across it: like nothing else here."""
    x, y, z = np.eye(3)
    return np.vstack([
        plane(rng, (0, -3, 0), x, y, 6, 6),
        plane(rng, (0, -3, 0), y, z, 6, 2),
        plane(rng, (3, -2, 0), y, z, 3, 0.8),
        plane(rng, (0, 3, 0), x, z, 6, 2),
    ])  # fmt: skip


def submap(robot: str, seq: int, anchor: np.ndarray, points: np.ndarray) -> Submap:
    local = (points - anchor[:3, 3]) @ anchor[:3, :3]
    return Submap(robot, seq, anchor, np.array([float(seq)]), len(points), fit(local))


def test_a_match_as_good_as_the_robots_own_lookalikes_is_refused() -> None:
    """Robot a has seen two identical rooms 30 m apart by its odometry (a building of equal
    offices): b's view of such a room fits a's first as well as it would fit a's second, so
    the match proves nothing and is refused. a's hall, unlike anything else a has seen,
    matches b's view of it and is kept."""
    rng = np.random.default_rng(1)
    office, other = room(rng), hall(rng)
    away = (30.0, 0.0, 0.0), (60.0, 0.0, 0.0)
    b_frame = yaw_pose(70, (3.0, -2.0, 0.0))  # where b's map frame sits in a's
    held = [
        submap("a", 0, np.eye(4), office),
        submap("a", 1, yaw_pose(0, away[0]), office + away[0]),
        submap("a", 2, yaw_pose(0, away[1]), other + away[1]),
        submap("b", 0, np.linalg.inv(b_frame), room(rng)),
        submap("b", 1, np.linalg.inv(b_frame) @ yaw_pose(0, away[1]), hall(rng) + away[1]),
    ]
    # Only this test decides here: no within-pair ambiguity test, no local-map refinement.
    options = PlaceOptions(max_distance=2.0, max_ambiguity=1.0, skip_recent=0, refine_neighbours=0)
    mapper = Mapper(Config(place=options))
    matches = {(m.query, (m.candidate.robot, m.candidate.seq)): m for m in mapper.add(held)}
    lookalike = matches[(("a", 0), ("b", 0))]
    assert lookalike.registration.confidence > 0.8
    assert not lookalike.accepted and lookalike.plausible_confusion >= options.max_confusion
    unique = matches[(("a", 2), ("b", 1))]
    assert unique.accepted and unique.plausible_confusion < options.max_confusion
    truth = np.linalg.inv(held[4].anchor) @ held[2].anchor
    t, r = pose_errors(unique.registration.transform, truth)
    assert t < 0.05 and r < 1.0, (t, r)


def test_a_match_free_to_slide_along_a_bare_corridor_is_refused() -> None:
    """Two robots see the same stretch of two bare walls over a floor: their mixtures
    coincide wherever they are slid along it, so the match pins nothing lengthwise and is
    refused (`PlaceOptions.min_conditioning`); with that test off it is accepted. The same
    stretch with a cabinet and a closed end (`room`) is pinned and kept."""
    rng = np.random.default_rng(2)
    b_frame = yaw_pose(40, (2.0, 1.0, 0.0))
    # Only this test decides here: the corridor is the same from either end.
    options = PlaceOptions(max_distance=2.0, max_ambiguity=1.0, skip_recent=0, max_turned=None)
    for scene, kept in ((corridor, False), (room, True)):
        held = [
            submap("a", 0, np.eye(4), scene(rng)),
            submap("b", 0, np.linalg.inv(b_frame), scene(rng)),
        ]
        (match,) = Mapper(Config(place=options)).add(held)
        assert match.registration.confidence > 0.8
        assert (match.registration.conditioning >= options.min_conditioning) == kept
        assert match.accepted == kept
        (free,) = Mapper(Config(place=replace(options, min_conditioning=0.0))).add(held)
        assert free.accepted


@pytest.mark.parametrize(
    ("plausible", "level", "accepted"),
    [(0.5, 0.95, True), (0.9, 0.95, False), (0.5, 1.1, False), (0.0, 0.0, True)],
)
def test_a_match_must_clear_plausible_lookalikes_by_a_margin_and_beat_all(
    plausible, level, accepted
) -> None:
    """Lookalikes that fill free space their robot saw only need beating (max_any_confusion,
    1); those that do not, by the margin max_confusion (0.85)."""
    rng = np.random.default_rng(3)
    held = [submap("a", 0, np.eye(4), room(rng)), submap("b", 0, np.eye(4), room(rng))]
    mapper = Mapper(Config())
    mapper.hold(held)
    reg = register(held[0].gmm, held[1].gmm, np.eye(4))
    m = Match(("a", 0), Candidate("b", 0, 0.0), reg, accepted=True)
    c = reg.upright  # confusion is told on the upright parts
    mapper._confusions = {
        ("a", 0): Confusion(level * c, plausible * c),
        ("b", 0): Confusion(),
    }
    judged = mapper._unconfused(m)
    assert judged.accepted == accepted
    assert judged.plausible_confusion == pytest.approx(plausible)
    assert judged.confusion == pytest.approx(level)
