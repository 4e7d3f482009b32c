"""A small PCD (Point Cloud Library) reader, numpy only: ``DATA ascii`` and ``DATA binary``.

Fields may be of any TYPE/SIZE/COUNT (only x, y, z are kept, and they need COUNT 1); binary
data is little-endian, as PCL writes it. ``DATA binary_compressed`` (LZF) raises a
FileFormatError saying it is unsupported. VIEWPOINT is ignored: points stay in the file's frame
and the loader's poses place them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gmmap.errors import FileFormatError
from gmmap.io.datasets.base import read_point_file

KINDS = {"F": "f", "I": "i", "U": "u"}


@dataclass
class PcdHeader:
    """The header fields a reader needs, and the byte offset where the data starts."""

    fields: list[str]
    sizes: list[int]
    types: list[str]
    counts: list[int]
    points: int
    data: str
    data_offset: int

    def dtype(self) -> np.dtype:
        # Padding fields are all called "_": rename them so the record type stays valid.
        names = [f if f != "_" else f"_pad{i}" for i, f in enumerate(self.fields)]
        parts = zip(names, self.types, self.sizes, self.counts, strict=True)
        return np.dtype([(n, f"<{KINDS[t]}{s}", (c,)) for n, t, s, c in parts])


def read_pcd(path: str | Path) -> np.ndarray:
    """The points of a PCD file as (N, 3) float32 x y z; non-finite points are dropped."""
    path = Path(path)
    data = read_point_file(path)
    header = parse_header(data, path)
    for axis in "xyz":
        if axis not in header.fields:
            raise FileFormatError(f"{path}: no {axis!r} field (FIELDS {' '.join(header.fields)})")
        if header.counts[header.fields.index(axis)] != 1:
            raise FileFormatError(f"{path}: field {axis!r} must have COUNT 1")
    if header.data == "ascii":
        xyz = _ascii_points(data, header, path)
    elif header.data == "binary":
        xyz = _binary_points(data, header, path)
    else:
        raise FileFormatError(
            f"{path}: DATA {header.data} is unsupported (save it as binary or ascii)"
        )
    return xyz[np.isfinite(xyz).all(axis=1)].astype(np.float32, copy=False)


def parse_header(data: bytes, path: Path) -> PcdHeader:
    """Parses the header lines up to and including ``DATA``; every error names the file."""
    keys: dict[str, list[str]] = {}
    offset = 0
    while "DATA" not in keys:
        end = data.find(b"\n", offset)
        if end < 0:
            raise FileFormatError(f"{path}: not a PCD file (no DATA line in the header)")
        words = data[offset:end].decode("ascii", errors="replace").split()
        offset = end + 1
        if words and not words[0].startswith("#"):
            keys[words[0].upper()] = words[1:]
    try:
        return _header(keys, offset)
    except (KeyError, ValueError, IndexError) as exc:
        raise FileFormatError(f"{path}: bad PCD header ({exc!r})") from exc


def _header(keys: dict[str, list[str]], offset: int) -> PcdHeader:
    fields = keys["FIELDS"]
    counts = [int(c) for c in keys.get("COUNT", ["1"] * len(fields))]
    sizes, types = [int(s) for s in keys["SIZE"]], [t.upper() for t in keys["TYPE"]]
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise ValueError("FIELDS, SIZE, TYPE and COUNT differ in length")
    if any(t not in KINDS for t in types):
        raise ValueError(f"TYPE must be F, I or U, got {types}")
    width, height = int(keys["WIDTH"][0]), int(keys.get("HEIGHT", ["1"])[0])
    points = int(keys.get("POINTS", [width * height])[0])
    return PcdHeader(fields, sizes, types, counts, points, keys["DATA"][0].lower(), offset)


def _ascii_points(data: bytes, header: PcdHeader, path: Path) -> np.ndarray:
    width = sum(header.counts)
    tokens = data[header.data_offset :].split()
    if len(tokens) < header.points * width:
        raise FileFormatError(
            f"{path}: truncated: {header.points} points need {header.points * width} values, "
            f"{len(tokens)} present"
        )
    try:
        table = np.array(tokens[: header.points * width], dtype=np.float64).reshape(-1, width)
    except ValueError as exc:
        raise FileFormatError(f"{path}: malformed ascii data ({exc})") from exc
    starts = np.cumsum([0, *header.counts])
    return table[:, [starts[header.fields.index(a)] for a in "xyz"]]


def _binary_points(data: bytes, header: PcdHeader, path: Path) -> np.ndarray:
    dtype = header.dtype()
    need = header.points * dtype.itemsize
    have = len(data) - header.data_offset
    if have < need:
        raise FileFormatError(
            f"{path}: truncated: {header.points} points need {need} bytes, {have} present"
        )
    rows = np.frombuffer(data, dtype=dtype, count=header.points, offset=header.data_offset)
    return np.stack([rows[a][:, 0].astype(np.float64) for a in "xyz"], axis=1)
