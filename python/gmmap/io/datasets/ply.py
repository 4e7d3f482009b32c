"""A small PLY point reader (numpy only): ASCII and binary, vertex x y z; other data skipped.
``write_ply`` writes the one layout the simulator needs: binary little-endian float32 x y z.

Supports ``format ascii``, ``binary_little_endian`` and ``binary_big_endian``; the vertex
element may hold any scalar properties (only x, y, z are kept) and may follow other elements
(faces etc.) in ASCII files, or scalar-only elements in binary ones. List properties before or
inside the vertex element of a binary file raise FileFormatError: skipping them would mean
parsing every list.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.io.datasets.base import read_point_file

TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}


@dataclass
class PlyElement:
    """One ``element`` of the header: its rows and (name, numpy type or "list") properties."""

    name: str
    count: int
    properties: list[tuple[str, str]] = field(default_factory=list)

    def dtype(self, order: str) -> np.dtype:
        return np.dtype([(n, order + t) for n, t in self.properties])

    @property
    def has_lists(self) -> bool:
        return any(t == "list" for _, t in self.properties)


@dataclass
class PlyHeader:
    """The parsed header and the byte offset where the data starts."""

    format: str
    elements: list[PlyElement]
    data_offset: int


def read_ply(path: str | Path) -> np.ndarray:
    """The vertices of a PLY file as (N, 3) float32 x y z; non-finite vertices are dropped."""
    path = Path(path)
    data = read_point_file(path)
    header = parse_header(data, path)
    names = [e.name for e in header.elements]
    if "vertex" not in names:
        raise FileFormatError(f"{path}: no 'element vertex' in the header")
    vertex = header.elements[names.index("vertex")]
    missing = {"x", "y", "z"} - {n for n, _ in vertex.properties}
    if missing:
        raise FileFormatError(f"{path}: vertex has no {', '.join(sorted(missing))} property")
    if header.format == "ascii":
        xyz = _ascii_vertices(data, header, path)
    else:
        xyz = _binary_vertices(data, header, path)
    return xyz[np.isfinite(xyz).all(axis=1)].astype(np.float32, copy=False)


def write_ply(path: str | Path, points: np.ndarray, comment: str = "written by gmmap") -> None:
    """Writes (N, 3) points as a binary little-endian PLY of float32 x y z (exact for float32
    input: what ``read_ply`` returns is bit-identical)."""
    xyz = np.asarray(points)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InvalidInputError(f"points must be (N, 3), got shape {xyz.shape}")
    header = (
        f"ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {len(xyz)}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    Path(path).write_bytes(header.encode("ascii") + xyz.astype("<f4").tobytes())


def parse_header(data: bytes, path: Path) -> PlyHeader:
    """Parses ``ply`` … ``end_header``; every error names the file."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise FileFormatError(f"{path}: not a PLY file (no 'ply' … 'end_header' header)")
    newline = data.find(b"\n", end)
    offset = len(data) if newline < 0 else newline + 1
    fmt, elements = None, []
    for line in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append(PlyElement(words[1], int(words[2])))
            elif words[0] == "property":
                elements[-1].properties.append(_property(words))
        except (IndexError, KeyError, ValueError) as exc:
            raise FileFormatError(f"{path}: bad header line {line!r}") from exc
    if fmt not in FORMATS:
        raise FileFormatError(f"{path}: unsupported PLY format {fmt!r} (ascii or binary)")
    return PlyHeader(fmt, elements, offset)


def _property(words: list[str]) -> tuple[str, str]:
    if words[1] == "list":
        if words[2] not in TYPES or words[3] not in TYPES:
            raise KeyError(f"unknown list types {words[2]!r}, {words[3]!r}")
        return words[4], "list"
    return words[2], TYPES[words[1]]


def _ascii_vertices(data: bytes, header: PlyHeader, path: Path) -> np.ndarray:
    lines = [ln for ln in data[header.data_offset :].split(b"\n") if ln.strip()]
    start = 0
    for element in header.elements:
        if element.name == "vertex":
            break
        start += element.count  # one line per row in ASCII, lists included
    vertex = next(e for e in header.elements if e.name == "vertex")
    rows = lines[start : start + vertex.count]
    if len(rows) < vertex.count:
        raise FileFormatError(
            f"{path}: truncated: {len(rows)} of {vertex.count} vertex lines present"
        )
    if vertex.has_lists:
        raise FileFormatError(f"{path}: list properties in the vertex element are unsupported")
    try:
        values = np.array(b" ".join(rows).split(), dtype=np.float64)
        table = values.reshape(vertex.count, len(vertex.properties))
    except ValueError as exc:
        raise FileFormatError(f"{path}: malformed vertex lines ({exc})") from exc
    columns = [n for n, _ in vertex.properties]
    return table[:, [columns.index(c) for c in "xyz"]]


def _binary_vertices(data: bytes, header: PlyHeader, path: Path) -> np.ndarray:
    order, offset = FORMATS[header.format], header.data_offset
    for element in header.elements:
        if element.has_lists:
            raise FileFormatError(
                f"{path}: binary element {element.name!r} has list properties before the "
                "vertices end (unsupported)"
            )
        dtype = element.dtype(order)
        if element.name == "vertex":
            need = element.count * dtype.itemsize
            if len(data) - offset < need:
                raise FileFormatError(
                    f"{path}: truncated: {element.count} vertices need {need} bytes, "
                    f"{len(data) - offset} present"
                )
            rows = np.frombuffer(data, dtype=dtype, count=element.count, offset=offset)
            return np.stack([rows[c].astype(np.float64) for c in "xyz"], axis=1)
        offset += element.count * dtype.itemsize
    raise AssertionError("unreachable: the caller checked that a vertex element exists")
