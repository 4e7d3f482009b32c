"""Emulated links for tests and benchmarks: a TCP relay in front of a Zenoh endpoint that caps
bandwidth, delays, stalls and cuts what crosses it, and counts every byte it carries.

This machine's kernel has ``tc tbf`` but neither ``netem`` nor iptables, so delay, loss and
partitions are done here, in the application. A robot connects to the relay's endpoint instead
of its peer's; the relay forwards both directions. Over TCP a lost segment is never missing
bytes, it is a retransmission stall, so ``loss`` holds a chunk back for ``stall_s`` with that
probability. During an outage no byte moves either way; the connections stay open (as a radio
out of range leaves them), and Zenoh's lease decides when a peer is gone. A rendezvous link
(`gmmap.eval.links.rendezvous`) is the same outage, for as long as its two robots are out of
each other's reach.

What the relay counts is all that Zenoh put on the socket: its framing, keep-alives, liveliness
and queries included, and, from the kernel's own counts of its sockets (``TCP_INFO``), the
packets each side sent, ACKs, handshakes and retransmissions included. ``LinkCount.wire_bytes``
adds each packet's headers to the payload: IPv4, TCP with the timestamp option where the
connection negotiated it, and Ethernet (`HEADER_BYTES`). A direction is counted where the
relay receives it, as its sender segmented it: the connecting side's packets on the relay's
accepted socket, the target's on the socket to the target. Both sockets offer Ethernet's
segment size (``SEGMENT``), not loopback's 64 KiB, so a message over 1,448 bytes is counted
as the several packets (and ACKs) it would be on a radio or Ethernet link. The relay's kernel
takes in what a sender sends while the link is down, and the relay holds it until the link
returns; what it never passes on (the link stayed down, or the session ended) is not counted:
a link out of reach would not have carried it.

Zenoh over UDP (`TransportOptions.protocol`) goes through a
`gmmap.eval.links.datagrams.DatagramRelay` instead: there a
lost datagram is missing, and what meets an outage or a closed rendezvous link is dropped, as
a radio out of range drops it; each datagram is counted with its UDP, IPv4 and Ethernet
headers, per IP fragment.

Peers in Zenoh's peer mode tell each other where they listen (gossip) and would connect
directly, around the relay; a fleet behind relays turns gossip off
(``ZENOH_NO_GOSSIP``, for `TransportOptions.zenoh_options`).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import socket
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import TracebackType

from gmmap.options import LinkOptions

ZENOH_NO_GOSSIP = {"scouting/gossip/enabled": False}
CHUNK = 4096  # bytes read at once
SEGMENT = 1448  # a TCP segment's payload on Ethernet with timestamps: a capped link's unit
BUFFER = 8  # chunks in flight per direction before the relay stops reading (back-pressure)
ETHERNET_IP_BYTES = 14 + 20  # per packet: Ethernet and IPv4
HEADER_BYTES = ETHERNET_IP_BYTES + 20  # per TCP packet: and TCP without options
TIMESTAMP_BYTES = 12  # the TCP timestamp option, padded, on every packet once negotiated
_TCPI_OPT_TIMESTAMPS = 1
GATE_POLL_S = 0.1  # how often a closed rendezvous link looks again


@dataclass
class LinkCount:
    """What crossed one direction of a relay: the payload bytes and the chunks they came in,
    and the packets on the link with their headers (``wire_bytes``); on a datagram link, the
    datagrams it dropped (``dropped``: lost, cut off, or over its queue)."""

    bytes: int = 0
    chunks: int = 0
    stalls: int = 0
    packets: int = 0
    wire_bytes: int = 0
    dropped: int = 0


@dataclass(frozen=True)
class Received:
    """What one TCP socket received, as the kernel counts it (``TCP_INFO``): its packets, the
    payload in them and each packet's headers (``header``)."""

    packets: int = 0
    payload: int = 0
    header: int = HEADER_BYTES

    @property
    def wire_bytes(self) -> int:
        return self.payload + self.packets * self.header


def received(sock: socket.socket) -> Received:
    """The packets ``sock`` received and their bytes with headers; nothing where the kernel
    does not say (not Linux, or older than 4.2)."""
    try:
        info = sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_INFO, 232)
    except (OSError, AttributeError):
        return Received()
    if len(info) < 144:
        return Received()
    (payload,) = struct.unpack_from("Q", info, 128)  # tcpi_bytes_received
    (packets,) = struct.unpack_from("I", info, 140)  # tcpi_segs_in
    header = HEADER_BYTES + (TIMESTAMP_BYTES if info[5] & _TCPI_OPT_TIMESTAMPS else 0)
    return Received(packets, payload, header)


@dataclass
class _Direction:
    count: LinkCount = field(default_factory=LinkCount)
    free_at: float = 0.0  # when the rate cap lets the next byte go (monotonic)


def _ethernet_segments(sock: socket.socket) -> None:
    """Have both ends of ``sock``'s connection send segments of at most ``SEGMENT`` bytes
    (the MSS it offers in its SYN)."""
    with contextlib.suppress(OSError, AttributeError):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_MAXSEG, SEGMENT)


def _dup(sock) -> socket.socket:
    return socket.socket(fileno=os.dup(sock.fileno()))


class Relay:
    """A shaping, counting TCP relay from ``host:port`` (loopback by default) to ``target``
    (host, port).

    Use as a context manager, or `start` and `close`. ``endpoint`` is the Zenoh endpoint to
    connect to. One event loop thread serves every connection; "forward" is what the
    connecting side sent, "backward" what it received.
    """

    def __init__(
        self,
        target: tuple[str, int],
        shape: LinkOptions | None = None,
        port: int = 0,
        host: str = "127.0.0.1",
        gate: Callable[[], bool] | None = None,
    ):
        self.target = target
        self.shape = shape or LinkOptions()
        self.gate = gate  # while it says False, nothing crosses (a rendezvous link apart)
        self._port, self._host = port, host
        self._rng = random.Random(self.shape.seed)
        self._dirs = {"forward": _Direction(), "backward": _Direction()}
        self._lock = threading.Lock()
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, daemon=True)
        self._server: asyncio.base_events.Server | None = None
        self._tasks: set[asyncio.Task] = set()
        self._t0 = time.monotonic()
        # Each live connection's (accepted, upstream) sockets, and what closed ones received.
        self._sockets: set[tuple[socket.socket, socket.socket]] = set()
        self._closed: dict[str, list[Received]] = {"forward": [], "backward": []}

    @property
    def port(self) -> int:
        return self._port

    @property
    def endpoint(self) -> str:
        return f"tcp/{self._host}:{self._port}"

    def start(self) -> Relay:
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(self._serve(), self._loop)
        future.result(timeout=5)
        return self

    def counts(self) -> dict[str, LinkCount]:
        with self._lock:
            out = {k: LinkCount(**vars(d.count)) for k, d in self._dirs.items()}
            seen = {k: list(r) for k, r in self._closed.items()}
            for accepted, upstream in self._sockets:
                seen["forward"].append(received(accepted))
                seen["backward"].append(received(upstream))
        for k, parts in seen.items():
            c = out[k]
            c.packets = sum(r.packets for r in parts)
            c.wire_bytes = sum(r.wire_bytes for r in parts)
            # What the relay's kernel took in while the link was down and never passed on (the
            # link came back too late, or its session ended): a link out of reach would not
            # have carried it, its sender's TCP would have kept it.
            held = sum(r.payload for r in parts) - c.bytes
            if held > 0:
                segments = -(-held // SEGMENT)
                c.packets -= segments
                c.wire_bytes -= held + segments * max(r.header for r in parts)
        return out

    def close(self) -> None:
        if not self._thread.is_alive():
            return
        asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop).result(timeout=5)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)
        self._loop.close()

    def __enter__(self) -> Relay:
        return self.start()

    def __exit__(
        self, kind: type[BaseException] | None, err: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # --------------------------------------------------------------------- event loop side
    async def _serve(self) -> None:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        _ethernet_segments(sock)
        sock.bind((self._host, self._port))
        self._port = sock.getsockname()[1]
        self._server = await asyncio.start_server(self._accept, sock=sock)
        self._t0 = time.monotonic()

    async def _shutdown(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        up = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        _ethernet_segments(up)
        up.setblocking(False)
        try:
            await self._loop.sock_connect(up, self.target)
            up_reader, up_writer = await asyncio.open_connection(sock=up)
        except OSError:
            up.close()
            writer.close()
            return
        pumps = [
            asyncio.ensure_future(self._pump(reader, up_writer, "forward")),
            asyncio.ensure_future(self._pump(up_reader, writer, "backward")),
        ]
        self._tasks.update(pumps)
        # Duplicates: asyncio closes its sockets at the peer's EOF, and the kernel's counts
        # would go with them before the last could be read.
        pair = tuple(_dup(w.get_extra_info("socket")) for w in (writer, up_writer))
        with self._lock:
            self._sockets.add(pair)
        with contextlib.suppress(asyncio.CancelledError):
            # One side closing closes the other, as a TCP link would.
            await asyncio.wait(pumps, return_when=asyncio.FIRST_COMPLETED)
        for task in pumps:
            task.cancel()
            self._tasks.discard(task)
        with self._lock:
            self._sockets.discard(pair)
            for name, sock in zip(("forward", "backward"), pair, strict=True):
                self._closed[name].append(received(sock))
        for w in (writer, up_writer):
            w.close()
        for sock in pair:
            sock.close()

    async def _pump(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, name: str):
        """Reads chunks and releases each when the rate cap, the delay, a stall and any outage
        allow; a bounded queue between them gives back-pressure."""
        # Under a cap, about a second of data: more held here would delay Zenoh's keep-alives
        # past its lease (at 500 B/s, 8 segments are 23 s).
        rate = self.shape.rate
        queue: asyncio.Queue = asyncio.Queue(
            BUFFER if rate is None else max(1, int(rate // SEGMENT))
        )
        sender = asyncio.ensure_future(self._send(queue, writer, name))
        try:
            # Under a cap, a packet at a time: it arrives whole once its time on the link has
            # passed. Smaller chunks would have the far side send an ACK for each.
            size = CHUNK if self.shape.rate is None else SEGMENT
            while chunk := await reader.read(size):
                await queue.put((time.monotonic() + self.shape.delay_s, chunk))
            await queue.put(None)
            await sender
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            sender.cancel()

    async def _send(self, queue: asyncio.Queue, writer: asyncio.StreamWriter, name: str) -> None:
        d = self._dirs[name]
        while (item := await queue.get()) is not None:
            due, chunk = item
            stalled = self.shape.loss > 0 and self._rng.random() < self.shape.loss
            if stalled:
                due += self.shape.stall_s
            if self.shape.rate is not None:
                # The cap: a chunk leaves once the previous ones have had their time.
                start = max(time.monotonic(), d.free_at)
                d.free_at = start + len(chunk) / self.shape.rate
                due = max(due, d.free_at)
            await self._wait_until(due)
            writer.write(chunk)
            with self._lock:  # counted once on the socket, before a close can cancel the drain
                d.count.bytes += len(chunk)
                d.count.chunks += 1
                d.count.stalls += stalled
            await writer.drain()

    async def _wait_until(self, due: float) -> None:
        """Sleeps until ``due`` (monotonic) and then past any outage under way, and while the
        gate is closed."""
        while True:
            now = time.monotonic()
            if now < due:
                await asyncio.sleep(due - now)
                continue
            end = self.shape.outage_end(now - self._t0)
            if end is not None:
                await asyncio.sleep(self._t0 + end - now)
            elif self.gate is not None and not self.gate():
                await asyncio.sleep(GATE_POLL_S)
            else:
                return
