"""Typed errors: every bad input gmmap rejects raises one of these (all are ``ValueError``s)."""


class GmmapError(Exception):
    """Base class of gmmap's own errors."""


class InvalidInputError(GmmapError, ValueError):
    """Points or arguments that cannot be used (wrong shape, NaN/inf, out of range)."""


class InvalidGmmError(GmmapError, ValueError):
    """Mixture parameters that do not describe a valid Gaussian mixture."""


class FileFormatError(GmmapError, ValueError):
    """A file that is missing pieces, truncated or not in the expected format."""


class UnknownFormatError(FileFormatError):
    """A path that no dataset loader recognises (the message lists the supported formats)."""


class TopicNotFoundError(InvalidInputError):
    """A bag topic that is absent or of the wrong type; ``available`` maps topics to types."""

    def __init__(self, message: str, available: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.available = dict(available or {})


class DecodeError(GmmapError, ValueError):
    """Bytes that are not a valid gmmap wire message (truncated, corrupt, foreign, hostile)."""


class TransportError(GmmapError):
    """The transport cannot do what was asked (session failed to open, already closed, …)."""


class TransportConfigError(TransportError, ValueError):
    """A bad transport configuration or argument (names, endpoints, sequence numbers, payloads)."""


class RefusedError(GmmapError, ValueError):
    """A message from the fleet that a robot refuses (unsigned, forged, from a revoked or
    unknown member, oversized, over its sender's rate); ``cause`` names why, for counters."""

    def __init__(self, cause: str, message: str) -> None:
        super().__init__(message)
        self.cause = cause


class CredentialsError(GmmapError, ValueError):
    """Fleet credentials that cannot be made or used (`gmmap.fleet.security.credentials`): a bad
    fleet, member or role name, a fleet or member that already exists, a member that is not
    there."""


class CredentialsFileError(CredentialsError, FileFormatError):
    """A credentials file that is missing, truncated or garbage, or a key that does not match
    its certificate."""


class InsecureKeyError(CredentialsError):
    """A private key file that group or others may read: refused, as ssh does (chmod 600)."""


class UntrustedMemberError(CredentialsError):
    """A certificate the fleet's authority did not issue (another CA, forged, tampered), is not
    valid now (expired, not yet valid, stale CRL) or is no member certificate."""


class RevokedMemberError(UntrustedMemberError):
    """A member certificate that the fleet's revocation list (CRL) names."""


class RosMessageError(InvalidInputError):
    """A ROS 2 message, key expression or rmw_zenoh attachment that `gmmap.io.ros2` cannot use:
    truncated or garbage CDR, a wrong type, an unsupported encoding or distro, a malformed key."""
