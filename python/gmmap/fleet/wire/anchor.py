"""The anchor of a submap on the wire (docs/wire-format.md, "Submap body"): a rigid transform
as a quantised quaternion and translation (version 2's forms 1-4), anything else entry by entry,
exactly (form 0, and every anchor of version 1)."""

from __future__ import annotations

import math
import struct

import numpy as np

from gmmap.errors import DecodeError, InvalidInputError
from gmmap.fleet.wire.bitstream import _Reader, _Writer
from gmmap.fleet.wire.quantise import QMIN_EXPONENT
from gmmap.math.geometry import matrix_to_quaternion, quaternion_to_matrix

# A rigid anchor (version 2) is quantised: a unit quaternion by its three smallest components
# (the largest, made positive, follows from them) in steps of 2^-20, about 2 µrad of rotation,
# and the translation in steps of 2^-13 m (0.12 mm, the finest mean step): 13 bytes for a
# levelled anchor of the demo's office, against 47 as float64. The owner too uses the decoded
# anchor (it decodes its own message), so every robot's pose graph starts from the same numbers.
_ANCHOR_EXACT = 0  # form 0: the entry codes below; forms 1-4: rigid, largest component x/y/z/w
_QUAT_BITS = 20
_TRANSLATION_BITS = QMIN_EXPONENT
_MAX_TRANSLATION = 1 << 53  # steps; 2^40 m
_RIGID_TOLERANCE = 1e-6  # |RᵀR − I| and |det R − 1| below which an anchor is sent as rigid


def write_anchor(w: _Writer, anchor: object) -> None:
    """Writes ``anchor`` in version 2: rigid (forms 1-4) where it is one, else exact (form 0);
    `InvalidInputError` if it is not a finite 4×4 with last row [0, 0, 0, 1]."""
    A = np.asarray(anchor, dtype=np.float64)
    if A.shape != (4, 4) or not np.isfinite(A).all() or not (A[3] == [0, 0, 0, 1]).all():
        raise InvalidInputError("anchor must be a finite 4x4 matrix with last row [0, 0, 0, 1]")
    steps = np.round(A[:3, 3] * 2.0**_TRANSLATION_BITS)
    if not _is_rotation(A[:3, :3]) or np.abs(steps).max() > _MAX_TRANSLATION:
        w.u8(_ANCHOR_EXACT)
        write_anchor_entries(w, A)
        return
    q = matrix_to_quaternion(A[:3, :3])[0]
    largest = int(np.argmax(np.abs(q)))
    q = q if q[largest] > 0 else -q
    w.u8(1 + largest)
    for c in np.delete(q, largest):
        w.svarint(round(float(c) * 2.0**_QUAT_BITS))
    for t in steps:
        w.svarint(int(t))


def _is_rotation(R: np.ndarray) -> bool:
    return bool(
        np.abs(R.T @ R - np.eye(3)).max() < _RIGID_TOLERANCE
        and abs(np.linalg.det(R) - 1.0) < _RIGID_TOLERANCE
    )


def read_anchor(r: _Reader) -> np.ndarray:
    """A version-2 anchor; `DecodeError` for an unknown form or a quaternion over unit length."""
    form = r.u8("anchor form")
    if form == _ANCHOR_EXACT:
        return read_anchor_entries(r)
    if form > 4:
        raise DecodeError(f"unknown anchor form {form}")
    steps = [r.svarint("anchor rotation", 1 << _QUAT_BITS) for _ in range(3)]
    small = np.array(steps, dtype=np.float64) * 2.0**-_QUAT_BITS
    rest = 1.0 - float(small @ small)
    if rest < 0.0:
        raise DecodeError("anchor rotation is not a unit quaternion")
    q = np.insert(small, form - 1, math.sqrt(rest))
    t = [r.svarint("anchor translation", _MAX_TRANSLATION) for _ in range(3)]
    A = np.eye(4)
    A[:3, :3] = quaternion_to_matrix(q)[0]
    A[:3, 3] = np.array(t, dtype=np.float64) * 2.0**-_TRANSLATION_BITS
    return A


# Form 0, and every anchor of version 1: 3-bit codes of the 12 upper entries: exact 0, 1, −1, a
# float64 that follows, or a copy (4) or negated copy (5) of an earlier entry whose index
# follows. Lossless, for anchors that are not rigid transforms.
_ANCHOR_CONSTANTS = (0.0, 1.0, -1.0)
_LITERAL, _COPY, _NEGATED = 3, 4, 5


def write_anchor_entries(w: _Writer, A: np.ndarray) -> None:
    """The upper 3×4 block of ``A``, entry by entry (form 0)."""
    entries = [float(v) for v in A[:3].reshape(-1)]
    mask, tail = 0, bytearray()
    for i, v in enumerate(entries):
        code, extra = _anchor_code(entries, i, v)
        mask |= code << (3 * i)
        tail += extra
    w.raw(mask.to_bytes(5, "little") + bytes(tail))


def _anchor_code(entries: list[float], i: int, v: float) -> tuple[int, bytes]:
    if v in _ANCHOR_CONSTANTS:
        return _ANCHOR_CONSTANTS.index(v), b""
    bits = struct.pack("<d", v)
    for j in range(i):  # bitwise equality, so the copy is exact
        if struct.pack("<d", entries[j]) == bits:
            return _COPY, bytes([j])
        if struct.pack("<d", -entries[j]) == bits:
            return _NEGATED, bytes([j])
    return _LITERAL, bits


def read_anchor_entries(r: _Reader) -> np.ndarray:
    """An anchor sent entry by entry (form 0, and version 1); `DecodeError` if malformed."""
    mask = int.from_bytes(r.take(5, "anchor codes"), "little")
    if mask >> 36:
        raise DecodeError("anchor codes: unused bits set")
    top: list[float] = []
    for i in range(12):
        code = (mask >> (3 * i)) & 7
        if code < _LITERAL:
            top.append(_ANCHOR_CONSTANTS[code])
        elif code == _LITERAL:
            top.append(struct.unpack("<d", r.take(8, "anchor entry"))[0])
        elif code in (_COPY, _NEGATED):
            j = r.u8("anchor reference")
            if j >= i:
                raise DecodeError("anchor entry refers to a later entry")
            top.append(top[j] if code == _COPY else -top[j])
        else:
            raise DecodeError(f"unknown anchor code {code}")
    if not np.isfinite(top).all():
        raise DecodeError("anchor is not finite")
    return np.vstack([np.reshape(top, (3, 4)), [0.0, 0.0, 0.0, 1.0]])
