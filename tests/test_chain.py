"""A narrow view is registered as a chain of its robot's submaps; a wide one alone."""

import math

import numpy as np

from gmmap.config import Config
from gmmap.eval.merge import merge
from gmmap.io.sim import simulate_options
from gmmap.mapping.frontier import Horizon
from gmmap.mapping.submap import Submap, build_submaps, chain_of
from gmmap.math.gmm import Gmm
from gmmap.options import PlaceOptions, SimOptions

BINS = 72


def turning(seen_bins: int, n: int = 6, horizons: bool = True) -> dict:
    """A robot turning a quarter per submap in place, each submap seeing ``seen_bins`` of the
    directions straight ahead."""
    ranges = np.full(BINS, np.nan)
    ranges[:seen_bins] = 2.0
    gmm = Gmm(np.ones(1), np.zeros((1, 3)), np.eye(3)[None])
    held = {}
    for seq in range(n):
        anchor = np.eye(4)
        c, s = math.cos(seq * math.pi / 2), math.sin(seq * math.pi / 2)
        anchor[:2, :2] = [[c, -s], [s, c]]
        views = [Horizon(np.zeros(2), ranges.copy())] if horizons else None
        held[("a", seq)] = Submap("a", seq, anchor, np.zeros(1), 100, gmm, horizons=views)
    return held


def test_a_narrow_view_grows_a_chain_until_it_sees_round():
    held = turning(seen_bins=18)  # a quarter of the directions each
    chain = chain_of(("a", 2), held, PlaceOptions(chain=5, chain_view=0.95))
    # The quarters: its own, then ±1 (three), then ±2 adds the fourth.
    assert [s.seq for s in chain] == [0, 1, 2, 3, 4]
    assert [s.seq for s in chain_of(("a", 2), held, PlaceOptions(chain=1))] == [1, 2, 3]
    assert [s.seq for s in chain_of(("a", 2), held, PlaceOptions(chain=0))] == [2]


def test_a_wide_view_or_an_unknown_one_stays_alone():
    assert [s.seq for s in chain_of(("a", 2), turning(seen_bins=BINS), PlaceOptions())] == [2]
    assert [s.seq for s in chain_of(("a", 2), turning(18, horizons=False), PlaceOptions())] == [2]


def test_depth_cameras_robots_join_in_the_office():
    """The simulated office, three robots with the 60° depth camera, seed 0 (the sensor
    matrix's first): robots 0 and 1 join where they met, and nothing joins wrongly."""
    config = Config()
    run = simulate_options(SimOptions(robots=3, seed=0, sensor="depth"))
    sessions = {r.name: list(build_submaps(r, r.name, config.build, config.select)) for r in run}
    _, report = merge(sessions, config)
    joined = [p for p in report["pairs"] if p["frame_t_error"] is not None]
    assert {"robot_0", "robot_1"} <= set(max(report["groups"], key=len))
    assert joined and all(p["frame_t_error"] < 0.5 and p["frame_r_error_deg"] < 5 for p in joined)
