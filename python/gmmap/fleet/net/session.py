"""Opening the fleet transport's Zenoh session (`gmmap.fleet.net.transport`): the Zenoh
configuration from `TransportOptions`, and the endpoint to listen on.

The lease is 60 s, not Zenoh's 10 s, with a keep-alive every 15 s (lease / 4, as Zenoh's) when a
session has nothing else to send: on a 500 B/s link Zenoh's defaults would take a fifth of it, and
each keep-alive costs two packets (docs/benchmarks.md, the idle link). An outage shorter than the
lease is a stall the link resumes from, not a reconnection: a new session costs its handshakes and
declarations (about 2.4 kB), and what was in flight when the old one ended crosses again. With a
30 s lease each 30 s partition of benchmarks/links.py ended the sessions: 1,800-2,000 B per
delivered submap there, against about 1,000 B with 60 s. The price is that a robot that died
silently (power lost, out of range for good) is seen gone only after 60 s, and a robot waits for
such a peer anyway (`gmmap.fleet.sharing.holdings`). ``transport.zenoh_options`` can set another.

On a shared channel (``transport.broadcast``) a robot's session only listens, and a second one
opens to the peers when it first fetches (`gmmap.fleet.net.transport`): such a session costs
about 960 B of handshakes and declarations over UDP, and its keep-alives about 70 B per 40 s
(the lease there is 120 s, with a keep-alive every 40 s). Five robots' full mesh put 14.6 kB on
a 500 B/s channel in a demo whose submaps took 48 kB.
"""

from __future__ import annotations

import json
from typing import Any

import zenoh

from gmmap.errors import TransportConfigError, TransportError
from gmmap.fleet.net.keys import free_port
from gmmap.fleet.security.access import acl, tls_entries
from gmmap.options import TransportOptions

LEASE = {"transport/link/tx/lease": 60_000, "transport/link/tx/keep_alive": 4}  # ms; per lease
# Over UDP nothing holds a handshake until the link is up: one sent while it is down is lost,
# and Zenoh would wait 10 s for its answer, then back off to 4 s between tries. A meeting
# may last seconds: try every second, each try given a second.
DATAGRAM_RETRY = {
    "transport/unicast/open_timeout": 1_000,
    "connect/retry": {"period_init_ms": 1_000, "period_max_ms": 1_000, "period_increase_factor": 1},
}


# On a shared channel every robot hears the others' broadcasts and dials the peers it lists:
# Zenoh's gossip would only repeat locators on the air. Three robots' idle sessions over UDP cost
# 3,165 B with gossip and 2,354 B without; five robots' 13,066 B and 7,265 B.
NO_GOSSIP = {"scouting/gossip/enabled": False}
SHARED_LEASE = {"transport/link/tx/lease": 120_000, "transport/link/tx/keep_alive": 3}

# On a slow shared channel one full packet takes seconds (3 s at 500 B/s) and a few wait ahead
# of a handshake: Zenoh's 10 s to open a session ran out over and over at 500 B/s (48 TCP
# connections opened and dropped in one 3-robot demo, a third of its air time). Allow the
# time ~15 kB of queue would take to drain, never less than Zenoh's 10 s.
HANDSHAKE_QUEUE_BYTES = 15_000


def handshake_timeout_ms(channel_rate: float | None) -> int:
    """Zenoh's time to open (and accept) a unicast session on a channel of ``channel_rate``."""
    if channel_rate is None:
        return 10_000
    return max(10_000, round(1000 * HANDSHAKE_QUEUE_BYTES / channel_rate))


def zenoh_config(
    options: TransportOptions, listen_endpoints: tuple[str, ...], credentials=None
) -> zenoh.Config:
    """The Zenoh configuration of a robot's session, secured where ``credentials`` are given
    (`gmmap.fleet.security.access`); `TransportConfigError` for a bad option."""
    cfg = zenoh.Config()
    entries: dict[str, Any] = {
        "mode": options.mode,
        "listen/endpoints": list(listen_endpoints),
        "connect/endpoints": list(options.connect),
        "scouting/multicast/enabled": options.multicast_scouting,
        **LEASE,
        **(DATAGRAM_RETRY if options.protocol == "udp" else {}),
        **({**NO_GOSSIP, **SHARED_LEASE} if options.broadcast is not None else {}),
    }
    if options.channel_rate is not None:
        timeout = handshake_timeout_ms(options.channel_rate)
        entries["transport/unicast/open_timeout"] = timeout
        entries["transport/unicast/accept_timeout"] = timeout
    if credentials is not None:
        plain = [e for e in (*listen_endpoints, *options.connect) if not e.startswith("tls/")]
        if plain:
            raise TransportConfigError(f"a secured robot's endpoints are tls/…; got {plain}")
        c = credentials
        entries.update(tls_entries(str(c.ca_path), str(c.cert_path), str(c.tls_key_path)))
        entries["access_control"] = acl(c.fleet, roster(c))
    entries.update(options.zenoh_options)
    for key, value in entries.items():
        try:
            cfg.insert_json5(key, json.dumps(value))
        except (zenoh.ZError, TypeError, ValueError) as err:
            raise TransportConfigError(f"bad Zenoh option {key}={value!r}: {err}") from err
    return cfg


def roster(credentials) -> dict[str, str]:
    """Member name → role: the members a robot knows (revoked ones left out) and itself."""
    members = {n: m.role for n in credentials.roster.names() if (m := credentials.roster.get(n))}
    return {**members, credentials.name: credentials.role}


def open_session(
    robot: str, options: TransportOptions, credentials=None
) -> tuple[zenoh.Session, tuple[str, ...]]:
    """The open session of ``robot`` and the endpoints it listens on; `TransportError` when
    Zenoh cannot open it."""
    # A port we pick ourselves may be taken between free_port() and Zenoh's bind: retry.
    attempts = 3 if options.listen is None and options.port == 0 else 1
    if credentials is not None and options.protocol == "udp":
        raise TransportConfigError(
            "a secured robot's links are TLS over TCP: transport.protocol udp cannot carry them"
        )
    if credentials is not None and options.broadcast is not None:
        raise TransportConfigError(
            "a secured robot's links are TLS: the broadcast group (transport.broadcast) has none"
        )
    protocol = "tls" if credentials is not None else options.link_protocol
    for attempt in range(attempts):
        listen_endpoints = (
            options.listen
            if options.listen is not None  # () listens nowhere (connects only)
            else (f"{protocol}/127.0.0.1:{options.port or free_port()}",)
        )
        try:
            config = zenoh_config(options, listen_endpoints, credentials)
            return zenoh.open(config), listen_endpoints
        except zenoh.ZError as err:
            if attempt + 1 == attempts:
                raise TransportError(
                    f"cannot open the Zenoh session of robot {robot!r} (listen "
                    f"{list(listen_endpoints)}, connect "
                    f"{list(options.connect)}): "
                    f"{err}"
                ) from err
    raise AssertionError("unreachable")


def open_router(port: int, host: str = "127.0.0.1", protocol: str = "tcp") -> zenoh.Session:
    """A Zenoh session in router mode listening on ``protocol/host:port``: robots in client
    mode connect to it and it routes between them."""
    endpoint = f"{protocol}/{host}:{port}"
    cfg = zenoh.Config()
    for key, value in (("mode", "router"), ("listen/endpoints", [endpoint]),
                       ("scouting/multicast/enabled", False), *LEASE.items()):  # fmt: skip
        cfg.insert_json5(key, json.dumps(value))
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as err:
        raise TransportError(f"cannot open a Zenoh router on {endpoint}: {err}") from err
