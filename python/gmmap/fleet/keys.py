"""Key expressions of the fleet transport (`gmmap.fleet.transport`, whose module docstring lists
them): building and parsing them, checking a sequence number, and `free_port` for the default
listen endpoint.
"""

from __future__ import annotations

import random
import socket

from gmmap.errors import TransportConfigError
from gmmap.names import NAME_RE

PREFIX = "gmmap"


def check_seq(seq: object, what: str = "seq") -> int:
    # bool is an int subclass; True as a sequence number is a bug, not a 1.
    if isinstance(seq, bool) or not isinstance(seq, int) or seq < 0:
        raise TransportConfigError(f"{what} must be an integer ≥ 0; got {seq!r}")
    return seq


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (the OS picks it; another process may still race)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((host, 0))
        return int(sock.getsockname()[1])


def listen_port(host: str = "127.0.0.1", low: int = 20_000, high: int = 32_768) -> int:
    """A free TCP port below Linux's ephemeral range (32768 up), for another process to bind
    later: no port the OS numbers meanwhile (a listener on port 0, an outgoing connection) can
    take it first. Another process picking the same way may still race."""
    rng = random.SystemRandom()
    for _ in range(200):
        port = rng.randrange(low, high)
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            try:
                sock.bind((host, port))
            except OSError:
                continue
        return port
    return free_port(host)


def data_key(fleet: str, robot: str, kind: str, seq: int) -> str:
    """The key expression of one message: ``gmmap/<fleet>/<robot>/<kind>/<seq>``."""
    return f"{PREFIX}/{fleet}/{robot}/{kind}/{seq}"


def alive_key(fleet: str, robot: str) -> str:
    """The liveliness token of a robot: ``gmmap/<fleet>/<robot>``."""
    return f"{PREFIX}/{fleet}/{robot}"


def parse_data_key(key: str) -> tuple[str, str, str, int] | None:
    """``(fleet, robot, kind, seq)`` of a message key expression, or None when malformed."""
    parts = str(key).split("/")
    if len(parts) != 5 or parts[0] != PREFIX:
        return None
    _, fleet, robot, kind, seq_text = parts
    if not all(NAME_RE.fullmatch(name) for name in (fleet, robot, kind)):
        return None
    # Canonical decimal only: "007" or "+7" would give two keys for one message.
    if not seq_text.isdigit() or str(int(seq_text)) != seq_text:
        return None
    return fleet, robot, kind, int(seq_text)


def parse_fetch(key: str, since: str | None) -> tuple[str, str, str, int] | None:
    """``(fleet, robot, kind, since)`` of a fetch query ``gmmap/<fleet>/<robot>/<kind>/*``;
    robot ``*`` for `fetch_unknown`."""
    parts = key.split("/")
    if len(parts) != 5 or parts[0] != PREFIX or parts[4] != "*":
        return None
    _, fleet, robot, kind, _ = parts
    names = (fleet, kind) if robot == "*" else (fleet, robot, kind)
    if not all(NAME_RE.fullmatch(name) for name in names):
        return None
    since_text = "0" if since is None else since
    if not since_text.isdigit():
        return None
    return fleet, robot, kind, int(since_text)


def as_payload(payload: object) -> bytes:
    """A message's payload as bytes; `TransportConfigError` for anything not bytes-like."""
    if isinstance(payload, bytes):
        return payload
    if isinstance(payload, (bytearray, memoryview)):
        return bytes(payload)
    raise TransportConfigError(f"payload must be bytes; got {type(payload).__name__}")
