"""gmmap: communication-efficient multi-robot mapping with Gaussian Mixture Model submaps."""

from importlib.metadata import PackageNotFoundError, version

from gmmap.config import Config, load_config
from gmmap.errors import (
    DecodeError,
    FileFormatError,
    GmmapError,
    InvalidGmmError,
    InvalidInputError,
)
from gmmap.fleet.wire.codec import decode, encode
from gmmap.math.em import fit_gmm
from gmmap.math.gmm import FitInfo, Gmm
from gmmap.math.points import voxel_filter
from gmmap.math.register import Registration, register
from gmmap.math.select import SelectOptions, select_components

try:
    __version__ = version("gmmap")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = [
    "Config",
    "DecodeError",
    "FileFormatError",
    "FitInfo",
    "Gmm",
    "GmmapError",
    "InvalidGmmError",
    "InvalidInputError",
    "Registration",
    "SelectOptions",
    "__version__",
    "decode",
    "encode",
    "fit_gmm",
    "load_config",
    "register",
    "select_components",
    "voxel_filter",
]
