"""Sealed messages (`gmmap.fleet.security.seal`) and the door every arriving message passes
(`gmmap.fleet.security.door`, `gmmap.fleet.security.guard`)."""

import pytest
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

from gmmap.errors import RefusedError
from gmmap.fleet.security.guard import MAX_SENDERS, OTHERS, Guard
from gmmap.fleet.security.seal import OVERHEAD, open_sealed, seal
from gmmap.fleet_options import SecurityOptions

KEYS = {name: Ed25519PrivateKey.generate() for name in ("a", "b")}


def lookup(name):
    key = KEYS.get(name)
    return None if key is None else key.public_key()


def sealed(robot="a", kind="submap", seq=3, payload=b"submap bytes", fleet="f"):
    return seal(KEYS[robot].sign, fleet, robot, kind, seq, payload)


def cause(robot, kind, seq, data, fleet="f"):
    with pytest.raises(RefusedError) as err:
        open_sealed(lookup, fleet, robot, kind, seq, data)
    return err.value.cause


def test_a_sealed_message_opens_under_its_own_name_only() -> None:
    data = sealed()
    assert len(data) == len(b"submap bytes") + OVERHEAD
    assert open_sealed(lookup, "f", "a", "submap", 3, data) == b"submap bytes"
    assert cause("a", "submap", 4, data) == "bad_signature"  # replayed under another seq
    assert cause("a", "have", 3, data) == "bad_signature"  # or another kind
    assert cause("a", "submap", 3, data, fleet="g") == "bad_signature"  # or fleet
    assert cause("b", "submap", 3, data) == "bad_signature"  # b cannot pass it off as its own


def test_an_altered_forged_or_unsigned_message_is_refused() -> None:
    data = bytearray(sealed())
    data[-1] ^= 1  # a relay changed one bit of the payload
    assert cause("a", "submap", 3, bytes(data)) == "bad_signature"
    forged = seal(KEYS["b"].sign, "f", "a", "submap", 3, b"submap bytes")  # b signs as a
    assert cause("a", "submap", 3, forged) == "bad_signature"
    assert cause("a", "submap", 3, b"submap bytes") == "unsigned"
    assert cause("a", "submap", 3, b"") == "unsigned"
    assert cause("c", "submap", 3, sealed()) == "unknown_signer"


def test_the_guard_caps_size_and_rate_per_sender_with_bounded_memory() -> None:
    now = [0.0]
    guard = Guard(SecurityOptions(max_bytes=1024, rate=2.0, burst=3), clock=lambda: now[0])
    assert not guard.admit("a", 1025)
    assert [guard.admit("a", 10) for _ in range(4)] == [True, True, True, False]
    assert guard.admit("b", 10)  # each sender has its own bucket
    now[0] = 0.5  # one token back
    assert guard.admit("a", 10) and not guard.admit("a", 10)
    assert guard.refusals.snapshot() == {"a": {"oversize": 1, "rate": 2}}
    for i in range(3 * MAX_SENDERS):  # a flood under made-up names
        guard.admit(f"x{i}", 2000)
    counts = guard.refusals.snapshot()
    assert len(counts) == MAX_SENDERS + 1 and counts[OTHERS]["oversize"] > MAX_SENDERS
