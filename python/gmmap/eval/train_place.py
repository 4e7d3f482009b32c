"""Training the learned place descriptor (`gmmap.mapping.learned`) with JAX on the CPU.

Each step draws ``queries`` tuples: a query, a positive (the same place seen by another robot,
by `gmmap.eval.place.positives`) and ``negatives`` submaps whose true centres lie more than
`NEGATIVE_M` apart (half from the query's world, half from others). The loss is InfoNCE over
each tuple's cosine similarities at ``temperature``: −log of the positive's softmax share.
PointNetVLAD's lazy triplet (a margin over the hardest negative) collapsed here: with all
descriptors alike at the start, every triplet sat at the margin and the gradients vanished. Each
cloud is a random ``points``-point subset of the GMM-resampled or of the raw cloud (even odds),
jittered; the network sees it canonical, as at inference. Adam on every parameter, its rate
falling along a cosine to a tenth by the end (of ``steps`` or of ``minutes``).

JAX is a development dependency (``pip install 'gmmap[dev]'``): inference needs numpy alone.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from gmmap.eval.placedata import Clouds
from gmmap.mapping.learned import Architecture, c4, canonical, forward, init_params

NEGATIVE_M = 10.0  # true centres this far apart are different places


@dataclass(frozen=True)
class TrainOptions:
    arch: Architecture = field(default_factory=Architecture)
    queries: int = 6  # per step
    negatives: int = 6  # per query
    points: int = 1024  # per cloud while training (inference takes 4,096)
    temperature: float = 0.1
    lr: float = 1e-3  # falls to a tenth over the run (cosine)
    jitter_m: float = 0.01
    gmm_share: float = 0.5  # share of clouds taken from the resampled GMM, the rest raw
    seed: int = 0


@dataclass
class Sampler:
    """Draws training tuples (query, positive, negatives) from parts' clouds."""

    parts: Sequence[Clouds]
    options: TrainOptions
    rng: np.random.Generator = field(init=False)

    def __post_init__(self) -> None:
        self.rng = np.random.default_rng(self.options.seed)
        self.queries = [(p, i) for p, c in enumerate(self.parts)
                        for i in np.flatnonzero(c.positives.any(axis=1))]  # fmt: skip
        if not self.queries:
            raise ValueError("no part has a positive pair to train on")

    def cloud(self, part: int, i: int) -> np.ndarray:
        c, o = self.parts[part], self.options
        source = c.gmm if self.rng.random() < o.gmm_share else c.raw
        pick = self.rng.choice(source.shape[1], o.points, replace=False)
        pts = source[i, pick] + self.rng.normal(0, o.jitter_m, (o.points, 3))
        return canonical(pts)

    def negative(self, part: int, i: int) -> tuple[int, int]:
        c = self.parts[part]
        far = np.flatnonzero(np.linalg.norm(c.centres - c.centres[i], axis=1) > NEGATIVE_M)
        if len(far) and (len(self.parts) == 1 or self.rng.random() < 0.5):
            return part, int(self.rng.choice(far))
        other = int(self.rng.integers(len(self.parts)))
        while other == part and len(self.parts) > 1:
            other = int(self.rng.integers(len(self.parts)))
        return other, int(self.rng.integers(len(self.parts[other].gmm)))

    def batch(self) -> np.ndarray:
        """(queries · (2 + negatives), points, 3): per query its cloud, a positive's and the
        negatives', in that order."""
        o = self.options
        clouds = []
        for k in self.rng.choice(len(self.queries), o.queries, replace=False):
            part, i = self.queries[k]
            j = int(self.rng.choice(np.flatnonzero(self.parts[part].positives[i])))
            clouds += [self.cloud(part, i), self.cloud(part, j)]
            clouds += [self.cloud(*self.negative(part, i)) for _ in range(o.negatives)]
        return np.stack(clouds)


def _loss_fn(options: TrainOptions):
    import jax
    import jax.numpy as jnp

    layers = len(options.arch.widths)
    per = 2 + options.negatives

    def loss(params, clouds):
        d = forward(params, c4(clouds, jnp), layers, jnp).reshape(options.queries, per, -1)
        # cosine similarities of the query to its positive (column 0) and negatives
        sim = jnp.einsum("qd,qkd->qk", d[:, 0], d[:, 1:]) / options.temperature
        return jnp.mean(jax.nn.logsumexp(sim, axis=1) - sim[:, 0])

    return loss


def train(
    parts: Sequence[Clouds],
    options: TrainOptions,
    steps: int,
    minutes: float | None = None,
    progress: Callable[[str], None] | None = None,
    batches: Callable[[], np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], list[dict]]:
    """Trained parameters and the log (one entry per step: step, loss, seconds). Stops after
    ``steps`` or ``minutes``. ``batches`` replaces the sampler (a test's fixed batch)."""
    import jax
    import jax.numpy as jnp

    sample = batches or Sampler(parts, options).batch
    params = {k: jnp.asarray(v) for k, v in init_params(options.arch, options.seed).items()}
    m = {k: jnp.zeros_like(v) for k, v in params.items()}
    v = {k: jnp.zeros_like(x) for k, x in params.items()}
    b1, b2 = 0.9, 0.999

    @jax.jit
    def step(params, m, v, t, rate, clouds):
        loss, grads = jax.value_and_grad(_loss_fn(options))(params, clouds)
        m = {k: b1 * m[k] + (1 - b1) * g for k, g in grads.items()}
        v = {k: b2 * v[k] + (1 - b2) * g * g for k, g in grads.items()}
        lr = rate * jnp.sqrt(1 - b2**t) / (1 - b1**t)
        params = {k: p - lr * m[k] / (jnp.sqrt(v[k]) + 1e-8) for k, p in params.items()}
        return params, m, v, loss

    log: list[dict] = []
    start = time.monotonic()
    elapsed = 0.0
    for t in range(1, steps + 1):
        done = max(t / steps, elapsed / (60 * minutes) if minutes else 0.0)
        rate = options.lr * (0.1 + 0.45 * (1 + np.cos(np.pi * min(done, 1.0))))
        params, m, v, loss = step(params, m, v, float(t), float(rate), jnp.asarray(sample()))
        elapsed = time.monotonic() - start
        log.append({"step": t, "loss": float(loss), "seconds": round(elapsed, 2)})
        if progress and (t % 50 == 0 or t == 1):
            recent = np.mean([e["loss"] for e in log[-50:]])
            progress(f"step {t}: loss {recent:.4f} ({elapsed:.0f} s)")
        if minutes is not None and elapsed > 60 * minutes:
            break
    return {k: np.asarray(p, np.float32) for k, p in params.items()}, log
