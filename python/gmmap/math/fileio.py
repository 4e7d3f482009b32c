"""The project's file container: a versioned npz, written atomically, read with typed errors."""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from gmmap.errors import FileFormatError


def save_npz(path: str | os.PathLike, kind: str, version: int, arrays: dict) -> None:
    """Writes ``arrays`` tagged with ``kind`` and ``version``; a crash never leaves half a file."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, format=np.array(kind), version=np.array(version), **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_npz(path: str | os.PathLike, kind: str, version: int) -> dict[str, np.ndarray]:
    """Reads a file written by ``save_npz`` for ``kind``; anything else raises FileFormatError
    (a missing file raises FileNotFoundError)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            found = str(data["format"]) if "format" in data else None
            if found != kind:
                raise FileFormatError(f"{path}: not a {kind} file")
            if int(data["version"]) != version:
                raise FileFormatError(f"{path}: unsupported {kind} version {int(data['version'])}")
            return {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise
    except FileFormatError:
        raise
    except (zipfile.BadZipFile, OSError, EOFError, KeyError, ValueError) as exc:
        raise FileFormatError(f"{path}: unreadable {kind} file ({exc})") from exc
