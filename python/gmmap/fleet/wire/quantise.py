"""Quantisation geometry shared by the wire codec's encoder and decoder (`gmmap.fleet.wire.codec`):
Morton codes of grid cells, equal bins on [-1, 1], the octahedral map of a hemisphere, the
half diamond of a sign-free direction in a plane, and a rotation quantised to and rebuilt
from them.

IEEE-754 basic operations only (no libm): the decoder derives radices from these (the mean's
from the decoded rotation), so every decoder must get them bit for bit.
"""

from __future__ import annotations

import numpy as np

QMIN_EXPONENT = 13  # the finest mean step, 2^-13 m ≈ 0.12 mm; also the anchor's translation step

# --- Morton codes ----------------------------------------------------------------------------

_SPREAD = (
    (32, 0x1F00000000FFFF),
    (16, 0x1F0000FF0000FF),
    (8, 0x100F00F00F00F00F),
    (4, 0x10C30C30C30C30C3),
    (2, 0x1249249249249249),
)


def _spread(v: np.ndarray) -> np.ndarray:
    x = v.astype(np.uint64) & np.uint64(0x1FFFFF)
    for shift, mask in _SPREAD:
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def _compact(x: np.ndarray) -> np.ndarray:
    x = x & np.uint64(0x1249249249249249)
    x = (x ^ (x >> np.uint64(2))) & np.uint64(0x10C30C30C30C30C3)
    x = (x ^ (x >> np.uint64(4))) & np.uint64(0x100F00F00F00F00F)
    x = (x ^ (x >> np.uint64(8))) & np.uint64(0x1F0000FF0000FF)
    x = (x ^ (x >> np.uint64(16))) & np.uint64(0x1F00000000FFFF)
    x = (x ^ (x >> np.uint64(32))) & np.uint64(0x1FFFFF)
    return x.astype(np.int64)


def _morton(cells: np.ndarray) -> np.ndarray:
    c = cells.astype(np.uint64)
    m = _spread(c[:, 0]) | (_spread(c[:, 1]) << np.uint64(1)) | (_spread(c[:, 2]) << np.uint64(2))
    return m.astype(np.int64)


def _unmorton(m: np.ndarray) -> np.ndarray:
    return _compact(m.astype(np.uint64)[:, None] >> np.arange(3, dtype=np.uint64))


# --- geometry (IEEE basic operations only) ---------------------------------------------------


def _pexp(x: np.ndarray) -> np.ndarray:
    """exp(x) as (1 + x/2^16)^(2^16) by 16 squarings: within 1 % for |x| ≤ 14, and, unlike libm's
    exp, the same bits on every platform. Used only where a decoder derives a radix."""
    y = 1.0 + x * (1.0 / 65536.0)
    for _ in range(16):
        np.multiply(y, y, out=y)
    return y


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _normalised(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(_dot(v, v))[:, None]


def _bin(t: np.ndarray, radix: np.ndarray) -> np.ndarray:
    """The bin of t ∈ [-1, 1] among ``radix`` equal bins."""
    return np.clip(np.floor((t + 1.0) * 0.5 * radix), 0, radix - 1).astype(np.int64)


def _bin_centre(j: np.ndarray, radix: np.ndarray) -> np.ndarray:
    return (2.0 * j + 1.0) / radix - 1.0


def _octahedral(normal: np.ndarray) -> np.ndarray:
    """A unit vector (sign free: the upper hemisphere) as (u, v) ∈ [-1, 1]²."""
    n = np.where(normal[:, 2:3] < 0, -normal, normal)
    p = n[:, :2] / (np.abs(n[:, 0]) + np.abs(n[:, 1]) + n[:, 2])[:, None]
    return np.stack([p[:, 0] + p[:, 1], p[:, 0] - p[:, 1]], axis=1)


def _from_octahedral(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    n = np.empty((len(u), 3))
    n[:, 0] = (u + v) * 0.5
    n[:, 1] = (u - v) * 0.5
    n[:, 2] = 1.0 - np.abs(n[:, 0]) - np.abs(n[:, 1])
    return _normalised(n)


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A right-handed basis (t₁, t₂) of the plane normal to n: t₁ ∝ n × x̂, or n × ŷ when n is
    within 53° of x̂."""
    with_x = np.abs(n[:, 0]) < 0.6
    t1 = np.zeros((len(n), 3))
    t1[:, 0] = np.where(with_x, 0.0, -n[:, 2])  # n × x̂ = (0, n_z, −n_y)
    t1[:, 1] = np.where(with_x, n[:, 2], 0.0)  # n × ŷ = (−n_z, 0, n_x)
    t1[:, 2] = np.where(with_x, -n[:, 1], n[:, 0])
    t1 = _normalised(t1)
    return t1, _cross(n, t1)


def _half_circle(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """A direction (c, s) in the plane, sign free, as t ∈ [-1, 1] on the upper half diamond."""
    flip = (s < 0) | ((s == 0) & (c < 0))
    c, s = np.where(flip, -c, c), np.where(flip, -s, s)
    den = np.abs(c) + s
    return np.where(den > 0, c / np.where(den > 0, den, 1.0), 0.0)


def _rotation(normal: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The proper rotation [n, e₂, e₃] (columns, ascending σ) from the normal and the largest
    axis' half-diamond coordinate."""
    t1, t2 = _tangents(normal)
    c, s = t, 1.0 - np.abs(t)
    norm = np.sqrt(c * c + s * s)
    e3 = (c / norm)[:, None] * t1 + (s / norm)[:, None] * t2
    R = np.empty((len(t), 3, 3))
    R[:, :, 0], R[:, :, 1], R[:, :, 2] = normal, _cross(e3, normal), e3
    return R


def _quantise_rotation(V: np.ndarray, radix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bins of the normal's octahedral (u, v) and of the largest axis' half-diamond coordinate
    about the decoded normal, and the decoded rotation."""
    uv = _octahedral(V[:, :, 0])
    j = np.empty(radix.shape, dtype=np.int64)
    j[:, 0], j[:, 1] = _bin(uv[:, 0], radix[:, 0]), _bin(uv[:, 1], radix[:, 1])
    c = _bin_centre(j[:, :2], radix[:, :2])
    normal = _from_octahedral(c[:, 0], c[:, 1])
    t1, t2 = _tangents(normal)
    j[:, 2] = _bin(_half_circle(_dot(V[:, :, 2], t1), _dot(V[:, :, 2], t2)), radix[:, 2])
    return j, _rotation(normal, _bin_centre(j[:, 2], radix[:, 2]))
