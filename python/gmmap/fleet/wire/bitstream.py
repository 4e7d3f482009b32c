"""Byte- and bit-level coding for the wire codec (`gmmap.fleet.wire.codec`; the layout is in
``docs/wire-format.md``).

Byte fields (u8, i8, LEB128 varints, zigzag signed varints) and little-endian bit streams
(fixed-width fields, unary codes), with Rice codes and truncated binary codes on top of them.
Every reader is bounds-checked and fails with `DecodeError` only: it faces untrusted bytes.
"""

from __future__ import annotations

import struct

import numpy as np

from gmmap.errors import DecodeError
from gmmap.names import NAME_RE

# --- byte-level fields -----------------------------------------------------------------------


class _Writer:
    def __init__(self) -> None:
        self.buf = bytearray()

    def u8(self, v: int) -> None:
        self.buf.append(v)

    def i8(self, v: int) -> None:
        self.buf += struct.pack("<b", v)

    def uvarint(self, v: int) -> None:
        while v >= 0x80:
            self.buf.append((v & 0x7F) | 0x80)
            v >>= 7
        self.buf.append(v)

    def svarint(self, v: int) -> None:
        self.uvarint(-2 * v - 1 if v < 0 else 2 * v)  # zigzag

    def raw(self, b: bytes) -> None:
        self.buf += b

    def name(self, name: str) -> None:
        """A name (`gmmap.names`): its UTF-8 length as a varint, then the bytes."""
        raw = name.encode()
        self.uvarint(len(raw))
        self.raw(raw)


class _Reader:
    """Bounds-checked reads from a byte string; every failure is a DecodeError."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 0

    def take(self, n: int, what: str) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise DecodeError(f"truncated message: {what} needs {n} bytes")
        out = self.data[self.pos : self.pos + n]
        self.pos += n
        return out

    def u8(self, what: str) -> int:
        return self.take(1, what)[0]

    def i8(self, what: str) -> int:
        return struct.unpack("<b", self.take(1, what))[0]

    def uvarint(self, what: str, limit: int) -> int:
        v, shift = 0, 0
        while True:
            b = self.u8(what)
            v |= (b & 0x7F) << shift
            if not b & 0x80:
                break
            shift += 7
            if shift > 63:
                raise DecodeError(f"{what}: varint longer than 64 bits")
        if v > limit:
            raise DecodeError(f"{what} = {v} exceeds {limit}")
        return v

    def svarint(self, what: str, limit: int) -> int:
        z = self.uvarint(what, 2 * limit + 1)
        v = (z >> 1) ^ -(z & 1)
        if abs(v) > limit:
            raise DecodeError(f"{what} = {v} exceeds ±{limit}")
        return v

    def name(self, what: str) -> str:
        """A name of `_Writer.name`; DecodeError where it is not a name."""
        try:
            name = self.take(self.uvarint(f"{what} length", 255), what).decode()
        except UnicodeDecodeError as err:
            raise DecodeError(f"{what} is not UTF-8") from err
        if not NAME_RE.fullmatch(name):
            raise DecodeError(f"{what} {name!r} is not a name")
        return name

    def rest(self) -> bytes:
        out = self.data[self.pos :]
        self.pos = len(self.data)
        return out


# --- bit streams -----------------------------------------------------------------------------


class _BitWriter:
    """Bits, least significant first within each byte; values LSB first."""

    def __init__(self) -> None:
        self.chunks: list[np.ndarray] = []

    def fixed(self, values: np.ndarray, widths: np.ndarray | int) -> None:
        values = np.asarray(values, dtype=np.uint64).reshape(-1)
        widths = np.broadcast_to(np.asarray(widths, dtype=np.int64), values.shape)
        if values.size == 0 or int(widths.max()) == 0:
            return
        for start in range(0, values.size, 8192):  # blocks bound the (n, width) temporaries
            v, wd = values[start : start + 8192], widths[start : start + 8192]
            j = np.arange(int(wd.max()), dtype=np.uint64)
            bits = ((v[:, None] >> j) & np.uint64(1)).astype(np.uint8)
            self.chunks.append(bits[j[None, :].astype(np.int64) < wd[:, None]])

    def unary(self, q: np.ndarray) -> None:
        """q ones, then a zero, for each q."""
        q = np.asarray(q, dtype=np.int64)
        bits = np.ones(int(q.sum()) + len(q), dtype=np.uint8)
        bits[np.cumsum(q + 1) - 1] = 0
        self.chunks.append(bits)

    def tobytes(self) -> bytes:
        if not self.chunks:
            return b""
        return np.packbits(np.concatenate(self.chunks), bitorder="little").tobytes()


class _BitReader:
    """Reads a little-endian bit stream; fixed-width fields (≤ 56 bits) come from 64-bit
    windows gathered per field, so a read is a handful of vectorised operations."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.bytes = np.frombuffer(data + bytes(8), dtype=np.uint8)  # any window is in range
        self.nbits = 8 * len(data)
        self.pos = 0

    def fixed(self, widths: np.ndarray) -> np.ndarray:
        widths = np.asarray(widths, dtype=np.int64)
        total = int(widths.sum())
        if self.pos + total > self.nbits:
            raise DecodeError("truncated bit stream")
        starts = self.pos + np.cumsum(widths) - widths
        windows = self.bytes[(starts >> 3)[:, None] + _WINDOW].view("<u8")[:, 0]
        masks = (np.uint64(1) << widths.astype(np.uint64)) - np.uint64(1)
        self.pos += total
        return ((windows >> (starts & 7).astype(np.uint64)) & masks).astype(np.int64)

    def unary(self, n: int) -> np.ndarray:
        """n unary codes (q ones, then a zero)."""
        if n == 0:
            return np.zeros(0, dtype=np.int64)
        first = self.pos >> 3
        bits = np.unpackbits(self.bytes[first : len(self.data)], bitorder="little")
        ends = np.flatnonzero(bits[self.pos - 8 * first :] == 0)[:n]
        if len(ends) < n:
            raise DecodeError("truncated bit stream (unary code)")
        self.pos += int(ends[-1]) + 1
        q = ends.copy()
        q[1:] -= ends[:-1] + 1
        return q

    def finish(self) -> None:
        """The stream must end in its last byte, padded with zero bits."""
        if self.nbits - self.pos >= 8:
            raise DecodeError(f"{(self.nbits - self.pos) // 8} unexpected trailing bytes")
        if self.pos < self.nbits and self.data[-1] >> (self.pos & 7):
            raise DecodeError("non-zero padding bits")


_WINDOW = np.arange(8)


def _rice_k(x: np.ndarray, max_k: int) -> int:
    """The Rice parameter (at most ``max_k``) that codes ``x`` in the fewest bits."""
    k = np.arange(max_k + 1)
    costs = (x[None, :] >> k[:, None]).sum(axis=1) + (k + 1) * len(x)
    return int(np.argmin(costs))


def _rice_write(bw: _BitWriter, streams: np.ndarray, ks: np.ndarray) -> None:
    """Rice codes of the rows of ``streams`` (rows × n), row i with parameter ks[i]: first all
    quotients (unary, row after row), then all remainders, so both halves decode vectorised."""
    bw.unary((streams >> ks[:, None]).reshape(-1))
    bw.fixed(
        (streams & ((np.int64(1) << ks[:, None]) - 1)).reshape(-1), np.repeat(ks, streams.shape[1])
    )


def _rice_read(br: _BitReader, n: int, ks: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Reads what ``_rice_write`` wrote: len(ks) rows of n values, row i at most limits[i]."""
    q = br.unary(len(ks) * n).reshape(len(ks), n)
    if (q > (limits >> ks)[:, None]).any():
        raise DecodeError("Rice-coded value out of range")
    x = (q << ks[:, None]) | br.fixed(np.repeat(ks, n)).reshape(len(ks), n)
    if (x > limits[:, None]).any():
        raise DecodeError("Rice-coded value out of range")
    return x


def _bit_length(v: np.ndarray) -> np.ndarray:
    """Bits needed for each non-negative integer below 2^52 (exact: frexp, not log2)."""
    return np.frexp(np.asarray(v, dtype=np.float64))[1].astype(np.int64)


def _tb_write(bw: _BitWriter, x: np.ndarray, radix: np.ndarray) -> None:
    """Truncated binary codes of 0 ≤ x < radix (radix 1 takes no bits): prefixes of b - 1 bits
    for all values first, then the one extra bit of those that need it."""
    x, radix = np.asarray(x, np.int64).reshape(-1), np.asarray(radix, np.int64).reshape(-1)
    b = _bit_length(radix - 1)
    u = (np.int64(1) << b) - radix  # values below u take b - 1 bits
    extra = (radix > 1) & (x >= u)
    y = x + u
    bw.fixed(np.where(extra, y >> 1, x), np.maximum(b - 1, 0))
    bw.fixed(y[extra] & 1, 1)


def _tb_read(br: _BitReader, radix: np.ndarray) -> np.ndarray:
    radix = np.asarray(radix, np.int64).reshape(-1)
    b = _bit_length(radix - 1)
    u = (np.int64(1) << b) - radix
    prefix = br.fixed(np.maximum(b - 1, 0))
    extra = (radix > 1) & (prefix >= u)
    out = prefix.copy()
    out[extra] = 2 * prefix[extra] + br.fixed(np.ones(int(extra.sum()), np.int64)) - u[extra]
    return out  # always < radix: truncated binary has no invalid codes
