"""Emulated datagram links (`gmmap.eval.links.relay` for TCP): a UDP relay in front of a Zenoh
endpoint that drops, delays and caps what crosses it and counts every datagram with its
headers, for robots that talk Zenoh over UDP (`TransportOptions.protocol`)."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

from gmmap.eval.links.relay import ETHERNET_IP_BYTES, LinkCount, Relay, _Direction

UDP_HEADER_BYTES = 8
IP_PAYLOAD = 1480  # an IPv4 packet's payload on Ethernet: larger datagrams go as fragments
QUEUE_S = 1.0  # a capped datagram link drops what would wait longer than this to be sent
MAX_SENDERS = 64  # addresses a datagram relay forwards for: a flood of others is dropped


class DatagramRelay(Relay):
    """A shaping, counting UDP relay from ``host:port`` to ``target``, for Zenoh over UDP
    (`TransportOptions.protocol`): the same interface as `Relay`, ``endpoint`` ``udp/…``.

    A datagram is lost, not stalled: ``loss`` drops it with that probability, and during an
    outage or while the gate is closed what would cross is dropped (and not counted: a link
    out of reach carries nothing). Under a cap a datagram waits its turn; one that would wait
    more than `QUEUE_S` is dropped, as a radio's full queue drops. Each client address gets
    its own socket towards the target, so the target tells its peers apart (up to
    `MAX_SENDERS` of them; datagrams from more are dropped, not given sockets without end).
    Counted per datagram: its payload, UDP's 8 bytes and, per IPv4 packet (a datagram over
    Ethernet's 1,480 bytes of IP payload travels as fragments), IPv4's and Ethernet's headers.
    """

    @property
    def endpoint(self) -> str:
        return f"udp/{self._host}:{self._port}"

    def counts(self) -> dict[str, LinkCount]:
        with self._lock:
            return {k: LinkCount(**vars(d.count)) for k, d in self._dirs.items()}

    async def _serve(self) -> None:
        self._listen = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._listen.bind((self._host, self._port))
        self._listen.setblocking(False)
        self._port = self._listen.getsockname()[1]
        self._upstream: dict[tuple, socket.socket] = {}
        self._loop.add_reader(self._listen, self._from_client)
        self._t0 = time.monotonic()

    async def _shutdown(self) -> None:
        for sock in (self._listen, *self._upstream.values()):
            self._loop.remove_reader(sock)
            sock.close()

    def _from_client(self) -> None:
        for data, addr in _drain(self._listen):
            up = self._upstream.get(addr)
            if up is None and len(self._upstream) >= MAX_SENDERS:
                self._drop(self._dirs["forward"])
                continue
            if up is None:
                up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                up.connect(self.target)
                up.setblocking(False)
                self._upstream[addr] = up
                self._loop.add_reader(up, self._from_target, up, addr)
            self._forward("forward", data, up.send)

    def _from_target(self, up: socket.socket, addr: tuple) -> None:
        for data, _ in _drain(up):
            self._forward("backward", data, lambda d: self._listen.sendto(d, addr))

    def _forward(self, name: str, data: bytes, send: Callable[[bytes], object]) -> None:
        now = time.monotonic()
        d = self._dirs[name]
        if self._down(now) or (self.shape.loss > 0 and self._rng.random() < self.shape.loss):
            self._drop(d)
            return
        due = now + self.shape.delay_s
        if self.shape.rate is not None:
            start = max(now, d.free_at)
            if start - now > QUEUE_S:
                self._drop(d)
                return
            d.free_at = start + datagram_wire(len(data))[1] / self.shape.rate
            due = max(due, d.free_at)
        self._loop.call_later(due - now, self._emit, d, data, send)

    def _emit(self, d: _Direction, data: bytes, send: Callable[[bytes], object]) -> None:
        if self._down(time.monotonic()):  # the link went down while it was on its way
            self._drop(d)
            return
        try:
            send(data)
        except OSError:  # the peer is gone, or its buffer is full: lost
            self._drop(d)
        else:
            packets, wire = datagram_wire(len(data))
            with self._lock:
                d.count.bytes += len(data)
                d.count.chunks += 1
                d.count.packets += packets
                d.count.wire_bytes += wire

    def _drop(self, d: _Direction) -> None:
        with self._lock:
            d.count.dropped += 1

    def _down(self, now: float) -> bool:
        return self.shape.outage_end(now - self._t0) is not None or (
            self.gate is not None and not self.gate()
        )


def datagram_wire(size: int) -> tuple[int, int]:
    """The IPv4 packets a UDP datagram of ``size`` payload bytes takes on Ethernet, and their
    bytes with all headers."""
    packets = -(-(size + UDP_HEADER_BYTES) // IP_PAYLOAD)
    return packets, size + UDP_HEADER_BYTES + packets * ETHERNET_IP_BYTES


def _drain(sock: socket.socket):
    """The datagrams waiting on ``sock``, with their senders."""
    while True:
        try:
            yield sock.recvfrom(65_536)
        except ConnectionRefusedError:  # ICMP from a peer that went away: the next may be fine
            continue
        except OSError:  # nothing waits (BlockingIOError), or the socket closed
            return


def relay_for(protocol: str) -> type[Relay]:
    """The relay for a Zenoh link protocol: ``udp`` datagrams, else a TCP stream."""
    return DatagramRelay if protocol == "udp" else Relay
