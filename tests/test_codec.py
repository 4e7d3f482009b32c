"""The wire codec: round trips within the documented bounds, sizes, and hostile input."""

from __future__ import annotations

import functools
import math
import multiprocessing
import os
import struct
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
import zstandard
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gmmap
from gmmap import DecodeError, Gmm, InvalidInputError
from gmmap.fleet.wire import anchor as anchors_codec
from gmmap.fleet.wire import codec
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.mapping.submap import BuildOptions, Submap, build_submaps, level
from gmmap.math.geometry import rotation_angle

D = codec.DEFAULT_DISTORTION
QMIN = math.ldexp(1.0, -codec.QMIN_EXPONENT)
FUZZ_TOTAL = 100_000
HYPOTHESIS_MUTATIONS = 1_500
HYPOTHESIS_BODIES = 1_000


# --- fixtures and helpers --------------------------------------------------------------------


def random_rotations(k: int, rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(k, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1
    return q


def random_gmm(k: int, seed: int = 0) -> Gmm:
    """Components on a jittered 25 cm grid (so decoded means match by proximity), standard
    deviations from 1 mm to 20 cm with distinct axes, random rotations and weights."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(12), np.arange(12), np.arange(4)), -1).reshape(-1, 3)
    means = grid[rng.choice(len(grid), k, replace=False)] * 0.25 + rng.uniform(-0.03, 0.03, (k, 3))
    log_std = np.sort(rng.uniform(np.log(0.001), np.log(0.2), (k, 3)), axis=1)
    log_std[:, 1] = np.maximum(log_std[:, 1], log_std[:, 0] + 0.5)
    log_std[:, 2] = np.maximum(log_std[:, 2], log_std[:, 1] + 0.5)
    R = random_rotations(k, rng)
    cov = np.einsum("kij,kj,klj->kil", R, np.exp(2 * log_std), R)
    w = rng.dirichlet(np.full(k, 2.0))
    return Gmm(w, means + np.array([-1.5, 0.7, 0.2]), 0.5 * (cov + cov.transpose(0, 2, 1)))


@functools.lru_cache(maxsize=1)
def real_submaps() -> tuple[Submap, ...]:
    """Two 100-component submaps of the bundled TUM fr1_xyz frames (4 frames each)."""
    opts = BuildOptions(frames_per_submap=4, covariance="full", select=False)
    return tuple(build_submaps(TumRgbd(BUNDLED_TUM_SLICE, stride=2), "robot-a", opts))


def matched(original: Gmm, decoded: Gmm) -> np.ndarray:
    """For each original component, the index of the decoded one with the nearest mean."""
    d = np.linalg.norm(original.means[:, None] - decoded.means[None], axis=2)
    index = d.argmin(axis=1)
    assert len(set(index.tolist())) == len(original), "decoded means do not match one to one"
    return index


def weight_index(w: np.ndarray, distortion: float) -> np.ndarray:
    return np.maximum(1.0, np.rint(np.sqrt(w * len(w) / (6 * distortion))))


def angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between axes, sign free."""
    return np.arccos(np.clip(np.abs(np.sum(a * b, axis=-1)), 0.0, 1.0))


# --- round trips -----------------------------------------------------------------------------


@pytest.mark.parametrize("distortion", [1e-4, D, 1e-2])
def test_gmm_round_trip_within_documented_bounds(distortion: float) -> None:
    g = random_gmm(120, seed=1)
    out = gmmap.decode(gmmap.encode(g, distortion=distortion))
    assert isinstance(out, Gmm) and len(out) == len(g)
    idx = matched(g, out)
    w, mu, cov = out.weights[idx], out.means[idx], out.covariances[idx]

    n = weight_index(g.weights, distortion)
    assert np.allclose(w, n * n / np.sum(n * n), rtol=1e-12)  # re-normalised n²
    step = math.sqrt(6 * distortion / len(g))
    heavy = g.weights >= 1.5 * distortion / len(g)
    assert np.all(np.abs(n * step - np.sqrt(g.weights))[heavy] <= step / 2 + 1e-12)

    lam, V = np.linalg.eigh(g.covariances)
    lam_hat, V_hat = np.linalg.eigh(cov)
    ell, ell_hat = 0.5 * np.log(lam), 0.5 * np.log(lam_hat)
    assert np.all(np.abs(ell_hat - ell) <= 1 / (math.sqrt(2) * n[:, None]) + 1e-9)

    normal_radix, angle_radix, mean_step = codec._steps(n, ell_hat, QMIN)
    slack = 1.02  # the test's eigh(decoded) differs from the decoder's ℓ̂ in the last bits
    distinct = np.diff(ell_hat, axis=1) > 0.2  # axes that the decoded covariance defines
    ok_normal = distinct[:, 0]
    normal_err = angle(V[:, :, 0], V_hat[:, :, 0])
    assert np.all(normal_err[ok_normal] <= slack * 2.5 / normal_radix[ok_normal] + 1e-9)
    ok_axis = distinct.all(axis=1)
    axis_err = angle(V[:, :, 2], V_hat[:, :, 2])
    bound = slack * (2.0 / angle_radix + 2.5 / normal_radix)
    assert np.all(axis_err[ok_axis] <= bound[ok_axis] + 1e-9)

    err = mu - g.means
    assert np.all(np.linalg.norm(err, axis=1) <= 0.5 * np.linalg.norm(mean_step, axis=1) * slack)
    along = np.abs(np.einsum("kji,kj->ki", V_hat, err))
    assert np.all(along[ok_axis] <= 0.5 * mean_step[ok_axis] * slack + 1e-12)
    if distortion <= D:
        assert g.l2_correlation(out) > 0.99


def test_submap_round_trip_keeps_identity_fields() -> None:
    rng = np.random.default_rng(3)
    anchors = [level(np.eye(4), (0, 0, 1)), np.eye(4)]
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = random_rotations(1, rng)[0], [12.5, -3.25, 0.125]
    anchors.append(T)
    yawed = np.eye(4)
    yawed[:2, :2] = [[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]]
    yawed[:3, 3] = [1.2, 0.6, 1.5]
    anchors.append(yawed)
    scaled = yawed.copy()
    scaled[:3, :3] *= 1.5  # not rigid: sent entry by entry, exactly
    anchors.append(scaled)
    stamps = 1305031102.175304 + np.cumsum(rng.uniform(0.02, 0.05, 7))
    for i, anchor in enumerate(anchors):
        s = Submap("robot-ü", 41 + i, anchor, stamps, 12345, random_gmm(30, seed=i))
        s.points, s.gt_anchor, s.stats = np.zeros((5, 3)), np.eye(4), {"frames": 5}
        out = gmmap.decode(gmmap.encode(s))
        assert isinstance(out, Submap)
        assert (out.robot, out.seq, out.n_points) == ("robot-ü", 41 + i, 12345)
        assert out.anchor.dtype == np.float64 and (out.anchor[3] == [0, 0, 0, 1]).all()
        if anchor is scaled:
            assert np.array_equal(out.anchor, anchor)
        else:
            assert np.abs(out.anchor[:3, 3] - anchor[:3, 3]).max() <= 2.0**-14
            assert rotation_angle(out.anchor[:3, :3].T @ anchor[:3, :3]) < 2e-6
            assert np.allclose(out.anchor[:3, :3].T @ out.anchor[:3, :3], np.eye(3), atol=1e-14)
        assert out.stamps[0] == stamps[0]
        tol = 2.0**-24 * np.abs(stamps - stamps[0]) + 2 * np.spacing(stamps[0])
        assert np.all(np.abs(out.stamps - stamps) <= tol)
        assert out.points is None and out.gt_anchor is None and out.stats == {}
        assert out.gmm.l2_correlation(s.gmm) > 0.99


def test_anchors_are_compact() -> None:
    yawed = level(np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0], (0, 0, 1))
    anchor = np.eye(4)
    anchor[:3, :3], anchor[:3, 3] = yawed[:3, :3], [0.5, 0.25, 1.75]
    w = codec._Writer()
    anchors_codec.write_anchor(w, anchor)
    # The form, a quaternion's x and y (0) and z or w (3 bytes), a translation under 128 m.
    assert len(w.buf) <= 1 + 1 + 1 + 3 + 3 * 3
    general = np.eye(4)
    general[:3, :3] = random_rotations(1, np.random.default_rng(2))[0]
    w = codec._Writer()
    anchors_codec.write_anchor(w, general)
    assert len(w.buf) <= 1 + 3 * 3 + 3


def test_version_1_and_2_messages_still_decode() -> None:
    """Stores hold older messages: version 2 lacks the free-space block (its one byte, 0, for
    a submap without horizons), version 1 also has the anchor as its entry codes alone."""
    s = Submap("r", 3, level(np.eye(4), (0, 0, 1)), np.array([5.0, 6.0]), 9, random_gmm(5))
    s.anchor[:3, 3] = [1.0 / 3.0, 2.0, -7.25]
    new = gmmap.encode(s)
    w = codec._Writer()
    anchors_codec.write_anchor(w, s.anchor)
    start = new.index(bytes(w.buf))
    end = start + len(w.buf)
    assert new[end] == 0  # no horizons
    v2 = new[:4] + b"\x02" + new[5:end] + new[end + 1 :]
    exact = codec._Writer()
    anchors_codec.write_anchor_entries(exact, s.anchor)
    v1 = new[:4] + b"\x01" + new[5:start] + bytes(exact.buf) + new[end + 1 :]
    now = gmmap.decode(new)
    for old, anchor in ((v1, s.anchor), (v2, now.anchor)):
        out = gmmap.decode(old)
        assert np.array_equal(out.anchor, anchor) and out.horizons is None
        assert np.array_equal(out.gmm.means, now.gmm.means)


def test_horizons_round_trip_to_their_codes_and_bad_blocks_are_refused() -> None:
    """A submap's free-space horizons travel as 10 cm codes (NaN: not seen) at cm viewpoints;
    a band upside down or too few bins is a DecodeError."""
    from gmmap.mapping.frontier import Horizon, code_ranges, range_codes

    ranges = np.linspace(0.3, 20.0, 72)
    ranges[5:9] = np.nan
    views = [Horizon(np.array([0.0, 0.0]), ranges), Horizon(np.array([1.234, -0.5]), ranges[::-1])]
    s = Submap("r", 1, np.eye(4), np.array([0.0]), 9, random_gmm(5), horizons=views,
               horizon_band=(-0.5, 0.5))  # fmt: skip
    out = gmmap.decode(gmmap.encode(s))
    assert out.horizon_band == (-0.5, 0.5) and len(out.horizons) == 2
    np.testing.assert_allclose(out.horizons[1].origin, [1.23, -0.5])
    np.testing.assert_array_equal(out.horizons[0].ranges, code_ranges(range_codes(ranges)))
    w = codec._Writer()
    codec._write_horizons(w, views, (-0.5, 0.5))
    good = bytes(w.buf)
    for bad in (good[:1] + b"\x64\x63" + good[3:], good[:3] + b"\x04" + good[4:], good[:-1]):
        with pytest.raises(DecodeError):
            codec._read_horizons(codec._Reader(bad))
    with pytest.raises(InvalidInputError):
        codec._write_horizons(codec._Writer(), views, (-0.5, 1e4))


def test_edge_cases_round_trip() -> None:
    one = Gmm([1.0], [[1e6, -2e5, 3.0]], [np.diag([1e-6, 4e-6, 9e-6])])
    out = gmmap.decode(gmmap.encode(one))
    assert np.allclose(out.means, one.means, atol=1e-3) and out.weights[0] == 1.0
    sphere = Gmm.from_diagonal([0.5, 0.5], [[0, 0, 0], [100.0, 0, 0]], [[0.01] * 3, [0.04] * 3])
    out = gmmap.decode(gmmap.encode(sphere))
    lam = np.linalg.eigvalsh(out.covariances)  # within e^(±√2/n), n = 13 here
    assert np.allclose(lam, [[0.01] * 3, [0.04] * 3], rtol=0.12)
    wide = random_gmm(40, seed=5).transform(np.diag([1.0, 1.0, 1.0, 1.0]))
    spread = Gmm(wide.weights, wide.means * 1e4, wide.covariances)  # 30 km: coarser cells
    out = gmmap.decode(gmmap.encode(spread))
    assert np.abs(out.means[matched(spread, out)] - spread.means).max() < 2.0
    empty_stamps = Submap("", 0, np.eye(4), np.zeros(0), 0, one)
    out = gmmap.decode(gmmap.encode(empty_stamps))
    assert out.robot == "" and len(out.stamps) == 0


def test_many_components() -> None:
    rng = np.random.default_rng(7)
    k = 5000
    g = Gmm.from_diagonal(
        rng.dirichlet(np.ones(k)), rng.uniform(-20, 20, (k, 3)), rng.uniform(1e-5, 1e-2, (k, 3))
    )
    data = gmmap.encode(g)
    assert len(data) < 12 * k
    out = gmmap.decode(data)
    assert len(out) == k and g.l2_correlation(out) > 0.99


def test_real_submap_fits_in_a_kilobyte_and_registers_alike() -> None:
    a, b = real_submaps()[:2]
    assert len(a.gmm) == len(b.gmm) == 100 and not a.gmm.is_diagonal
    sizes = [len(gmmap.encode(s)) for s in (a, b)]
    assert max(sizes) <= 1000, sizes
    assert min(s.gmm.float32_bytes for s in (a, b)) / max(sizes) > 4
    da, db = (gmmap.decode(gmmap.encode(s)) for s in (a, b))
    guess = np.linalg.inv(b.anchor) @ a.anchor
    r0 = gmmap.register(a.gmm, b.gmm, guess).transform
    r1 = gmmap.register(da.gmm, db.gmm, guess).transform
    assert np.linalg.norm(r1[:3, 3] - r0[:3, 3]) < 0.003
    cos = (np.trace(r1[:3, :3].T @ r0[:3, :3]) - 1) / 2
    assert math.degrees(math.acos(min(1.0, cos))) < 0.25


def test_encoding_is_deterministic_and_distortion_trades_bytes() -> None:
    g = random_gmm(80, seed=2)
    assert gmmap.encode(g) == gmmap.encode(g)
    sizes = [len(gmmap.encode(g, distortion=d)) for d in (1e-5, 1e-4, 1e-3, 1e-2, 1e-1)]
    assert sizes == sorted(sizes, reverse=True)
    corr = [g.l2_correlation(gmmap.decode(gmmap.encode(g, distortion=d))) for d in (1e-5, 1e-1)]
    assert corr[0] > corr[1]


def test_zstd_is_used_when_it_helps() -> None:
    s = Submap("r" * 200, 1, np.eye(4), np.full(4000, 5.0), 10, random_gmm(10))
    data = gmmap.encode(s)
    assert data[6] == codec.COMPRESSION_ZSTD and len(data) < 1000
    out = gmmap.decode(data)
    assert out.robot == "r" * 200 and np.array_equal(out.stamps, s.stamps)
    assert gmmap.encode(random_gmm(50))[6] == codec.COMPRESSION_NONE


def test_encode_rejects_what_it_cannot_send() -> None:
    g = random_gmm(5)
    bad = [
        lambda: gmmap.encode(np.zeros((3, 3))),
        lambda: gmmap.encode(g, distortion=0.0),
        lambda: gmmap.encode(g, distortion=float("nan")),
        lambda: gmmap.encode(g, distortion="fine"),
        lambda: gmmap.encode(Submap("a", 0, np.ones((4, 4)), np.zeros(1), 0, g)),
        lambda: gmmap.encode(Submap("a", 0, np.eye(3), np.zeros(1), 0, g)),
        lambda: gmmap.encode(Submap("a", 0, np.eye(4), np.array([0.0, np.nan]), 0, g)),
        lambda: gmmap.encode(Submap("é" * 200, 0, np.eye(4), np.zeros(1), 0, g)),
        lambda: gmmap.encode(Submap("a", 0, np.eye(4), np.zeros(1), -1, g)),
        lambda: gmmap.encode(Gmm([1.0], [[2e12, 0, 0]], [np.eye(3)])),
    ]
    for f in bad:
        with pytest.raises(InvalidInputError):
            f()


def test_decode_error_is_a_gmmap_value_error() -> None:
    assert issubclass(DecodeError, gmmap.GmmapError) and issubclass(DecodeError, ValueError)
    data = gmmap.encode(random_gmm(3))
    assert isinstance(gmmap.decode(bytearray(data)), Gmm)
    assert isinstance(gmmap.decode(memoryview(data)), Gmm)


# --- bad input -------------------------------------------------------------------------------


def header(kind: int = codec.KIND_GMM, version: int = codec.VERSION, comp: int = 0) -> bytes:
    return codec.MAGIC + bytes([version, kind, comp])


def uvarint(v: int) -> bytes:
    w = codec._Writer()
    w.uvarint(v)
    return bytes(w.buf)


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"G",
        codec.MAGIC,
        header(),
        b"GMMX" + header()[4:] + b"\x01",
        header(version=0) + b"\x01",
        header(version=2) + b"\x01",
        header(kind=0) + b"\x01",
        header(kind=3) + b"\x01",
        header(comp=2) + b"\x01",
        header(comp=1) + b"\x01\x02\x03",
        b"\x89PNG\r\n\x1a\n" + bytes(100),
    ],
)
def test_empty_short_and_foreign_input(data: bytes) -> None:
    with pytest.raises(DecodeError):
        gmmap.decode(data)


def test_wrong_magic_and_version_are_named() -> None:
    good = gmmap.encode(random_gmm(4))
    with pytest.raises(DecodeError, match="magic"):
        gmmap.decode(b"XMMW" + good[4:])
    with pytest.raises(DecodeError, match="version 9"):
        gmmap.decode(good[:4] + b"\x09" + good[5:])
    with pytest.raises(DecodeError, match="expected bytes"):
        gmmap.decode("GMMW")  # type: ignore[arg-type]


def test_hostile_counts_fail_fast() -> None:
    submap_prefix = header(codec.KIND_SUBMAP) + b"\x01a" + b"\x00\x00"
    hostile = [
        header() + uvarint(2**31),  # K = 2^31
        header() + uvarint(65535) + b"\xfc\x00\x00\x00\x00\x00" + bytes(5) + b"\xff" * 10,
        header() + uvarint(0),
        header() + b"\xff" * 11,  # a varint over 64 bits
        header(codec.KIND_SUBMAP) + uvarint(2**20) + b"x" * 50,  # robot name length
        submap_prefix + uvarint(2**31),  # stamp count
        submap_prefix + uvarint(65535) + bytes(8),  # stamps that are not there
        header(codec.KIND_SUBMAP) + b"\x02\xff\xfe",  # not UTF-8
        submap_prefix + uvarint(0) + b"\x05",  # anchor form 5
        submap_prefix + uvarint(0) + b"\x04" + uvarint(2 * 800_000) * 3,  # |q| > 1
        submap_prefix + uvarint(0) + b"\x04" + uvarint(2 * 2**21),  # a component over 1
        gmmap.encode(random_gmm(4)) + b"\x00",  # trailing byte
    ]
    for data in hostile:
        with pytest.raises(DecodeError):
            gmmap.decode(data)


def test_non_finite_values_are_rejected() -> None:
    s = Submap("r", 1, np.eye(4), np.array([98765.4321, 98766.0]), 3, random_gmm(5))
    s.anchor = np.diag([2.0, 2.0, 2.0, 1.0])  # not rigid: its entries travel as float64
    s.anchor[0, 3] = 1234.5678
    data = gmmap.encode(s)
    for value, replacement in ((98765.4321, math.nan), (1234.5678, math.inf)):
        at = data.index(struct.pack("<d", value))
        bad = data[:at] + struct.pack("<d", replacement) + data[at + 8 :]
        with pytest.raises(DecodeError, match="finite"):
            gmmap.decode(bad)


def test_zstd_bombs_and_bad_frames_are_refused() -> None:
    raw = gmmap.encode(random_gmm(20))
    assert raw[6] == codec.COMPRESSION_NONE
    body = raw[7:]
    cctx = zstandard.ZstdCompressor(level=3)
    assert isinstance(gmmap.decode(header(comp=1) + cctx.compress(body)), Gmm)
    bomb = zstandard.ZstdCompressor(level=3).compress(body + bytes(8 << 20))  # 8 MiB of zeros
    no_size = zstandard.ZstdCompressor(write_content_size=False).compress(body)
    for data in (
        header(comp=1) + bomb,
        header(comp=1) + no_size,
        header(comp=1) + cctx.compress(body) + b"\x00",
        header(comp=1) + cctx.compress(body)[:-2],
    ):
        with pytest.raises(DecodeError):
            gmmap.decode(data)


def test_oversized_input_is_refused_before_copying() -> None:
    with pytest.raises(DecodeError, match="exceeds"):
        gmmap.decode(header() + bytes(codec.MAX_MESSAGE))


# --- fuzzing: 100,000 mutated or truncated messages, only DecodeError ------------------------


@functools.lru_cache(maxsize=1)
def corpus() -> tuple[bytes, ...]:
    a = real_submaps()[0]
    general = Submap("b", 7, np.eye(4), np.arange(5.0), 9, random_gmm(12, seed=9))
    general.anchor = np.eye(4)
    general.anchor[:3, :3] = random_rotations(1, np.random.default_rng(1))[0]
    zipped = Submap("c" * 100, 2, np.eye(4), np.full(600, 1.0), 1, random_gmm(3, seed=4))
    messages = (
        gmmap.encode(a),
        gmmap.encode(a.gmm),
        gmmap.encode(general),
        gmmap.encode(zipped),
        gmmap.encode(Gmm([1.0], [[0.1, 0.2, 0.3]], [np.eye(3) * 1e-4])),
        gmmap.encode(random_gmm(3, seed=8), distortion=0.1),
    )
    assert messages[3][6] == codec.COMPRESSION_ZSTD
    return messages


def mutate(msg: bytes, rng: np.random.Generator) -> bytes:
    """One of: truncation, bit flips, byte overwrites, insertion, deletion, a header byte set
    to an extreme value."""
    m = bytearray(msg)
    op = int(rng.integers(6))
    if op == 0:
        return bytes(m[: int(rng.integers(len(m)))])
    if op == 1:
        for p in rng.integers(len(m), size=int(rng.integers(1, 4))):
            m[p] ^= 1 << int(rng.integers(8))
    elif op == 2:
        for p in rng.integers(len(m), size=int(rng.integers(1, 4))):
            m[p] = int(rng.integers(256))
    elif op == 3:
        p = int(rng.integers(len(m) + 1))
        m[p:p] = rng.bytes(int(rng.integers(1, 9)))
    elif op == 4:
        p = int(rng.integers(len(m)))
        del m[p : p + int(rng.integers(1, 9))]
    else:
        m[int(rng.integers(min(len(m), 64)))] = int(rng.choice([0, 1, 0x7F, 0x80, 0xFF]))
    return bytes(m)


def check_decode(data: bytes) -> str | None:
    """None if ``decode`` returns a mixture/submap or raises a DecodeError of its own checks;
    else what went wrong."""
    try:
        out = gmmap.decode(data)
    except DecodeError as exc:
        if str(exc).startswith("malformed message"):  # the safety net, not a check
            return f"unchecked: {exc!r} from {exc.__cause__!r}"
        return None
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"
    if not isinstance(out, (Gmm, Submap)):
        return f"decoded a {type(out).__name__}"
    return None


def fuzz_chunk(seed: int, count: int) -> list[str]:
    rng = np.random.default_rng(seed)
    messages = corpus()
    failures = []
    for _ in range(count):
        data = mutate(messages[int(rng.integers(len(messages)))], rng)
        problem = check_decode(data)
        if problem is not None:
            failures.append(f"{problem} for {data.hex()}")
    return failures


def test_fuzz_seeded_mutations_raise_only_decode_error() -> None:
    corpus()  # built once, before forking
    total = FUZZ_TOTAL - HYPOTHESIS_MUTATIONS - HYPOTHESIS_BODIES
    workers = min(2, os.cpu_count() or 1)
    if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            parts = pool.map(fuzz_chunk, range(workers), [total // workers] * workers)
            failures = [f for part in parts for f in part]
    else:
        failures = fuzz_chunk(0, total)
    assert not failures, f"{len(failures)} failures, first: {failures[:3]}"


@settings(
    max_examples=HYPOTHESIS_MUTATIONS,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(
    which=st.integers(0, 5),
    cut=st.integers(0, 4000),
    edits=st.lists(st.tuples(st.integers(0, 4000), st.integers(0, 255)), max_size=4),
    insert=st.binary(max_size=8),
)
def test_hypothesis_mutations_raise_only_decode_error(
    which: int, cut: int, edits: list[tuple[int, int]], insert: bytes
) -> None:
    m = bytearray(corpus()[which])
    for pos, value in edits:
        m[pos % len(m)] = value
    if insert:
        p = cut % (len(m) + 1)
        m[p:p] = insert
    elif cut < len(m):
        m = m[:cut]
    assert check_decode(bytes(m)) is None


@settings(max_examples=HYPOTHESIS_BODIES, deadline=None)
@given(kind=st.sampled_from([codec.KIND_GMM, codec.KIND_SUBMAP]), body=st.binary(max_size=400))
def test_hypothesis_arbitrary_bodies_raise_only_decode_error(kind: int, body: bytes) -> None:
    assert check_decode(header(kind) + body) is None
