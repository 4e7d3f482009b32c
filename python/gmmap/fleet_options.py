"""The fleet's sections of the configuration (`gmmap.config`, re-exported by `gmmap.options`):
a robot's transport, its node, its security, and the demo's emulated links. Like
`gmmap.options`, nothing heavy is imported here, and each field's meaning is its ``#:`` comment.
"""

from __future__ import annotations

import ipaddress
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from gmmap.errors import InvalidInputError, TransportConfigError
from gmmap.names import MODES, check_endpoint, check_name

TOPOLOGIES = ("mesh", "chain", "router")
PROTOCOLS = ("tcp", "udp")


@dataclass(frozen=True)
class TransportOptions:
    """Where a robot's Zenoh session listens and whom it connects to (`gmmap.fleet.net.transport`).

    ``listen`` None means one loopback endpoint ``<protocol>/127.0.0.1:<port>``; ``port`` 0 picks
    a free ephemeral port when the transport opens. ``protocol``: ``tcp`` (None: TCP, or TLS in a
    secured fleet) or ``udp``, datagrams: no ACKs, handshakes or retransmission stalls, for
    links that come and go (what a datagram lost, fetches recover; no TLS over it). Multicast
    scouting is off by default so that fleets on one network only meet through ``connect``
    endpoints (Zenoh's gossip still lets peers of peers find each other, except on a shared
    channel: see ``broadcast``). ``zenoh_options`` are raw Zenoh configuration entries
    (``{"transport/link/tx/lease": 5000}``) applied last.

    ``broadcast``: on one radio channel shared by the fleet, a UDP multicast group
    (``udp/224.0.0.224:7447``, ``#iface=<name>`` to pick the interface, else the route to the
    group picks it; a loopback needs ``ip link set lo multicast on``): submaps and adverts go on
    the air once for every robot in range (`gmmap.fleet.net.air`), and presence is what is
    heard there (greetings, `gmmap.fleet.net.transport`). A robot opens unicast sessions only
    to fetch what it missed, to the peers listed in ``connect``, Zenoh's gossip off. Not in a
    secured fleet: the group has no TLS. ``channel_rate``: the shared channel's bytes/s, all
    robots together; each robot then sends (submaps, adverts and fetch answers) within an
    equal share of it over the robots present and, with ``broadcast``, those heard lately
    (`gmmap.fleet.net.outbox.air_share`), and within ``robot.budget`` where that is lower.
    Without it, datagrams on a saturated channel are dropped (broadcast has no congestion
    control).
    """

    #: Zenoh listen endpoints; null: one loopback endpoint on port
    listen: tuple[str, ...] | None = None
    port: int = 0  #: Port of the loopback listen endpoint; 0: a free one
    connect: tuple[str, ...] = ()  #: Zenoh endpoints of other robots to connect to
    mode: str = "peer"  #: Zenoh mode: peer or client
    #: tcp or udp (datagrams, no retransmission); null: TCP, or TLS when secured
    protocol: str | None = None
    #: Zenoh multicast scouting: meet peers on the network without connect
    multicast_scouting: bool = False
    fetch_timeout: float = 2.0  #: Seconds a query to peers waits for answers
    #: UDP multicast group of a shared channel (udp/224.0.0.224:7447); null: unicast links only
    broadcast: str | None = None
    #: Bytes/s of the radio channel all robots share; each sends within its share. null: none
    channel_rate: float | None = None
    #: Raw Zenoh configuration entries, applied last
    zenoh_options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise TransportConfigError(f"mode must be one of {MODES}; got {self.mode!r}")
        if self.protocol is not None and self.protocol not in PROTOCOLS:
            raise TransportConfigError(
                f"protocol must be one of {PROTOCOLS} or null; got {self.protocol!r}"
            )
        if isinstance(self.port, bool) or not isinstance(self.port, int):
            raise TransportConfigError(f"port must be an integer; got {self.port!r}")
        if not 0 <= self.port <= 65535:
            raise TransportConfigError(f"port must be in 0..65535; got {self.port}")
        # Accept any sequence of strings but store tuples: the options stay immutable.
        if self.listen is not None:
            object.__setattr__(self, "listen", _endpoints("listen", self.listen))
        object.__setattr__(self, "connect", _endpoints("connect", self.connect))
        if self.mode == "client" and not self.connect:
            raise TransportConfigError("mode 'client' needs at least one connect endpoint")
        if not isinstance(self.fetch_timeout, (int, float)) or not self.fetch_timeout > 0:
            raise TransportConfigError(f"fetch_timeout must be > 0 s; got {self.fetch_timeout!r}")
        if not isinstance(self.zenoh_options, Mapping):
            raise TransportConfigError("zenoh_options must be a mapping of key to value")
        if self.broadcast is not None:
            multicast_group(self.broadcast)
        rate = self.channel_rate
        if rate is not None and not (
            isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0
        ):
            raise TransportConfigError(f"channel_rate must be > 0 bytes/s or null; got {rate!r}")

    @property
    def link_protocol(self) -> str:
        """The protocol of an unsecured robot's links: ``protocol``, TCP where unset."""
        return self.protocol or "tcp"


def multicast_group(endpoint: str) -> tuple[str, int, str | None]:
    """(address, port, interface name or None) of ``udp/<IPv4 multicast address>:<port>
    [#iface=<name>]``; `TransportConfigError` for anything else."""
    locator, _, suffix = endpoint.partition("#") if isinstance(endpoint, str) else ("", "", "")
    proto, _, address = locator.partition("/")
    host, _, port = address.rpartition(":")
    iface = suffix.removeprefix("iface=")
    try:
        ok = proto == "udp" and ipaddress.IPv4Address(host).is_multicast and 0 < int(port) < 65536
        ok = ok and (not suffix or (suffix.startswith("iface=") and bool(iface)))
    except ValueError:
        ok = False
    if not ok:
        raise TransportConfigError(
            "broadcast must be udp/<IPv4 multicast address>:<port>[#iface=<name>] "
            f"(udp/224.0.0.224:7447); got {endpoint!r}"
        )
    return host, int(port), iface or None


def _endpoints(what: str, endpoints: Sequence[str] | str) -> tuple[str, ...]:
    if isinstance(endpoints, str):
        raise TransportConfigError(f"{what} must be a list of endpoints, not one string")
    return tuple(check_endpoint(e, listen=what == "listen") for e in endpoints)


DEFAULT_BUNDLE = 3  # own submaps sent together (`RobotOptions.bundle`)


@dataclass(frozen=True)
class RobotOptions:
    """One robot node (`gmmap.fleet.node.robot`). ``store`` None: a temporary store (lost on exit).
    ``wait_for``: peers to wait for (up to ``wait_timeout`` s) before consuming frames;
    ``linger``: seconds it keeps receiving, matching and optimising after its frames end;
    then it stays until the peers in reach hold what it holds and it holds what they hold, and
    every robot it knows of is done mapping and its last submap has arrived, or until
    ``deadline`` seconds after its frames (`gmmap.fleet.node.robot.RobotNode.linger`).
    ``rejudge``: at the end, every pair held is judged again in one call, so that the final
    maps are an offline merge's of the same submaps, whatever order they arrived in.
    ``budget``: bytes/s of payload and keys the robot puts on each link, submaps, adverts and
    fetch answers together, sent in priority order (`gmmap.fleet.net.outbox`); None: no cap.
    ``bundle``: own submaps sent together, in one Zenoh batch that shares its packets' headers
    and ACKs; a submap waits at most ``bundle_wait`` s for the others, and none waits once the
    frames end or an advert is due (1: each at once). None: ``DEFAULT_BUNDLE``, or 1 where
    `gmmap demo` emulates links that come and go: a passing contact cannot wait."""

    name: str = "robot"  #: This robot's name (unique in the fleet)
    fleet: str = "gmmap"  #: The fleet's name: robots of other fleets are ignored
    store: str | None = None  #: The robot's SQLite store; null: a temporary one, lost on exit
    wait_for: tuple[str, ...] = ()  #: Peers to wait for before consuming frames
    wait_timeout: float = 30.0  #: Seconds to wait for them, at most
    linger: float = 5.0  #: Seconds it keeps receiving, matching and optimising after its frames end
    deadline: float = 120.0  #: Latest end, seconds after its frames, peers complete or not
    #: At the end, judge every held pair again in one call, as an offline merge
    rejudge: bool = True
    #: Bytes/s of payload and keys per link, in priority order; null: no cap
    budget: float | None = None
    #: Own submaps sent together; null: 3, or 1 on the demo's come-and-go links
    bundle: int | None = None
    bundle_wait: float = 8.0  #: Seconds a submap waits at most for the rest of its bundle

    @property
    def bundle_size(self) -> int:
        """``bundle``, or its default where None."""
        return self.bundle or DEFAULT_BUNDLE

    def __post_init__(self) -> None:
        if self.bundle is not None and not (isinstance(self.bundle, int) and self.bundle >= 1):
            raise InvalidInputError(f"robot.bundle must be an integer >= 1, got {self.bundle!r}")
        if not (math.isfinite(self.bundle_wait) and self.bundle_wait >= 0):
            raise InvalidInputError(f"robot.bundle_wait must be >= 0 s, got {self.bundle_wait}")
        if self.budget is not None and not (math.isfinite(self.budget) and self.budget > 0):
            raise InvalidInputError(f"robot.budget must be > 0 bytes/s or null, got {self.budget}")
        check_name("robot.name", self.name)
        check_name("robot.fleet", self.fleet)
        for peer in self.wait_for:
            check_name("robot.wait_for", peer)
        if not (self.wait_timeout >= 0 and self.linger >= 0 and self.deadline >= 0):
            raise InvalidInputError("robot.wait_timeout, linger and deadline must be >= 0")


@dataclass(frozen=True)
class LinkOptions:
    """Emulated links between the demo's robots (`gmmap.eval.links`).

    With ``emulate`` (or any shaping set) each pair of robots talks through its own relay,
    which counts every byte Zenoh puts on the link and, in both directions: caps it at
    ``rate`` bytes/s (None: no cap), delays it by ``delay_s``, stalls a chunk for ``stall_s``
    with probability ``loss`` (TCP's retransmission after a loss; over UDP the datagram is
    dropped) and moves nothing during the ``outages``, (start, end) seconds after the relays
    start. ``topology``: ``mesh``, a link
    between every two robots; ``chain``, robot i linked to i + 1 only, so that the others'
    submaps reach a robot only through those in between; ``router``, every robot a Zenoh
    client of one Zenoh router, linked to it alone (the topology of larger fleets).

    Rendezvous links (mesh or chain, simulated robots): a link is up only while its robots are
    within ``range_m`` metres and, with ``line_of_sight``, nothing of the world stands between.
    """

    emulate: bool = False  #: Robot pairs talk through counting relays
    rate: float | None = None  #: Each link's cap, bytes/s each way; null: no cap
    delay_s: float = 0.0  #: Each link's one-way delay (s)
    loss: float = 0.0  #: Chance a chunk stalls for stall_s (TCP) or is dropped (UDP)
    stall_s: float = 0.2  #: Seconds a lost chunk stalls (TCP's retransmission)
    #: (start, end) seconds after the relays start, during which nothing moves
    outages: tuple[tuple[float, float], ...] = ()
    seed: int = 0  #: Seed of the losses
    #: Which robots are linked: mesh (all pairs), chain (i to i + 1) or router
    topology: str = "mesh"
    #: Rendezvous: a link is up only while its robots are this close (m)
    range_m: float | None = None
    #: Rendezvous: a link is up only while nothing of the world stands between
    line_of_sight: bool = False

    def __post_init__(self) -> None:
        if self.topology not in TOPOLOGIES:
            raise InvalidInputError(f"link.topology must be one of {TOPOLOGIES}")
        if self.range_m is not None and not (math.isfinite(self.range_m) and self.range_m > 0):
            raise InvalidInputError(f"link.range_m must be > 0 m or null, got {self.range_m}")
        if self.rendezvous and self.topology == "router":
            raise InvalidInputError("rendezvous links need link.topology mesh or chain")
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate > 0):
            raise InvalidInputError(f"link.rate must be > 0 bytes/s or null, got {self.rate}")
        for name in ("delay_s", "stall_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidInputError(f"link.{name} must be finite and >= 0, got {value}")
        if not 0 <= self.loss < 1:
            raise InvalidInputError(f"link.loss must be in [0, 1), got {self.loss}")
        for window in self.outages:
            if len(window) != 2 or not 0 <= window[0] < window[1]:
                raise InvalidInputError(f"link.outages: (start, end), 0 <= start < end: {window}")

    @property
    def shaped(self) -> bool:
        """Whether the robots talk through relays."""
        shaping = self.rate or self.delay_s or self.loss or self.outages or self.rendezvous
        return self.emulate or bool(shaping) or self.topology != "mesh"

    @property
    def rendezvous(self) -> bool:
        """Whether links are up only while their robots are in reach of each other."""
        return self.range_m is not None or self.line_of_sight

    def pairs(self, n: int) -> list[tuple[int, int]]:
        """The linked pairs (i < j) of ``n`` robots; with a router, it is number n."""
        if self.topology == "router":
            return [(i, n) for i in range(n)]
        if self.topology == "chain":
            return [(i, i + 1) for i in range(n - 1)]
        return [(i, j) for i in range(n) for j in range(i + 1, n)]

    def outage_end(self, t: float) -> float | None:
        """The end of the outage under way ``t`` seconds after the start, or None."""
        return next((end for start, end in self.outages if start <= t < end), None)


@dataclass(frozen=True)
class SecurityOptions:
    """Who may join a robot's fleet and what it lets in (`gmmap.fleet.security.door`).

    ``credentials``: a member folder made by ``gmmap fleet add``
    (`gmmap.fleet.security.credentials`). With it, links are Zenoh TLS with mutual authentication
    against the fleet's authority, Zenoh's access control lets each member publish only under its
    own name (a station none), and every submap and advert is sealed by its robot and checked on
    arrival, relayed or not. None: plain TCP and nothing sealed, for tests and trusted labs (with a
    warning). Always: a message over ``max_bytes`` is refused, and so is a sender over ``rate``
    messages/s (``burst`` at once; rate None: no limit)."""

    #: Member folder from gmmap fleet add (TLS, sealed submaps); null: unsecured
    credentials: str | None = None
    max_bytes: int = 256 * 1024  #: A message over this many bytes is refused
    rate: float | None = 50.0  #: Messages/s a sender may send before it is refused; null: no limit
    burst: int = 500  #: Messages a sender may send at once

    def __post_init__(self) -> None:
        if isinstance(self.max_bytes, bool) or not isinstance(self.max_bytes, int):
            raise InvalidInputError(f"security.max_bytes must be an integer, got {self.max_bytes}")
        if self.max_bytes < 1024:
            raise InvalidInputError(f"security.max_bytes must be >= 1024, got {self.max_bytes}")
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate > 0):
            raise InvalidInputError(f"security.rate must be > 0 messages/s or null: {self.rate}")
        if isinstance(self.burst, bool) or not isinstance(self.burst, int) or self.burst < 1:
            raise InvalidInputError(f"security.burst must be an integer >= 1, got {self.burst}")


@dataclass(frozen=True)
class StationOptions:
    """A base station (``gmmap station``, `gmmap.fleet.node.station`): its ``name`` in the fleet,
    its catch-up round every ``sweep_s`` seconds, its live view (`gmmap.io.liveview`) updated
    every ``every_s`` seconds and served on ``host``: the data (Rerun gRPC) on ``grpc_port``,
    Rerun's web viewer on ``web_port`` (0: not served)."""

    name: str = "station"  #: The station's name in the fleet
    sweep_s: float = 5.0  #: Seconds between catch-up rounds
    every_s: float = 1.0  #: Seconds between live-view updates
    host: str = "127.0.0.1"  #: Address to serve the view on
    grpc_port: int = 9876  #: Where the view data is served (Rerun gRPC)
    web_port: int = 9090  #: Where Rerun's web viewer is served; 0: not served

    def __post_init__(self) -> None:
        check_name("station.name", self.name, InvalidInputError)
        if not (self.sweep_s > 0 and self.every_s > 0):
            raise InvalidInputError("station.sweep_s and station.every_s must be > 0 seconds")
        for key in ("grpc_port", "web_port"):
            port = getattr(self, key)
            if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
                raise InvalidInputError(f"station.{key} must be a port 0..65535, got {port!r}")
        if self.grpc_port == 0:
            raise InvalidInputError("station.grpc_port must be a port, not 0")
