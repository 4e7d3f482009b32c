"""Key expressions of the fleet transport (`gmmap.fleet.net.transport`, whose module docstring lists
them): building and parsing them, checking a sequence number, and `free_port` for the default
listen endpoint.
"""

from __future__ import annotations

import random
import socket
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from gmmap.errors import TransportConfigError
from gmmap.names import NAME_RE, PREFIX

VIA = "via"  # in a fetch's key, before the robot asked to answer it


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


def fetch_key(fleet: str, robot: str, kind: str, via: str) -> str:
    """A fetch query's key expression, ``gmmap/<fleet>/<robot>/<kind>/*/via/<via>``: it asks
    the robot named ``via`` (``robot`` itself, one robot in between, or ``*``: every peer) for
    ``robot``'s messages, and reaches only that robot's queryable (`queryable_key`)."""
    return f"{PREFIX}/{fleet}/{robot}/{kind}/*/{VIA}/{via}"


def fetch_selector(
    fleet: str,
    robot: str,
    kind: str,
    via: str,
    since: int = 0,
    held: Iterable[int] = (),
    skip: Iterable[str] = (),
    air: bool = False,
) -> str:
    """A fetch query's `fetch_key` with its parameters (`parse_fetch`); ``air``: the asker
    hears the shared channel, where an answer may come instead."""
    params = [f"since={since}"]
    if ranges := seq_ranges(s for s in held if s > since):
        params.append(f"held={ranges}")
    if names := ",".join(sorted(skip)):
        params.append(f"skip={names}")
    if air:
        params.append("air=1")
    return f"{fetch_key(fleet, robot, kind, via)}?{';'.join(params)}"


def queryable_key(fleet: str, robot: str) -> str:
    """The fetches ``robot`` answers: those that name it, or every peer."""
    return f"{PREFIX}/{fleet}/*/*/*/{VIA}/{robot}"


def reply_key(fleet: str, robot: str, kind: str, seq: int, via: str) -> str:
    """A fetch reply's key: the message's, and the robot that answered."""
    return f"{data_key(fleet, robot, kind, seq)}/{VIA}/{via}"


def parse_reply_key(key: str) -> tuple[str, str, str, int] | None:
    """`parse_data_key` of a fetch reply's key (`reply_key`)."""
    parts = str(key).split("/")
    if len(parts) != 7 or parts[5] != VIA or not NAME_RE.fullmatch(parts[6]):
        return None
    return parse_data_key("/".join(parts[:5]))


@dataclass(frozen=True)
class FetchRequest:
    """A fetch query (`fetch_key`): ``robot``'s messages of ``kind`` from ``since`` on, but
    those in the ``held`` ranges; robot ``*`` (`fetch_unknown`): every robot held but ``skip``."""

    fleet: str
    robot: str
    kind: str
    since: int
    held: tuple[tuple[int, int], ...] = ()
    skip: frozenset[str] = frozenset()
    air: bool = False  # the asker hears the shared channel (`fetch_selector`)

    def wants(self, seq: object) -> bool:
        return (
            isinstance(seq, int)
            and seq >= self.since
            and not any(a <= seq <= b for a, b in self.held)
        )


def parse_fetch(key: str, parameters: Mapping[str, str]) -> FetchRequest | None:
    """The request of a fetch query's key and parameters (``since``, ``held``, ``skip``,
    ``air``); None where malformed."""
    parts = key.split("/")
    if len(parts) != 7 or parts[0] != PREFIX or parts[4] != "*" or parts[5] != VIA:
        return None
    _, fleet, robot, kind = parts[:4]
    names = (fleet, kind) if robot == "*" else (fleet, robot, kind)
    if not all(NAME_RE.fullmatch(name) for name in names):
        return None
    since, held = parameters.get("since") or "0", parse_seq_ranges(parameters.get("held"))
    if not since.isdigit() or held is None:
        return None
    skip = frozenset((parameters.get("skip") or "").split(",")) - {""}
    air = parameters.get("air") == "1"
    return FetchRequest(fleet, robot, kind, int(since), tuple(held), skip, air)


MAX_RANGES = 256  # in a fetch's ``held`` parameter: a longer list is refused


def seq_ranges(seqs: Iterable[int]) -> str:
    """Sequence numbers as ranges, ``0-3,7,9-10``: what a fetch already holds, in a few bytes."""
    out: list[str] = []
    run: list[int] = []
    for seq in sorted(set(seqs)):
        if run and seq == run[-1] + 1:
            run[-1] = seq
            continue
        if run:
            out.append(_range(*run))
        run = [seq, seq]
    if run:
        out.append(_range(*run))
    return ",".join(out)


def _range(first: int, last: int) -> str:
    return str(first) if first == last else f"{first}-{last}"


def parse_seq_ranges(text: str | None) -> list[tuple[int, int]] | None:
    """The inclusive ranges of `seq_ranges` (``None`` or empty: none); None where malformed or
    longer than MAX_RANGES."""
    if not text:
        return []
    parts = text.split(",")
    if len(parts) > MAX_RANGES:
        return None
    out = []
    for part in parts:
        first, dash, last = part.partition("-")
        last = last if dash else first
        if not (first.isdigit() and last.isdigit() and len(first) < 20 and len(last) < 20):
            return None
        if int(first) > int(last):
            return None
        out.append((int(first), int(last)))
    return out


def as_payload(payload: object) -> bytes:
    """A message's payload as bytes; `TransportConfigError` for anything not bytes-like."""
    if isinstance(payload, bytes):
        return payload
    if isinstance(payload, (bytearray, memoryview)):
        return bytes(payload)
    raise TransportConfigError(f"payload must be bytes; got {type(payload).__name__}")
