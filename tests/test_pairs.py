"""Robot-pair errors: where the robots met vs their map frames (gmmap.eval.pairs)."""

import numpy as np

from gmmap.eval.pairs import describe_pair, pair_errors
from gmmap.math.geometry import invert


def _pose(x: float, y: float, yaw_deg: float = 0.0) -> np.ndarray:
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = x, y
    return T


def test_drift_shows_in_the_frames_not_where_the_robots_met():
    # b starts 5 m from a; its odometry turned 2° wrong before it reached a's second submap.
    truth = {("a", 0): _pose(0, 0), ("a", 1): _pose(10, 0), ("b", 0): _pose(5, 0),
             ("b", 1): _pose(10, 0.5)}  # fmt: skip
    map_to_world = {"a": np.eye(4), "b": _pose(5, 0)}
    # The optimised poses agree with the truth where a and b met, b's start is off by the drift.
    poses = dict(truth)
    poses[("b", 0)] = truth[("b", 1)] @ _pose(0, 0, 2.0) @ invert(truth[("b", 1)]) @ truth[("b", 0)]
    to_reference = {"a": np.eye(4), "b": poses[("b", 0)]}  # b's map frame: its first anchor
    met = [(("a", 1), ("b", 1))]
    (p,) = pair_errors([["a", "b"]], ["a", "b"], poses, truth, met, to_reference, map_to_world)
    assert p["matches"] == 1 and p["t_error"] < 1e-9 and p["r_error_deg"] < 1e-6
    assert np.isclose(p["frame_r_error_deg"], 2.0) and p["frame_t_error"] > 0.1
    assert "where they met" in describe_pair(p)


def test_pairs_without_a_match_use_the_nearest_submaps_and_other_groups_get_none():
    truth = {("a", 0): _pose(0, 0), ("b", 0): _pose(1, 0), ("b", 1): _pose(9, 0),
             ("c", 0): _pose(3, 3)}  # fmt: skip
    poses = dict(truth)
    poses[("b", 1)] = _pose(9, 0.3)  # off, but not the nearest pair to a
    frames = {r: truth[(r, 0)] for r in "abc"}
    out = pair_errors([["a", "b"], ["c"]], "abc", poses, truth, [], frames, frames)
    ab, ac, bc = out
    assert ab["matches"] == 0 and ab["t_error"] < 1e-9
    assert ac["t_error"] is None and bc["frame_t_error"] is None
    assert describe_pair(ac).endswith("not connected")
