"""Free space in every submap: horizons recorded while building, carried to disk, and used by
verification to tell a place from its turned-round twin, on a 360° LiDAR and a depth camera."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import yaw_pose
from gmmap.config import Config
from gmmap.eval.place import truth
from gmmap.eval.registration import pose_errors
from gmmap.mapping.frame import Frame
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.submap import Submap, SubmapBuilder
from gmmap.options import BuildOptions, PlaceOptions

HEIGHT = 0.8  # the sensor above the floor (m)
TOP = 2.5  # the walls' height (m)
# A corridor closed at x = 0 that opens at x = 6 into a room reaching x = 10: alike from either
# end in the corridor, but only one end is closed.
WALLS = np.array([
    [(0, -1), (0, 1)], [(0, 1), (6, 1)], [(0, -1), (6, -1)],
    [(6, 1), (6, 4)], [(6, -1), (6, -4)], [(6, 4), (10, 4)], [(6, -4), (10, -4)],
    [(10, -4), (10, 4)],
], dtype=float)  # fmt: skip


def scan(xy, heading_deg: float, fov_deg: float, rng) -> np.ndarray:
    """What a sensor at ``xy`` (HEIGHT up), facing ``heading_deg``, sees over ``fov_deg``
    of azimuth and ±30° of elevation: the walls' first hits, and the floor before them; in
    the sensor's frame (x ahead, z up)."""
    az = np.radians(heading_deg + np.arange(-fov_deg / 2, fov_deg / 2, 0.5))
    d = np.stack([np.cos(az), np.sin(az)], axis=1)
    a, b = WALLS[:, 0], WALLS[:, 1]
    e = b - a
    w = a[None] - np.asarray(xy, float)[None, None]  # (rays, walls, 2)
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / den
        u = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / den
    t = np.where((t > 0) & (u >= 0) & (u <= 1), t, np.inf).min(axis=1)
    el = np.tan(np.radians(np.arange(-30.0, 30.0, 1.0)))
    r = np.broadcast_to(t[:, None], (len(t), len(el)))
    z = r * el[None]
    floor = z < -HEIGHT
    r = np.where(floor, -HEIGHT / np.where(floor, el[None], -1.0), r)
    keep = np.isfinite(r) & (z < TOP - HEIGHT)
    rel = np.radians(np.arange(-fov_deg / 2, fov_deg / 2, 0.5))[:, None] + 0 * r
    pts = np.stack([r * np.cos(rel), r * np.sin(rel), np.maximum(z, -HEIGHT)], axis=-1)[keep]
    return (pts + rng.normal(scale=0.005, size=pts.shape)).astype(np.float32)


def session(robot: str, start, headings, fov: float, frame: np.ndarray, rng) -> Submap:
    """One submap of a robot that creeps 5 cm along x per frame from ``start``, facing each
    of ``headings`` in turn and sensing as `scan`; its map frame sits at ``frame`` in the
    world."""
    builder = SubmapBuilder(robot, BuildOptions(n_components=60, submap_angle=None))
    for k, heading in enumerate(headings):
        xy = np.asarray(start, float) + np.array([0.05 * k, 0.0])
        world = yaw_pose(heading, (*xy, HEIGHT))
        pose = np.linalg.inv(frame) @ world
        builder.add(Frame(float(k), scan(xy, heading, fov, rng), pose, world))
    return builder.flush()


@pytest.mark.parametrize(
    ("fov", "a", "b"),
    [
        (360.0, ((2.8, 0.0), [0.0] * 5), ((2.2, 0.3), [0.0] * 5)),  # a handheld 360° LiDAR
        # A depth camera: a turns on the spot, b looks about the closed end. On the walls
        # alone (the world has no ceiling) the corridor laid upside down scores 0.95 of the
        # right alignment; the ranking leaves tilted solutions out, else the ambiguity
        # (place.max_ambiguity) would refuse the right match.
        (60.0, ((2.8, 0.0), range(0, 360, 45)), ((2.2, 0.3), range(90, 271, 30))),
    ],
)
def test_a_corridor_is_told_from_its_turned_twin_by_the_free_space_seen(fov, a, b) -> None:
    """Two robots in the corridor: the right alignment is accepted and the corridor seen end
    for end, which would put its closed end where a robot's rays went through, is refused.
    The same submaps without horizons cannot tell the two apart."""
    rng = np.random.default_rng(0)
    b_frame = yaw_pose(70, (3.0, -2.0, 0.4))
    held = [session("a", *a, fov, np.eye(4), rng), session("b", *b, fov, b_frame, rng)]
    assert all(s.horizons and s.horizon_band == (-0.25, 0.25) for s in held)
    options = PlaceOptions(max_distance=2.0, skip_recent=0)
    mapper = Mapper(Config(place=options))
    (match,) = mapper.add(held)
    query, key = mapper.submaps[match.query], (match.candidate.robot, match.candidate.seq)
    right = truth(query, mapper.submaps[key])
    t, r = pose_errors(match.registration.transform, right)
    assert match.accepted and t < 0.1 and r < 2.0, (match, t, r)
    # The twin: the alignment turned half round about the middle of the corridor.
    turn = yaw_pose(180, (6.0, 0.0, 0.0))
    twin = np.linalg.inv(mapper.submaps[key].gt_anchor) @ turn @ query.gt_anchor
    as_twin = replace(match, registration=replace(match.registration, transform=twin))
    refused = mapper._unseen(query, as_twin)
    assert not refused.accepted and refused.seen_through > options.max_seen_through
    assert mapper._unseen(query, match).seen_through <= options.max_seen_through
    # As a lookalike of its own robot's, the twin is no rival the verification could take.
    c = match.registration.confidence
    twin_only = replace(as_twin.registration, basins=((twin, c),))
    assert mapper._plausible(query, key, twin_only) == 0.0
    assert mapper._plausible(query, key, replace(twin_only, basins=((right, c),))) == pytest.approx(
        match.registration.upright
    )
    # Without horizons nothing says where the robots' rays went: the twin passes this test.
    blind = Mapper(Config(place=options))
    blind.hold([replace(s, horizons=None, horizon_band=None) for s in held])
    assert blind._unseen(blind.submaps[match.query], as_twin).accepted


def test_submaps_record_their_horizons_and_keep_them_on_disk(tmp_path) -> None:
    """Built submaps carry horizons in their anchor frame (a viewpoint per metre, 72
    directions), saved and loaded with them; ``horizon_band`` null records none."""
    rng = np.random.default_rng(1)
    s = session("a", (2.8, 0.0), [0.0] * 5, 360.0, yaw_pose(30, (1.0, 2.0, 0.0)), rng)
    (view,) = s.horizons
    np.testing.assert_allclose(view.origin, [0.0, 0.0], atol=1e-9)  # the anchor's own position
    assert len(view.ranges) == 72 and np.isfinite(view.ranges).all()
    # Facing the closed end 2.8 m away (x = 0), and +90°: the wall 1 m away.
    assert view.ranges[36] == pytest.approx(2.8, abs=0.1) and view.ranges[18] < 1.05
    s.save(tmp_path / "s.npz")
    back = Submap.load(tmp_path / "s.npz")
    assert back.horizon_band == s.horizon_band
    np.testing.assert_allclose(back.horizons[0].ranges, view.ranges, atol=0.1)
    builder = SubmapBuilder("a", BuildOptions(horizon_band=None))
    builder.add(Frame(0.0, scan((2.8, 0.0), 0.0, 360.0, rng), np.eye(4)))
    assert builder.flush().horizons is None
