"""The learned place descriptor's data: place sets (`gmmap.eval.place`) turned into clouds.

Each submap gives two clouds of `CLOUD_POINTS` points: its GMM Monte-Carlo resampled (what a
robot has of another robot's submap) and its raw buffered points, randomly subsampled (what
the paper's PointNetVLAD was trained on). Positives follow `gmmap.eval.place.positives`, the
rule of ``gmmap eval place``. A part is one place set: a simulated world, sensor and seed, or
a real recording split into halves; parts are cached as .npz files.

The recipe (`RECIPE`) fixes which parts train and which are held out: procedural offices
(`gmmap.io.sim.procedural`) with LiDAR and depth for training; other procedural offices, the
demo's office and TUM fr1_xyz are never used in training.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmmap.eval.place import PlaceSet, sim_place_set, split_place_set, world_points
from gmmap.mapping.place import RESAMPLE_POINTS, resample

CLOUD_POINTS = RESAMPLE_POINTS  # as the place database resamples a submap


@dataclass(frozen=True)
class Part:
    """One place set: ``world`` a simulator world with ``robots``, ``sensor`` and ``seed``, or
    ``recording`` a folder under the shared data, split into two halves."""

    world: str = ""
    robots: int = 4
    sensor: str = "lidar"
    seed: int = 0
    recording: str = ""

    @property
    def name(self) -> str:
        if self.recording:
            return f"{self.recording}_halves"
        return f"{self.world.replace(':', '-')}_{self.sensor}_{self.robots}r_seed{self.seed}"


def _offices(seeds, sensor: str, robots: int = 4) -> list[Part]:
    return [Part(f"random-office:{s}", robots, sensor, s) for s in seeds]


RECIPE = {
    "train": [
        *_offices(range(0, 24), "lidar"),
        *_offices(range(0, 12), "depth"),
        Part(recording="tum_fr3_long_office_household"),
        Part(recording="tum_fr3_cabinet_keyframes"),
    ],
    "held_out": [
        *_offices(range(1000, 1004), "lidar"),
        *_offices(range(1000, 1004), "depth"),
        Part("office", 5, "lidar", 7),
        Part("office", 5, "depth", 7),
        Part(recording="tum_fr1_xyz"),
    ],
}


@dataclass
class Clouds:
    """A part's clouds: ``gmm`` and ``raw`` (n, CLOUD_POINTS, 3) float32 in each submap's
    anchor frame, ``positives`` (n, n) and the submaps' true centres (n, 3), which tell far
    (negative) pairs from near ones that the positives rule leaves out (one robot's own)."""

    gmm: np.ndarray
    raw: np.ndarray
    positives: np.ndarray
    centres: np.ndarray
    name: str = ""


def clouds_of(place_set: PlaceSet, seed: int = 0, name: str = "") -> Clouds:
    rng = np.random.default_rng(seed)
    gmm, raw = [], []
    for i, s in enumerate(place_set.submaps):
        gmm.append(resample(s.gmm, CLOUD_POINTS, seed=seed * 100_003 + i))
        pick = rng.choice(len(s.points), CLOUD_POINTS, replace=len(s.points) < CLOUD_POINTS)
        raw.append(s.points[pick])
    centres = np.array([world_points(s).mean(axis=0) for s in place_set.submaps])
    return Clouds(
        np.asarray(gmm, np.float32), np.asarray(raw, np.float32), place_set.positives, centres, name
    )


def build(part: Part, data: Path) -> PlaceSet | None:
    """The place set of ``part``; None for a recording absent from ``data``."""
    if part.recording:
        from gmmap.io import datasets

        folder = data / part.recording
        if not folder.exists():
            return None
        return split_place_set(datasets.open(folder))
    return sim_place_set(part.world, part.robots, part.seed, sensor=part.sensor)


def load(part: Part, cache: Path, data: Path) -> Clouds | None:
    """A part's clouds from ``cache``, built (and cached) when missing."""
    path = cache / f"{part.name}.npz"
    if path.exists():
        z = np.load(path)
        return Clouds(z["gmm"], z["raw"], z["positives"], z["centres"], part.name)
    place_set = build(part, data)
    if place_set is None:
        return None
    c = clouds_of(place_set, part.seed, part.name)
    cache.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, gmm=c.gmm, raw=c.raw, positives=c.positives, centres=c.centres)
    os.replace(tmp, path)
    return c


def load_all(
    split: str,
    cache: Path,
    data: Path,
    progress: Callable[[str], None] | None = None,
    jobs: int = 1,
) -> list[Clouds]:
    """Every part of ``split`` ("train" or "held_out") that can be built here; missing parts
    are built by ``jobs`` processes at once."""
    parts = RECIPE[split]
    missing = [p for p in parts if not (cache / f"{p.name}.npz").exists()]
    if progress and missing:
        progress(f"{split}: building {len(missing)} of {len(parts)} parts ({jobs} at once)")
    if jobs > 1 and len(missing) > 1:
        with ProcessPoolExecutor(jobs) as pool:
            list(pool.map(load, missing, [cache] * len(missing), [data] * len(missing)))
    out = []
    for part in parts:
        if progress:
            progress(f"{split}: {part.name}")
        c = load(part, cache, data)
        if c is not None:
            out.append(c)
    return out
