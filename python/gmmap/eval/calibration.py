"""Fitting and checking the probability that a verified match is right
(`gmmap.mapping.calibration`), from matches whose truth is known.

`labelled` merges robots' submaps with the defaults, the two tests the probability weighs
switched off (`PlaceOptions.min_conditioning`, ``min_probability``), and returns the features
of every match that passed verification up to refinement, each labelled right when its views
overlap at the truth and its transform is within 0.2 m and 3° of it (`gmmap.eval.place`).
`fit` is a logistic regression with the weights' signs fixed (scipy's L-BFGS-B), each case
weighted alike so that a case with many matches does not outvote the others. `check`
scores a calibration on other matches: the Brier score, the mean probability against the
share right in bins of probability, and how many it never saw the like of.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from scipy.optimize import minimize

from gmmap.config import Config
from gmmap.eval.merge import merge
from gmmap.eval.sessions import is_right
from gmmap.mapping.calibration import FEATURES, SIGNS, Calibration, features
from gmmap.mapping.submap import Submap

MARGIN = 0.05  # the box of features seen, widened by this share of its range on each side
PENALTY = 1.0  # L2 weight on the standardised weights: keeps a separable fit from certainty


def labelled(
    sessions: Mapping[str, Sequence[Submap]], config: Config | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(features (n, 5), right (n,)) of the matches described in the module docstring."""
    config = config or Config()
    place = replace(config.place, min_conditioning=0.0, min_probability=None)
    mapper, _ = merge(sessions, replace(config, place=place))
    held = {(s.robot, s.seq): s for subs in sessions.values() for s in subs}
    verified = [m for m in mapper.matches if m.accepted]
    X = np.reshape([features(m) for m in verified], (-1, len(FEATURES)))
    return X, np.array([is_right(m, held) for m in verified], dtype=bool)


def fit(cases: Sequence[tuple[np.ndarray, np.ndarray]], source: str = "") -> Calibration:
    """The calibration fitted on ``cases`` (each a `labelled` result), weighted alike."""
    cases = [(X, y) for X, y in cases if len(y)]
    X = np.vstack([X for X, _ in cases])
    y = np.concatenate([y for _, y in cases]).astype(float)
    if y.min() == y.max():
        raise ValueError("fitting a calibration needs both right and wrong matches")
    w = np.concatenate([np.full(len(c[1]), len(y) / (len(cases) * len(c[1]))) for c in cases])
    centre, scale = X.mean(axis=0), np.maximum(X.std(axis=0), 1e-9)
    Z = (X - centre) / scale

    def loss(theta: np.ndarray) -> tuple[float, np.ndarray]:
        z = Z @ theta[:-1] + theta[-1]
        p = 1.0 / (1.0 + np.exp(-z))
        value = np.sum(w * (np.logaddexp(0.0, z) - y * z)) + PENALTY * theta[:-1] @ theta[:-1]
        g = w * (p - y)
        return value, np.append(Z.T @ g + 2 * PENALTY * theta[:-1], g.sum())

    bounds = [(0.0, None) if s > 0 else (None, 0.0) for s in SIGNS] + [(None, None)]
    theta = minimize(loss, np.zeros(len(FEATURES) + 1), jac=True, bounds=bounds).x
    span = X.max(axis=0) - X.min(axis=0)
    return Calibration(
        weights=tuple(float(v) for v in theta[:-1]),
        bias=float(theta[-1]),
        centre=tuple(float(v) for v in centre),
        scale=tuple(float(v) for v in scale),
        low=tuple(float(v) for v in X.min(axis=0) - MARGIN * span),
        high=tuple(float(v) for v in X.max(axis=0) + MARGIN * span),
        source=source,
    )


def check(calibration: Calibration, X: np.ndarray, y: np.ndarray, bins: int = 5) -> dict:
    """How well ``calibration`` predicts the labels ``y`` of features ``X``."""
    p = [calibration.probability(x) for x in X]
    known = np.array([q is not None for q in p], dtype=bool)
    q = np.array([v if v is not None else np.nan for v in p])
    out: dict = {"matches": len(y), "right": int(y.sum()), "unseen": int((~known).sum())}
    if not known.any():
        return out
    qk, yk = q[known], y[known].astype(float)
    out["brier"] = float(np.mean((qk - yk) ** 2))
    out["brier_base_rate"] = float(np.mean((yk.mean() - yk) ** 2))
    edges = np.linspace(0.0, 1.0, bins + 1)
    out["reliability"] = [
        {"p": [float(lo), float(hi)], "n": int(inside.sum()),
         "mean_p": float(qk[inside].mean()), "right": float(yk[inside].mean())}
        for lo, hi in itertools.pairwise(edges)
        if (inside := (qk >= lo) & ((qk < hi) | (hi == 1.0))).any()
    ]  # fmt: skip
    return out
