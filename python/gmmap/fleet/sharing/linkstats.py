"""A robot's byte counts, told only when asked: how a station shows what each robot sends and
receives per link without the robots publishing anything more.

A robot answers a fetch of its own kind ``links`` (``gmmap/<fleet>/<robot>/links/*``) with one
message: its transport's payload bytes sent and received, by peer, as JSON, numbered from the
clock (ms) and sealed like its submaps. Nothing is stored and nothing is sent unasked; a
station's query every few seconds costs each robot one small reply.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable

KIND = "links"
MAX_BYTES = 16_384


def _bytes(by_kind: dict) -> int:
    return int(sum(k.get("payload_bytes", 0) + k.get("key_bytes", 0) for k in by_kind.values()))


def counts(stats: dict, robot: str) -> dict:
    """What a robot tells: bytes sent (its own and relayed, by whose) and received, by robot,
    from its transport's ``stats()``."""
    told = {d: {r: _bytes(k) for r, k in sorted(stats.get(d, {}).items())}
            for d in ("sent", "received")}  # fmt: skip
    return {"robot": robot, **told}


def encode(stats: dict, robot: str) -> bytes:
    """`counts` as the JSON a robot answers with."""
    return json.dumps(counts(stats, robot), separators=(",", ":")).encode()


def decode(payload: bytes) -> dict | None:
    """The counts in ``payload``, or None when it is not such a message."""
    if len(payload) > MAX_BYTES:
        return None
    try:
        told = json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None
    ok = isinstance(told, dict) and all(isinstance(told.get(d), dict) for d in ("sent", "received"))
    if not ok or not all(
        isinstance(v, int) for d in ("sent", "received") for v in told[d].values()
    ):
        return None
    return told


def provider(node) -> Callable[[str, str, int], list[tuple[int, bytes]]]:
    """``node``'s fetch provider (`Transport.serve`): its store's, and for ``links`` of its own
    its counts now. Its own submaps still waiting in its outbox for their bundle leave now, to
    every peer, instead of in the answer: else they would cross twice."""
    store = node.store.fetch_provider

    def provide(robot: str, kind: str, since: int) -> list[tuple[int, bytes]]:
        if kind != KIND:
            held = node.outbox.held(kind) if robot == node.robot else set()
            if held:
                node.outbox.now()
            return [(seq, p) for seq, p in store(robot, kind, since) if seq not in held]
        if robot != node.robot:
            return []
        seq = time.time_ns() // 1_000_000
        told = encode(node.transport.stats(), node.robot)
        return [(seq, node.door.seal(node.robot, KIND, seq, told))]

    return provide
