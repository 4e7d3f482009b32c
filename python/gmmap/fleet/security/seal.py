"""End-to-end authenticity of what robots exchange: a submap is sealed once, by the robot that
built it, and stays sealed in every store it passes through, so a robot in between that hands
it on (a fetch reply, multi-hop) can neither alter it nor forge one in another's name.

A sealed message is ``0x01 ‖ signature (64 B) ‖ payload``: an Ed25519 signature
(`cryptography`) of

    b"gmmap-seal-v1\\0" ‖ fleet ‖ 0 ‖ robot ‖ 0 ‖ kind ‖ 0 ‖ seq (8 B, big-endian) ‖ payload

by the key of ``robot``'s fleet certificate (`gmmap.fleet.security.credentials`). Fleet, robot, kind
and seq travel in the key expression, not in the envelope: signing them binds the payload to the
name it arrives under, so a valid submap replayed under another robot, sequence number or
fleet fails the check. The prefix keeps these signatures apart from any other use of the key
(the TLS handshake signs with it too, with its own context strings).

`open_sealed` checks the signature before anything parses the payload, and says why it refused
(`Refused.cause`): the robot's counters (`gmmap.fleet.security.guard.Refusals`) count each cause.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey

from gmmap.errors import RefusedError

VERSION = 1
SIGNATURE_BYTES = 64
OVERHEAD = 1 + SIGNATURE_BYTES  # bytes a seal adds to each message
_DOMAIN = b"gmmap-seal-v1\0"

# A signer's public key by robot name, None where the robot is unknown or revoked (the cause
# is the lookup's to say, by raising `RefusedError`).
KeyLookup = Callable[[str], Ed25519PublicKey | None]
Sign = Callable[[bytes], bytes]


def signed_bytes(fleet: str, robot: str, kind: str, seq: int, payload: bytes) -> bytes:
    """What the signature covers (see the module docstring)."""
    names = b"\0".join(x.encode() for x in (fleet, robot, kind))
    return _DOMAIN + names + b"\0" + struct.pack(">Q", seq) + payload


def seal(sign: Sign, fleet: str, robot: str, kind: str, seq: int, payload: bytes) -> bytes:
    """``payload`` sealed by ``sign`` (the robot's Ed25519 key) under its name and number."""
    signature = sign(signed_bytes(fleet, robot, kind, seq, payload))
    if len(signature) != SIGNATURE_BYTES:
        raise ValueError(f"an Ed25519 signature has {SIGNATURE_BYTES} bytes, not {len(signature)}")
    return bytes([VERSION]) + signature + payload


def open_sealed(
    keys: KeyLookup, fleet: str, robot: str, kind: str, seq: int, sealed: bytes
) -> bytes:
    """The payload inside ``sealed`` if ``robot``'s key signed it under this fleet, kind and
    seq; `RefusedError` (cause ``unsigned``, ``unknown_signer`` or ``bad_signature``, or the
    lookup's own) otherwise."""
    if len(sealed) < OVERHEAD or sealed[0] != VERSION:
        raise RefusedError("unsigned", f"{robot}/{kind}/{seq} carries no seal")
    key = keys(robot)
    if key is None:
        raise RefusedError("unknown_signer", f"{robot} is not a member of fleet {fleet!r}")
    signature, payload = sealed[1:OVERHEAD], sealed[OVERHEAD:]
    try:
        key.verify(signature, signed_bytes(fleet, robot, kind, seq, payload))
    except InvalidSignature:
        raise RefusedError(
            "bad_signature", f"{robot}/{kind}/{seq}: the seal does not match"
        ) from None
    return payload
