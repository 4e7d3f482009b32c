"""The paper's learned place descriptor: PointNetVLAD (Uy and Lee, CVPR 2018) on 4,096 points
Monte-Carlo resampled from a GMM submap, run with numpy alone (no deep-learning framework).

The network: a shared per-point MLP (PointNet without its T-Nets) to ``D`` features, a NetVLAD
layer of ``K`` clusters (soft assignment, residuals summed per cluster, intra- and then L2
normalised), and a linear map to the output, L2 normalised: cosine distance compares two.

Before the network the cloud is made independent of the frame it came in, because two robots
see one place in anchor frames that differ by a yaw and a translation (`canonical`): centred
on its centroid, turned so that its major horizontal axis lies along x, and then taken
together with its copies turned by 90°, 180° and 270° (`c4`). The NetVLAD sum over that union
is the same for any of the four turns, which covers the sign of the major axis and an
exchange of two nearly equal axes. So the descriptor is invariant to any yaw and translation
of the same cloud, and to the order of its points; it is not invariant to roll or pitch
(anchors are levelled).

`forward` is written against an array module (numpy here; ``jax.numpy`` for training,
`gmmap.eval.train_place`), so training and inference run one definition. The weights ship
with the package (`WEIGHTS`), with the recipe, seeds and log of the run that made them in
``gmmap/data/place/``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.math.points import as_points

WEIGHTS = Path(__file__).resolve().parents[1] / "data" / "place" / "pointnetvlad.npz"
SCALE = 4.0  # metres per network unit: office-sized submaps span a few units


@dataclass(frozen=True)
class Architecture:
    """Layer sizes: the PointNet MLP's widths (the last is NetVLAD's feature size ``D``),
    NetVLAD's ``clusters`` (K) and the descriptor's ``output`` length."""

    widths: tuple[int, ...] = (64, 64, 128)
    clusters: int = 16
    output: int = 256

    def shapes(self) -> dict[str, tuple[int, ...]]:
        """Each parameter's shape, by name."""
        out: dict[str, tuple[int, ...]] = {}
        fan_in = 3
        for i, w in enumerate(self.widths):
            out[f"mlp{i}_w"], out[f"mlp{i}_b"] = (fan_in, w), (w,)
            fan_in = w
        out["assign_w"], out["assign_b"] = (fan_in, self.clusters), (self.clusters,)
        out["centres"] = (self.clusters, fan_in)
        out["out_w"] = (self.clusters * fan_in, self.output)
        return out


def init_params(arch: Architecture, seed: int = 0) -> dict[str, np.ndarray]:
    """He-initialised weights, zero biases, centres near the origin (float32)."""
    rng = np.random.default_rng(seed)
    params = {}
    for name, shape in arch.shapes().items():
        if name.endswith("_b"):
            params[name] = np.zeros(shape, np.float32)
        elif name == "centres":
            params[name] = rng.normal(0, 0.1, shape).astype(np.float32)
        else:
            params[name] = rng.normal(0, math.sqrt(2.0 / shape[0]), shape).astype(np.float32)
    return params


def canonical(points: np.ndarray) -> np.ndarray:
    """The cloud centred on its centroid, its major horizontal axis along x, in network
    units (float32)."""
    p = np.asarray(points, np.float64)
    p = p - p.mean(axis=0)
    _, vectors = np.linalg.eigh(np.cov(p[:, :2].T) + 1e-12 * np.eye(2))
    major = vectors[:, 1]
    c, s = major[0], major[1]
    turned = np.column_stack([c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1], p[:, 2]])
    return (turned / SCALE).astype(np.float32)


def c4(clouds: Any, xp: Any = np) -> Any:
    """(..., N, 3) clouds with their copies turned by 90°, 180° and 270° about z:
    (..., 4N, 3)."""
    x, y, z = clouds[..., 0], clouds[..., 1], clouds[..., 2]
    turns = [(x, y), (-y, x), (-x, -y), (y, -x)]
    return xp.concatenate([xp.stack([a, b, z], axis=-1) for a, b in turns], axis=-2)


def _normalise(v: Any, xp: Any, axis: int = -1) -> Any:
    return v / xp.sqrt(xp.sum(v * v, axis=axis, keepdims=True) + 1e-12)


def forward(params: dict[str, Any], clouds: Any, layers: int, xp: Any = np) -> Any:
    """Descriptors (B, output) of canonical clouds (B, N, 3), C4 copies already added;
    ``layers`` MLP layers; ``xp`` the array module (numpy or jax.numpy)."""
    h = clouds
    for i in range(layers):
        h = xp.maximum(h @ params[f"mlp{i}_w"] + params[f"mlp{i}_b"], 0.0)
    logits = h @ params["assign_w"] + params["assign_b"]
    logits = logits - xp.max(logits, axis=-1, keepdims=True)
    a = xp.exp(logits)
    a = a / xp.sum(a, axis=-1, keepdims=True)  # (B, N, K) soft assignment
    v = xp.einsum("bnk,bnd->bkd", a, h) - xp.sum(a, axis=1)[..., None] * params["centres"]
    v = _normalise(v, xp)  # intra-normalisation, per cluster
    v = _normalise(v.reshape(v.shape[0], -1), xp)
    return _normalise(v @ params["out_w"], xp)


def save(path: Path, params: dict[str, np.ndarray], arch: Architecture, meta: dict) -> None:
    """Weights and their provenance (``meta``: JSON-able) in one .npz."""
    info = {"architecture": {"widths": list(arch.widths), "clusters": arch.clusters,
                             "output": arch.output}, **meta}  # fmt: skip
    arrays = {k: np.asarray(v, np.float32) for k, v in params.items()}
    np.savez_compressed(path, meta=np.array(json.dumps(info)), **arrays)


@lru_cache(maxsize=4)
def load(path: str) -> tuple[dict[str, np.ndarray], Architecture, dict]:
    """Weights, architecture and provenance from `save`'s file; `FileFormatError` when it is
    not one."""
    try:
        with np.load(path, allow_pickle=False) as z:
            info = json.loads(str(z["meta"]))
            a = info["architecture"]
            arch = Architecture(tuple(a["widths"]), int(a["clusters"]), int(a["output"]))
            params = {k: z[k] for k in arch.shapes()}
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise FileFormatError(f"{path}: not PointNetVLAD weights ({err})") from err
    for name, shape in arch.shapes().items():
        if params[name].shape != shape or not np.isfinite(params[name]).all():
            raise FileFormatError(f"{path}: {name} is not a finite {shape} array")
    return params, arch, info


def reference_cloud(seed: int = 0) -> np.ndarray:
    """A fixed input (4,096 points in a 6 m box) whose output the weights' file records, so
    that a test can tell the shipped weights still give what they gave when trained."""
    return np.random.default_rng(seed).uniform([-3, -2, 0], [3, 2, 2.5], (4096, 3))


@dataclass(frozen=True)
class LearnedDescriptor:
    """PointNetVLAD as a place descriptor (`gmmap.mapping.place.Descriptor`): weights from
    ``weights`` (default: the trained ones shipped with gmmap)."""

    weights: str = str(WEIGHTS)

    def __post_init__(self) -> None:
        load(self.weights)  # a bad weights file fails here, not in a robot's matching thread

    @property
    def model(self) -> tuple[dict[str, np.ndarray], Architecture, dict]:
        return load(self.weights)

    @property
    def candidate_distance(self) -> float:
        """The cosine distance under which a candidate is kept, from the training run."""
        return float(self.model[2]["max_distance"])

    def describe_points(self, points: np.ndarray) -> np.ndarray:
        p = as_points(points, "points")
        if len(p) < 3:
            raise InvalidInputError(f"a descriptor needs at least 3 points, got {len(p)}")
        params, arch, _ = self.model
        cloud = c4(canonical(p))[None]
        return forward(params, cloud, len(arch.widths))[0].astype(np.float64)
