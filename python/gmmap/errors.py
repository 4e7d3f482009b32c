"""Typed errors: every bad input gmmap rejects raises one of these (all are ``ValueError``s)."""


class GmmapError(Exception):
    """Base class of gmmap's own errors."""


class InvalidInputError(GmmapError, ValueError):
    """Points or arguments that cannot be used (wrong shape, NaN/inf, out of range)."""


class InvalidGmmError(GmmapError, ValueError):
    """Mixture parameters that do not describe a valid Gaussian mixture."""


class FileFormatError(GmmapError, ValueError):
    """A file that is missing pieces, truncated or not in the expected format."""
