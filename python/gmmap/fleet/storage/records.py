"""The store's record types (`gmmap.fleet.storage.store`, which exports them) and the validation and
byte encoding of their fields.

Every value is checked before it reaches SQL, so a bad argument raises `InvalidInputError`, not
a SQLite error; matrices are stored as little-endian float64 blobs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gmmap.errors import InvalidInputError
from gmmap.mapping.place import Candidate, Match
from gmmap.math.register import Registration


@dataclass(frozen=True)
class SubmapRecord:
    """One stored message: ``payload`` is the encoded submap, ``own`` whether this robot made it,
    ``received`` the Unix time it entered the store."""

    robot: str
    kind: str
    seq: int
    payload: bytes
    own: bool
    received: float


@dataclass(frozen=True, eq=False)  # numpy fields: element-wise == would not give a bool
class Edge:
    """A registration between two submaps: ``transform`` (4x4) maps the source submap's frame
    into the target's, ``information`` (6x6) weighs it in the pose graph, ``confidence`` is in
    [0, 1], ``status`` is "accepted" or "rejected". ``id`` and ``created`` are set by the store."""

    target_robot: str
    target_seq: int
    source_robot: str
    source_seq: int
    transform: np.ndarray
    information: np.ndarray
    confidence: float
    status: str = "accepted"
    id: int | None = None
    created: float | None = None


def edge_of(m: Match) -> Edge:
    """A judged match as the edge the store keeps."""
    r = m.registration
    return Edge(
        m.candidate.robot,
        m.candidate.seq,
        *m.query,
        r.transform,
        r.information,
        float(min(1.0, max(0.0, r.confidence))),
        "accepted" if m.accepted else "rejected",
    )


def match_of(e: Edge) -> Match:
    """A stored edge as the match it was judged to be (its registration as stored)."""
    reg = Registration(np.asarray(e.transform), e.confidence, np.asarray(e.information), 0, 0.0)
    candidate = Candidate(e.target_robot, e.target_seq, float("nan"))
    return Match((e.source_robot, e.source_seq), candidate, reg, e.status == "accepted")


def _check_text(what: str, value: object) -> str:
    if not isinstance(value, str) or not value or "\x00" in value:
        raise InvalidInputError(f"{what} must be a non-empty string; got {value!r}")
    return value


def _check_seq(what: str, value: object) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InvalidInputError(f"{what} must be an integer ≥ 0; got {value!r}")
    return int(value)


def _check_payload(payload: object) -> bytes:
    if isinstance(payload, (bytes, bytearray, memoryview)):
        return bytes(payload)
    raise InvalidInputError(f"payload must be bytes; got {type(payload).__name__}")


def _matrix_blob(what: str, value: object, n: int) -> bytes:
    matrix = np.asarray(value, dtype=np.float64)
    if matrix.shape != (n, n):
        raise InvalidInputError(f"{what} must be {n}x{n}; got shape {matrix.shape}")
    if not np.all(np.isfinite(matrix)):
        raise InvalidInputError(f"{what} must be finite")
    return matrix.astype("<f8").tobytes()


def _blob_matrix(blob: bytes, n: int) -> np.ndarray:
    return np.frombuffer(blob, dtype="<f8").reshape(n, n).astype(np.float64)


def _submap(row: tuple) -> SubmapRecord:
    robot, kind, seq, payload, own, received = row
    return SubmapRecord(robot, kind, int(seq), bytes(payload), bool(own), float(received))
