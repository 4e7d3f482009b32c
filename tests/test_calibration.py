"""The probability that a verified match is right (`gmmap.mapping.calibration`)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_verify import hall, submap

from conftest import yaw_pose
from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.calibration import check, fit
from gmmap.mapping.calibration import FEATURES, SIGNS, Calibration, features
from gmmap.mapping.mapper import Mapper
from gmmap.options import PlaceOptions


def synthetic(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Features spread as verified matches' are, each right with a known logistic chance."""
    rng = np.random.default_rng(seed)
    X = np.column_stack([
        rng.uniform(0.55, 1.0, n),  # confidence
        rng.uniform(0.0, 0.9, n),  # ambiguity
        rng.uniform(0.0, 0.9, n),  # confusion
        rng.uniform(0.1, 0.9, n),  # turned
        rng.uniform(-5.0, -0.5, n),  # log10 conditioning
    ])  # fmt: skip
    z = 12 * (X[:, 0] - 0.8) - 3 * X[:, 2] + 2 * (X[:, 4] + 2.5)
    return X, rng.random(n) < 1 / (1 + np.exp(-z))


def grid_along(calibration: Calibration, i: int, base: np.ndarray) -> list[float]:
    values = np.linspace(calibration.low[i], calibration.high[i], 25)
    return [calibration.probability(np.where(np.arange(5) == i, v, base)) for v in values]


@pytest.mark.parametrize("which", ["fitted", "shipped"])
def test_the_probability_is_monotone_in_every_feature_it_was_fitted_on(which):
    calibration = fit([synthetic(800, 0)]) if which == "fitted" else Calibration.load()
    rng = np.random.default_rng(1)
    for _ in range(20):
        base = rng.uniform(calibration.low, calibration.high)
        for i, sign in enumerate(SIGNS):
            p = np.array(grid_along(calibration, i, base))
            assert np.all(sign * np.diff(p) >= -1e-12), (FEATURES[i], p)


def test_a_fit_is_calibrated_on_matches_it_never_saw():
    """Fitted on one draw, it predicts another's share of right matches within a few
    points per bin, and scores better than the base rate."""
    calibration = fit([synthetic(3000, 0)])
    report = check(calibration, *synthetic(3000, 1))
    assert report["unseen"] == 0
    assert report["brier"] < 0.8 * report["brier_base_rate"]
    for b in report["reliability"]:
        if b["n"] >= 100:
            assert abs(b["mean_p"] - b["right"]) < 0.08, b


def test_a_match_unlike_anything_fitted_on_is_refused(tmp_path):
    """A calibration fitted on corridor-like matches (confidence under 0.9) has never seen a
    match as confident as two robots' views of one hall: it gives no probability, and with
    ``min_probability`` set the Mapper refuses the match that it otherwise accepts."""
    X, y = synthetic(800, 0)
    keep = X[:, 0] < 0.9
    path = tmp_path / "calibration.json"
    fit([(X[keep], y[keep])], "corridors only").save(path)
    rng = np.random.default_rng(3)
    b_frame = yaw_pose(30, (1.0, 2.0, 0.0))
    held = [
        submap("a", 0, np.eye(4), hall(rng)),
        submap("b", 0, np.linalg.inv(b_frame), hall(rng)),
    ]
    options = PlaceOptions(max_distance=2.0, skip_recent=0, calibration=str(path))
    (reported,) = Mapper(Config(place=options)).add(held)
    assert reported.accepted and reported.registration.confidence > 0.9
    assert Calibration.load(path).probability(features(reported)) is None
    assert reported.probability is None
    (refused,) = Mapper(Config(place=replace(options, min_probability=0.5))).add(held)
    assert not refused.accepted


def test_a_calibration_with_wrong_signs_or_a_broken_file_is_refused(tmp_path):
    good = fit([synthetic(400, 0)])
    with pytest.raises(InvalidInputError, match="signs"):
        replace(good, weights=(-1.0, 0.0, 0.0, 0.0, 1.0))
    with pytest.raises(InvalidInputError, match="per field"):
        replace(good, low=(0.0,))
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({"weights": [1, 2]}))
    with pytest.raises(InvalidInputError, match="cannot read"):
        Calibration.load(broken)
    with pytest.raises(InvalidInputError, match="cannot read"):
        Calibration.load(tmp_path / "absent.json")
    with pytest.raises(InvalidInputError):
        good.probability(np.array([0.5, np.nan, 0, 0, 0]))
    with pytest.raises(InvalidInputError):
        PlaceOptions(min_probability=1.5)
