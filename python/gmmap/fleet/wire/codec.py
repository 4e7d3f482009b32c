"""The wire codec: a `Gmm` or a `Submap` in under a kilobyte, and back.

``encode(x)`` returns bytes, ``decode(data)`` what was encoded (a `Gmm`, or a `Submap` whose
``points`` and ``gt_anchor`` are None and ``stats`` empty: those never leave the robot), or raises
`DecodeError`. The byte layout is specified in ``docs/wire-format.md``; in short:

- an envelope: magic ``GMMW``, version, kind (mixture or submap), compression (none or zstd,
  whichever is smaller);
- for a submap: robot name, sequence number, point count, stamps (the first as float64, the others
  as float32 offsets from it), the anchor (a rigid one as a quantised quaternion and
  translation, 13 to 19 bytes; any other entry by entry, exactly);
- the mixture, quantised so that each of the K components' ten parameters adds the same
  expected KL divergence D/K to the mixture (about 10·D nats in all, D = ``distortion``), and
  entropy coded:

  - weight: n = round(√(wK / 6D)) ≥ 1; the decoded weights are n², normalised. The Fisher
    information of each parameter of a component is proportional to its weight, so n also sets
    every other step of that component: a heavy component is sent finely, a light one coarsely;
  - standard deviations: log σ₁ ≤ log σ₂ ≤ log σ₃ in steps of √2 / n, the smallest from a
    per-mixture floor, each other from the previous one (so the gaps are small non-negative
    integers, Rice coded);
  - rotation: the normal (smallest axis) on the octahedral map of a hemisphere, the largest axis
    as an angle about it, both in steps that shrink with the anisotropy (a sphere sends no
    rotation at all, a thin disc its normal to a fraction of a degree);
  - mean: a 6.25 cm grid cell (sorted by Morton code, gaps Rice coded: sorting removes the
    log₂ K! bits of component order) plus an offset along each decoded axis in steps of
    2σᵢ / n (at least ``qmin``, 0.12 mm): a component's mean is known far better across its
    surface than along it, and its precision matters in that proportion.

  The radices (bins per quantised coordinate) follow from already decoded integers through
  IEEE-754 basic operations only (no libm), so every decoder derives them bit for bit.

Decoded components come in the order of their grid cells' Morton codes (not the encoder's
order). At the default D = 1e-3 a 100-component TUM submap takes about 870 bytes, against
4,000 as float32 (see benchmarks/codec.py for the figures and the registration accuracy).

The decoder checks every length, count and range before it allocates or loops (at most
65,535 components and stamps, 2 MiB of body, zstd frames with a declared size within that), so
corrupt or hostile input raises `DecodeError` and nothing else.

Why Python and not the Rust core: the parser faces untrusted bytes, and in numpy every index is
bounds-checked (an error, never an out-of-bounds read), while a message is ~1 kB with ~100
components, so the vectorised numpy code takes well under a millisecond; a native parser would
add unsafe-by-mistake surface for no measurable gain.
"""

from __future__ import annotations

import math
import struct
from typing import TYPE_CHECKING

import numpy as np
import zstandard

from gmmap.errors import DecodeError, InvalidGmmError, InvalidInputError
from gmmap.fleet.wire.anchor import read_anchor, read_anchor_entries, write_anchor
from gmmap.fleet.wire.bitstream import (
    _BitReader,
    _BitWriter,
    _Reader,
    _rice_k,
    _rice_read,
    _rice_write,
    _tb_read,
    _tb_write,
    _Writer,
)
from gmmap.fleet.wire.quantise import (
    QMIN_EXPONENT,
    _bin,
    _bin_centre,
    _from_octahedral,
    _morton,
    _pexp,
    _quantise_rotation,
    _rotation,
    _unmorton,
)
from gmmap.mapping.frontier import Horizon, code_ranges, range_codes
from gmmap.math.gmm import Gmm

if TYPE_CHECKING:
    from gmmap.mapping.submap import Submap

MAGIC = b"GMMW"
VERSION = 3
# Version 1 differs from 2 only in the anchor (its entry codes, without a form byte); version 2
# from 3 in the free-space block, which it lacks.
READABLE = (1, 2, 3)
KIND_GMM, KIND_SUBMAP = 1, 2
COMPRESSION_NONE, COMPRESSION_ZSTD = 0, 1
DEFAULT_DISTORTION = 1e-3  # expected KL divergence (nats) per parameter, over all components

MAX_BODY = 1 << 21  # bytes of (decompressed) body: bounds every allocation of the decoder
MAX_MESSAGE = MAX_BODY + 64
MAX_COMPONENTS = 65535
MAX_STAMPS = 65535
MAX_ROBOT_BYTES = 255
MAX_HORIZONS = 1024  # viewpoints per submap
HORIZON_BINS = (8, 720)  # directions per viewpoint, least and most
MAX_HORIZON_CM = 32767  # |coordinate| of a viewpoint, and |height| of the band, in cm
MAX_WEIGHT_INDEX = 1 << 24  # n; with n ≤ 2^24 every step below stays representable
MAX_LOG_STD = 80.0  # |log σ| (σ in metres): e^80 ≈ 5e34 is far outside any map
MAX_GAP = 1 << 40  # log-std gaps, in steps
MAX_RICE_K = 56  # remainders fit the decoder's 64-bit windows at any bit offset
# Largest value of each Rice stream: cell-code gap, weight index − 1, three log-std gaps.
_RICE_LIMITS = np.array([(1 << 60) - 1, MAX_WEIGHT_INDEX - 1, MAX_GAP, MAX_GAP, MAX_GAP])
RADIX_CAP = 1 << 20  # bins per quantised coordinate
GRID_BITS = 20  # cells per axis < 2^20, so Morton codes < 2^60
MAX_ORIGIN = 1 << 50
CELL_EXPONENT = -4  # default cell 2^-4 m = 6.25 cm
CELL_EXPONENT_RANGE = (-30, 60)
MAX_QMIN_EXPONENT = 60
LOG_FLOOR_SCALE = 64  # the log-std floor is sent in 1/64 nat
MAX_COORD = 1e12  # metres; means beyond are rejected by the encoder

_SQRT2 = math.sqrt(2.0)
_ZSTD_LEVEL = 19


# --- public API ------------------------------------------------------------------------------


def encode(x: Gmm | Submap, *, distortion: float = DEFAULT_DISTORTION) -> bytes:
    """The wire bytes of a mixture or a submap (see the module docstring).

    ``distortion`` D: each of the ten quantised parameters of each of the K components adds an
    expected KL divergence of D/K nats to the mixture (so about 10·D in all, whatever K);
    smaller sends more bytes.
    """
    try:
        distortion = float(distortion)
    except (TypeError, ValueError):
        distortion = math.nan
    if not 1e-12 <= distortion <= 1.0:
        raise InvalidInputError(f"distortion must be in [1e-12, 1], got {distortion!r}")
    from gmmap.mapping.submap import Submap  # lazily: it pulls in the dataset loaders

    if isinstance(x, Submap):
        kind, body = KIND_SUBMAP, _submap_fields(x) + _encode_gmm(x.gmm, distortion)
    elif isinstance(x, Gmm):
        kind, body = KIND_GMM, _encode_gmm(x, distortion)
    else:
        raise InvalidInputError(f"encode takes a Gmm or a Submap, got {type(x).__name__}")
    if len(body) > MAX_BODY:
        raise InvalidInputError(f"{len(body)} bytes exceed the wire format's {MAX_BODY}")
    compression = COMPRESSION_NONE
    packed = _zstd_compress(body)
    if len(packed) < len(body):
        compression, body = COMPRESSION_ZSTD, packed
    return MAGIC + bytes([VERSION, kind, compression]) + body


def decode(data: bytes | bytearray | memoryview) -> Gmm | Submap:
    """What ``encode`` encoded; `DecodeError` for anything that is not a valid message."""
    try:
        view = memoryview(data).cast("B")
    except TypeError as exc:
        raise DecodeError(f"expected bytes, got {type(data).__name__}") from exc
    if view.nbytes > MAX_MESSAGE:
        raise DecodeError(f"message of {view.nbytes} bytes exceeds {MAX_MESSAGE}")
    try:
        with np.errstate(all="ignore"):
            return _decode(bytes(view))
    except DecodeError:
        raise
    except (ValueError, IndexError, OverflowError, ArithmeticError, struct.error) as exc:
        # Every check below should fire first; this keeps the contract if one is missed.
        raise DecodeError(f"malformed message: {exc}") from exc
    except zstandard.ZstdError as exc:
        raise DecodeError(f"bad zstd body: {exc}") from exc


# --- envelope --------------------------------------------------------------------------------


def _decode(data: bytes) -> Gmm | Submap:
    if len(data) < len(MAGIC) + 3:
        raise DecodeError(f"message of {len(data)} bytes is too short")
    if data[:4] != MAGIC:
        raise DecodeError("not a gmmap wire message (bad magic)")
    version, kind, compression = data[4], data[5], data[6]
    if version not in READABLE:
        raise DecodeError(f"unsupported wire version {version} (this decoder reads {READABLE})")
    if kind not in (KIND_GMM, KIND_SUBMAP):
        raise DecodeError(f"unknown message kind {kind}")
    if compression == COMPRESSION_ZSTD:
        body = _zstd_decompress(data[7:])
    elif compression == COMPRESSION_NONE:
        body = data[7:]
    else:
        raise DecodeError(f"unknown compression {compression}")
    r = _Reader(body)
    if kind == KIND_GMM:
        return _decode_gmm(r)
    from gmmap.mapping.submap import Submap

    fields = _read_submap_fields(r, version)
    return Submap(**fields, gmm=_decode_gmm(r), points=None, gt_anchor=None, stats={})


def _zstd_compress(body: bytes) -> bytes:
    cctx = zstandard.ZstdCompressor(
        level=_ZSTD_LEVEL, write_content_size=True, write_checksum=False, write_dict_id=False
    )
    return cctx.compress(body)


def _zstd_decompress(frame: bytes) -> bytes:
    # The frame must declare its size, within MAX_BODY: zstd trusts a declared size over
    # max_output_size, so a bomb is refused before any allocation.
    params = zstandard.get_frame_parameters(frame)
    size = params.content_size
    if size == zstandard.CONTENTSIZE_UNKNOWN or size > MAX_BODY:
        raise DecodeError("zstd body without a declared size within the limit")
    if params.window_size > MAX_BODY or params.dict_id != 0:
        raise DecodeError("zstd body needs a window or dictionary this decoder refuses")
    dctx = zstandard.ZstdDecompressor(max_window_size=MAX_BODY)
    body = dctx.decompress(frame, max_output_size=MAX_BODY, allow_extra_data=False)
    if len(body) != size:
        raise DecodeError("zstd body shorter than declared")
    return body


# --- submap fields ---------------------------------------------------------------------------


def _submap_fields(s: Submap) -> bytes:
    w = _Writer()
    robot = str(s.robot).encode("utf-8")
    if len(robot) > MAX_ROBOT_BYTES:
        raise InvalidInputError(f"robot name longer than {MAX_ROBOT_BYTES} UTF-8 bytes")
    w.uvarint(len(robot))
    w.raw(robot)
    seq, n_points = int(s.seq), int(s.n_points)
    if not (-(1 << 62) <= seq < 1 << 62) or not (0 <= n_points < 1 << 63):
        raise InvalidInputError(f"seq {seq} or n_points {n_points} out of range")
    w.svarint(seq)
    w.uvarint(n_points)
    _write_stamps(w, s.stamps)
    write_anchor(w, s.anchor)
    _write_horizons(w, s.horizons, s.horizon_band)
    return bytes(w.buf)


def _read_submap_fields(r: _Reader, version: int) -> dict:
    n = r.uvarint("robot name length", MAX_ROBOT_BYTES)
    try:
        robot = r.take(n, "robot name").decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DecodeError("robot name is not UTF-8") from exc
    return {
        "robot": robot,
        "seq": r.svarint("seq", 1 << 62),
        "n_points": r.uvarint("n_points", (1 << 63) - 1),
        "stamps": _read_stamps(r),
        "anchor": read_anchor(r) if version >= 2 else read_anchor_entries(r),
        **(_read_horizons(r) if version >= 3 else {}),
    }


def _write_horizons(w: _Writer, horizons: list | None, band: tuple | None) -> None:
    """The free-space block: the viewpoint count (0: none recorded), then the band's heights
    and each viewpoint in cm and the bins, and per viewpoint its x, y and one code per bin
    (`gmmap.mapping.frontier.range_codes`)."""
    if not horizons or band is None:
        w.uvarint(0)
        return
    bins = len(horizons[0].ranges)
    if len(horizons) > MAX_HORIZONS or not HORIZON_BINS[0] <= bins <= HORIZON_BINS[1]:
        raise InvalidInputError(f"at most {MAX_HORIZONS} horizons of {HORIZON_BINS} bins each")
    if any(len(h.ranges) != bins for h in horizons):
        raise InvalidInputError("every horizon of a submap has the same number of bins")
    w.uvarint(len(horizons))
    for v in (*band, *(c for h in horizons for c in h.origin)):
        if not abs(v) * 100 <= MAX_HORIZON_CM:
            raise InvalidInputError(f"horizon height or viewpoint {v} m out of range")
    for v in band:
        w.svarint(round(v * 100))
    w.uvarint(bins)
    for h in horizons:
        w.svarint(round(h.origin[0] * 100))
        w.svarint(round(h.origin[1] * 100))
        w.raw(range_codes(h.ranges).tobytes())


def _read_horizons(r: _Reader) -> dict:
    n = r.uvarint("horizon count", MAX_HORIZONS)
    if n == 0:
        return {"horizons": None, "horizon_band": None}
    band = tuple(r.svarint("horizon band", MAX_HORIZON_CM) / 100 for _ in range(2))
    if not band[0] < band[1]:
        raise DecodeError(f"horizon band {band} is not (low, high)")
    bins = r.uvarint("horizon bins", HORIZON_BINS[1])
    if bins < HORIZON_BINS[0]:
        raise DecodeError(f"{bins} horizon bins, fewer than {HORIZON_BINS[0]}")
    horizons = []
    for _ in range(n):
        origin = np.array([r.svarint("viewpoint", MAX_HORIZON_CM) / 100 for _ in range(2)])
        codes = np.frombuffer(r.take(bins, "horizon codes"), dtype=np.uint8)
        horizons.append(Horizon(origin, code_ranges(codes)))
    return {"horizons": horizons, "horizon_band": band}


def _write_stamps(w: _Writer, stamps: object) -> None:
    """The first stamp as float64, the others as float32 offsets from it: exact first, the
    others within 2^-24 of their offset (6 µs after 100 s)."""
    t = np.asarray(stamps, dtype=np.float64).reshape(-1)
    if len(t) > MAX_STAMPS or not np.isfinite(t).all():
        raise InvalidInputError(f"stamps must be at most {MAX_STAMPS} finite values")
    w.uvarint(len(t))
    if len(t):
        offsets = (t[1:] - t[0]).astype("<f4")
        if not np.isfinite(offsets).all():
            raise InvalidInputError("stamp offsets overflow float32")
        w.raw(struct.pack("<d", t[0]) + offsets.tobytes())


def _read_stamps(r: _Reader) -> np.ndarray:
    n = r.uvarint("stamp count", MAX_STAMPS)
    if n == 0:
        return np.zeros(0)
    first = struct.unpack("<d", r.take(8, "first stamp"))[0]
    offsets = np.frombuffer(r.take(4 * (n - 1), "stamp offsets"), dtype="<f4")
    t = np.concatenate([[first], first + offsets.astype(np.float64)])
    if not np.isfinite(t).all():
        raise DecodeError("stamps are not finite")
    return t


# --- steps and radices shared by encoder and decoder (IEEE basic operations only) -----------


def _log_stds(floor: float, gaps: np.ndarray, step: np.ndarray) -> np.ndarray:
    """log σ₁..σ₃ from the floor and the three gaps: ℓ₁ = floor + g₁·step, ℓᵢ = ℓᵢ₋₁ + gᵢ·step."""
    out = np.empty(gaps.shape)
    prev = np.full(len(gaps), floor)
    for i in range(3):
        prev = prev + gaps[:, i] * step
        out[:, i] = prev
    return out


def _steps(n: np.ndarray, logstd: np.ndarray, qmin: float) -> tuple[np.ndarray, ...]:
    """Bins per octahedral coordinate of the normal and of the largest axis' angle, and the
    mean's step along each axis, from the weight index n and the decoded log-stds.

    Every step makes its parameter's expected KL contribution w·F·step²/24 (uniform error, F the
    Fisher information) equal to D/K, with w = 6n²·D/K:
    - a rotation δ mixing axes i, j has F = (r − 1/r)², r = σᵢ/σⱼ: step (2/n) / |r − 1/r|. The
      normal mixes with both other axes (root mean square of the two), the angle with the middle
      axis only. Bins: π/step over the angle's half circle; 2/step per octahedral coordinate
      (its range is 2; a bin then spans about step/√2 radians near the pole, up to ~1.7 times
      that elsewhere).
    - a mean error along axis i has F = 1/σᵢ²: step 2σᵢ/n, at least qmin.
    """
    ell = logstd
    e = _pexp(
        np.column_stack([ell[:, 1] - ell[:, 0], ell[:, 2] - ell[:, 0], ell[:, 2] - ell[:, 1], ell])
    )
    a = e[:, :3] - 1.0 / e[:, :3]  # r − 1/r for the pairs (1,2), (1,3), (2,3)
    normal = n * np.sqrt(0.5 * (a[:, 0] * a[:, 0] + a[:, 1] * a[:, 1]))
    angle = (0.5 * math.pi) * n * a[:, 2]
    return _radix(normal), _radix(angle), np.maximum(qmin, 2.0 * e[:, 3:] / n[:, None])


def _radix(x: np.ndarray) -> np.ndarray:
    return np.clip(np.ceil(x), 1, RADIX_CAP).astype(np.int64)


def _mean_radices(R: np.ndarray, step: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Bins along each decoded axis for the mean's offset in its cell, and the spans they cover:
    the cell's extent along axis i is cell·(|R₀ᵢ| + |R₁ᵢ| + |R₂ᵢ|)."""
    span = cell * (np.abs(R[:, 0, :]) + np.abs(R[:, 1, :]) + np.abs(R[:, 2, :]))
    return _radix(span / step), span


# --- the mixture -----------------------------------------------------------------------------


def _encode_gmm(g: Gmm, distortion: float) -> bytes:
    if len(g) > MAX_COMPONENTS:
        raise InvalidInputError(f"{len(g)} components exceed the wire format's {MAX_COMPONENTS}")
    if np.abs(g.means).max() > MAX_COORD:
        raise InvalidInputError(f"means beyond {MAX_COORD:g} m cannot be sent")
    exponent, origin, cells = _grid(g.means)
    morton = _morton(cells)
    order = np.argsort(morton, kind="stable")  # the decoded order
    morton, cells = morton[order], cells[order]
    w, mu, cov = g.weights[order], g.means[order], g.covariances[order]
    n = np.maximum(1.0, np.rint(np.sqrt(w * len(g) / (6.0 * distortion))))
    if n.max() > MAX_WEIGHT_INDEX:
        raise InvalidInputError(f"distortion {distortion:g} is too small for the wire format")
    lam, V = np.linalg.eigh(cov)  # ascending, so V[:, :, 0] is the normal
    floor_code, gaps, logstd = _quantise_log_stds(0.5 * np.log(lam), n)
    normal_radix, angle_radix, mean_step = _steps(n, logstd, math.ldexp(1.0, -QMIN_EXPONENT))
    rotation_radix = np.column_stack([normal_radix, normal_radix, angle_radix])
    j_rotation, R = _quantise_rotation(V, rotation_radix)
    mean_radix, span = _mean_radices(R, mean_step, math.ldexp(1.0, exponent))
    centre = (origin + cells + 0.5) * math.ldexp(1.0, exponent)
    j_mean = _bin(2.0 * np.einsum("kji,kj->ki", R, mu - centre) / span, mean_radix)

    streams = np.stack([np.diff(morton, prepend=0), n.astype(np.int64) - 1, *gaps.T])
    ks = np.array([_rice_k(x, MAX_RICE_K) for x in streams], dtype=np.int64)
    w_ = _Writer()
    w_.uvarint(len(g))
    w_.i8(exponent)
    for o in origin:
        w_.svarint(int(o))
    w_.u8(QMIN_EXPONENT)
    w_.svarint(floor_code)
    w_.raw(bytes(ks.tolist()))
    bw = _BitWriter()
    _rice_write(bw, streams, ks)
    _tb_write(bw, j_rotation, rotation_radix)
    _tb_write(bw, j_mean, mean_radix)
    return bytes(w_.buf) + bw.tobytes()


def _grid(means: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The cell exponent (6.25 cm cells, coarser only for maps over 65 km), the grid origin and
    each mean's cell, all cells within 2^20 of the origin."""
    exponent = CELL_EXPONENT
    while (np.ptp(means, axis=0) / math.ldexp(1.0, exponent)).max() >= (1 << GRID_BITS) - 2:
        exponent += 1
    index = np.floor(means / math.ldexp(1.0, exponent))
    origin = index.min(axis=0).astype(np.int64)
    cells = np.clip(index - origin, 0, (1 << GRID_BITS) - 1).astype(np.int64)
    return exponent, origin, cells


def _quantise_log_stds(ell: np.ndarray, n: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The floor code, the gaps and the decoded log-stds: each log-std in steps of √2/n from
    the previous decoded one (so errors do not add up and the gaps are ≥ 0)."""
    if np.abs(ell).max() > MAX_LOG_STD - 1:
        raise InvalidInputError("standard deviations outside [e^-79, e^79] m cannot be sent")
    floor_code = math.floor(ell[:, 0].min() * LOG_FLOOR_SCALE)
    step = _SQRT2 / n
    gaps = np.zeros(ell.shape, dtype=np.int64)
    prev = np.full(len(ell), floor_code / LOG_FLOOR_SCALE)
    for i in range(3):
        gaps[:, i] = np.maximum(0, np.rint((ell[:, i] - prev) / step))
        prev = prev + gaps[:, i] * step
    return floor_code, gaps, _log_stds(floor_code / LOG_FLOOR_SCALE, gaps, step)


def _decode_gmm(r: _Reader) -> Gmm:
    k = r.uvarint("component count", MAX_COMPONENTS)
    if k == 0:
        raise DecodeError("a mixture needs at least one component")
    exponent = r.i8("cell exponent")
    if not CELL_EXPONENT_RANGE[0] <= exponent <= CELL_EXPONENT_RANGE[1]:
        raise DecodeError(f"cell exponent {exponent} out of range")
    origin = np.array([r.svarint("grid origin", MAX_ORIGIN) for _ in range(3)], dtype=np.int64)
    qmin_exponent = r.u8("qmin exponent")
    if qmin_exponent > MAX_QMIN_EXPONENT:
        raise DecodeError(f"qmin exponent {qmin_exponent} out of range")
    floor = r.svarint("log-std floor", int(MAX_LOG_STD) * LOG_FLOOR_SCALE) / LOG_FLOOR_SCALE
    ks = np.frombuffer(r.take(5, "Rice parameters"), dtype=np.uint8).astype(np.int64)
    if ks.max() > MAX_RICE_K:
        raise DecodeError("Rice parameter out of range")
    br = _BitReader(r.rest())
    streams = _rice_read(br, k, ks, _RICE_LIMITS)
    cells = _read_cells(streams[0])
    n = (streams[1] + 1).astype(np.float64)
    logstd = _log_stds(floor, streams[2:].T, _SQRT2 / n)
    if not (np.abs(logstd) <= MAX_LOG_STD).all():
        raise DecodeError("standard deviations out of range")
    normal_radix, angle_radix, mean_step = _steps(n, logstd, math.ldexp(1.0, -qmin_exponent))
    rotation_radix = np.column_stack([normal_radix, normal_radix, angle_radix])
    c = _bin_centre(_tb_read(br, rotation_radix).reshape(k, 3), rotation_radix)
    R = _rotation(_from_octahedral(c[:, 0], c[:, 1]), c[:, 2])
    cell = math.ldexp(1.0, exponent)
    mean_radix, span = _mean_radices(R, mean_step, cell)
    offset = 0.5 * span * _bin_centre(_tb_read(br, mean_radix).reshape(k, 3), mean_radix)
    br.finish()
    means = (origin + cells + 0.5) * cell + (R @ offset[:, :, None])[:, :, 0]
    cov = (R * np.exp(2.0 * logstd)[:, None, :]) @ R.transpose(0, 2, 1)
    try:
        return Gmm(n * n / (n * n).sum(), means, 0.5 * (cov + cov.transpose(0, 2, 1)))
    except InvalidGmmError as exc:
        raise DecodeError(f"decoded mixture is invalid: {exc}") from exc


def _read_cells(gaps: np.ndarray) -> np.ndarray:
    """Cells from the gaps between consecutive Morton codes (each code below 2^60)."""
    if gaps.astype(np.float64).sum() >= 2.0**62:  # guards the int64 sum just below
        raise DecodeError("cell codes out of range")
    morton = np.cumsum(gaps)
    if morton[-1] >= 1 << 60:
        raise DecodeError("cell codes out of range")
    return _unmorton(morton)
