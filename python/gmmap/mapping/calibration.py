"""The probability that a verified match is right, from what verification measured.

Verification refuses a match on each of its tests alone (`gmmap.mapping.mapper.Mapper`); a
`Calibration` weighs them together into one probability, fitted on matches whose truth was
known (`gmmap.eval.calibration`, benchmarks/calibration.py) and shipped in
``gmmap/data/place/calibration.json``. It reads a match's `FEATURES`:

- ``confidence``: C of its registration;
- ``ambiguity``: the best other basin's C over C (`Registration.alternative_confidence`);
- ``confusion``: its submaps' chance level over C (`gmmap.mapping.confusion`);
- ``turned``: its half-turned twin's C over C (`gmmap.mapping.place.turned`);
- ``conditioning``: log10 of `Registration.conditioning`, how firmly it pins its freest
  direction.

The model is logistic with each weight's sign fixed (`SIGNS`: more C and firmer pinning never
make a match less likely right, more ambiguity, confusion or twin never more), so the
probability is monotone in every feature. A match whose features lie outside the box the
fitting data spanned (`Calibration.low`, `Calibration.high`) is one the calibration never saw
the like of: `probability` says None, and a Mapper that asks for a probability refuses it.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.mapping.place import Match

FEATURES = ("confidence", "ambiguity", "confusion", "turned", "conditioning")
SIGNS = (1, -1, -1, -1, 1)
SHIPPED = Path(__file__).resolve().parents[1] / "data" / "place" / "calibration.json"
FLOOR = 1e-6  # conditioning below this reads as this (log10 −6): nothing pinned


def features(m: Match) -> np.ndarray:
    """The `FEATURES` of a judged match, in that order."""
    r = m.registration
    c = r.confidence
    ambiguity = r.alternative_confidence / c if c > 0 else 0.0
    return np.array([c, ambiguity, m.confusion, m.turned, math.log10(max(r.conditioning, FLOOR))])


@dataclass(frozen=True)
class Calibration:
    """A fitted model: ``weights`` on the features standardised by ``centre`` and ``scale``,
    ``bias``, and the box ``low``-``high`` of the features it was fitted on. ``source``
    says what it was fitted on."""

    weights: tuple[float, ...]
    bias: float
    centre: tuple[float, ...]
    scale: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    source: str = ""

    def __post_init__(self) -> None:
        n = len(FEATURES)
        fields = (self.weights, self.centre, self.scale, self.low, self.high)
        if any(len(f) != n for f in fields):
            raise InvalidInputError(f"a calibration needs {n} values per field, one per feature")
        if not all(math.isfinite(v) for f in fields for v in f) or not math.isfinite(self.bias):
            raise InvalidInputError("a calibration's values must be finite")
        if min(self.scale) <= 0 or np.any(np.subtract(self.high, self.low) < 0):
            raise InvalidInputError("a calibration needs scale > 0 and low <= high")
        if np.any(np.multiply(self.weights, SIGNS) < 0):
            raise InvalidInputError(f"a calibration's weights must have the signs {SIGNS}")

    def probability(self, x: np.ndarray) -> float | None:
        """P(right) of features ``x``; None outside the box it was fitted on."""
        x = np.asarray(x, dtype=float)
        if x.shape != (len(FEATURES),) or not np.all(np.isfinite(x)):
            raise InvalidInputError(f"features must be {len(FEATURES)} finite numbers")
        if np.any(x < self.low) or np.any(x > self.high):
            return None
        z = (x - self.centre) / self.scale
        return float(1.0 / (1.0 + math.exp(-(float(np.dot(self.weights, z)) + self.bias))))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(asdict(self), indent=1) + "\n")

    @staticmethod
    def load(path: str | Path | None = None) -> Calibration:
        """The calibration at ``path`` (None: the one shipped with gmmap), read once per
        path: every `Mapper` built (a fresh one per `Mapper.rejudged`) asks for it."""
        return _read(Path(path) if path is not None else SHIPPED)


@functools.lru_cache(maxsize=8)
def _read(path: Path) -> Calibration:
    try:
        raw = json.loads(path.read_text())
        return Calibration(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()})
    except (OSError, ValueError, TypeError) as err:
        raise InvalidInputError(f"cannot read the calibration {path}: {err}") from None
