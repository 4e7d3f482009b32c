"""Emulated links for tests, benchmarks and the demo, outside the fleet runtime (no robot
imports them): a counting, shaping TCP relay (`relay`), its UDP twin (`datagrams`), who is in
reach of whom on rendezvous links (`rendezvous`), two transports joined by one relay
(`pair`) and one radio channel a whole fleet shares, capped by the kernel (`channel`)."""

from gmmap.eval.links.datagrams import MAX_SENDERS, DatagramRelay, datagram_wire, relay_for
from gmmap.eval.links.pair import relayed_pair
from gmmap.eval.links.relay import (
    HEADER_BYTES,
    TIMESTAMP_BYTES,
    ZENOH_NO_GOSSIP,
    LinkCount,
    Relay,
)
from gmmap.eval.links.rendezvous import Rendezvous

__all__ = [
    "HEADER_BYTES",
    "MAX_SENDERS",
    "TIMESTAMP_BYTES",
    "ZENOH_NO_GOSSIP",
    "DatagramRelay",
    "LinkCount",
    "Relay",
    "Rendezvous",
    "datagram_wire",
    "relay_for",
    "relayed_pair",
]
