"""The shared channel's broadcast (`TransportOptions.broadcast`): each message goes on the air
once, as one UDP multicast datagram, and every robot in the group hears it.

The kernel's UDP multicast, not Zenoh's multicast transport: with three robots on one channel,
Zenoh's multicast sessions (eclipse-zenoh 1.10) were seen to flood it at tens of MB/s, with or
without gossip, in separate processes too, and each robot announces itself on the group every
join interval, which a 500 B/s channel cannot spare. Here nothing goes on the air but the
messages and a robot's greetings (`gmmap.fleet.net.transport`: presence on a shared channel is
what is heard on it). There is no retransmission: what a robot missed (a lost datagram, a robot
out of range or not yet started) it learns of from the sender's next advert and fetches over a
unicast session opened for that (`gmmap.fleet.sharing.fetching`).

A datagram is ``b"G2"``, the fleet's and the robot's names (each a LEB128 length and UTF-8, as
in adverts: `gmmap.fleet.wire.bitstream`), the kind (one byte: its index in `KINDS`, or 255 and
the name), the seq (an unsigned LEB128 varint) and the payload: 17 B of header for
``demo``/``robot_0``/``submap``/12, where the key expression ``gmmap/demo/robot_0/submap/12``
and a header would take 34. A message too large for one datagram is not broadcast
(`Air.send` says so).
"""

from __future__ import annotations

import contextlib
import logging
import socket
import struct
import threading
import time
from collections.abc import Callable

from gmmap.errors import DecodeError, TransportError
from gmmap.fleet.wire.bitstream import _Reader, _Writer
from gmmap.fleet_options import multicast_group

log = logging.getLogger(__name__)

MAGIC = b"G2"
KINDS = ("submap", "have", "hello", "bye")  # one byte on the air; others are spelled out
OTHER_KIND = 255
MAX_DATAGRAM = 65_507  # bytes: IPv4's largest UDP payload
TICK_S = 1.0  # how often ``on_tick`` runs, heard or not

Message = tuple[str, str, str, int]  # fleet, robot, kind, seq


def header(fleet: str, robot: str, kind: str, seq: int) -> bytes:
    """A datagram's header, before its payload (module docstring)."""
    w = _Writer()
    w.raw(MAGIC)
    w.name(fleet)
    w.name(robot)
    w.u8(KINDS.index(kind) if kind in KINDS else OTHER_KIND)
    if kind not in KINDS:
        w.name(kind)
    w.uvarint(seq)
    return bytes(w.buf)


def parse(datagram: bytes) -> tuple[Message, bytes] | None:
    """((fleet, robot, kind, seq), payload), or None for a datagram that is not ours, is cut
    short or names something that is not a name."""
    if not datagram.startswith(MAGIC):
        return None
    r = _Reader(datagram)
    r.pos = len(MAGIC)
    try:
        fleet, robot = r.name("fleet"), r.name("robot")
        code = r.u8("kind")
        if code < len(KINDS):
            kind = KINDS[code]
        elif code == OTHER_KIND:
            kind = r.name("kind")
        else:
            return None
        seq = r.uvarint("seq", 2**64 - 1)
    except DecodeError:
        return None
    return (fleet, robot, kind, seq), r.rest()


def _mreqn(group: str, iface: str | None) -> bytes:
    """Linux's ``struct ip_mreqn``: the group on the named interface (0: the route's)."""
    index = socket.if_nametoindex(iface) if iface else 0
    return struct.pack("=4s4si", socket.inet_aton(group), bytes(4), index)


class Air:
    """One robot's sender and receiver on the multicast group ``endpoint``; on its receiving
    thread (`start`) ``on_message((fleet, robot, kind, seq), payload)`` runs for every datagram
    heard, own ones included, and ``on_tick()`` about every `TICK_S`."""

    def __init__(
        self,
        endpoint: str,
        on_message: Callable[[Message, bytes], None],
        on_tick: Callable[[], None] = lambda: None,
    ) -> None:
        host, port, iface = multicast_group(endpoint)
        self.group = (host, port)
        self._on_message, self._on_tick = on_message, on_tick
        self.last_sent = time.monotonic()
        try:
            self._send = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._send.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
            if iface:
                self._send.setsockopt(
                    socket.IPPROTO_IP, socket.IP_MULTICAST_IF, _mreqn(host, iface)
                )
            self._recv = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            # Every robot on this host binds the group's port.
            self._recv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._recv.bind((host, port))
            self._recv.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, _mreqn(host, iface))
            self._recv.settimeout(TICK_S)
        except OSError as err:
            self.close()
            raise TransportError(f"cannot join the broadcast group {endpoint}: {err}") from err
        self._closed = False
        self._thread = threading.Thread(target=self._listen, name="gmmap-air", daemon=True)

    def start(self) -> None:
        """Starts hearing: the receiving thread."""
        self._thread.start()

    def send(self, message: Message, payload: bytes = b"") -> bool:
        """Puts one message on the air; False where it does not fit one datagram,
        `TransportError` where the socket refuses it."""
        datagram = header(*message) + payload
        if len(datagram) > MAX_DATAGRAM:
            return False
        try:
            self._send.sendto(datagram, self.group)
        except OSError as err:
            raise TransportError(f"cannot broadcast {message}: {err}") from err
        self.last_sent = time.monotonic()
        return True

    def close(self) -> None:
        """Leaves the group. Idempotent."""
        self._closed = True
        for sock in (getattr(self, "_recv", None), getattr(self, "_send", None)):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
                sock.close()

    def _listen(self) -> None:
        ticked = time.monotonic()
        while not self._closed:
            try:
                parsed = parse(self._recv.recv(MAX_DATAGRAM))
            except TimeoutError:
                parsed = None
            except OSError:
                return  # closed
            try:
                if parsed is not None:
                    self._on_message(*parsed)
                if time.monotonic() >= ticked + TICK_S:
                    ticked = time.monotonic()
                    self._on_tick()
            except Exception:  # a bad message must not stop the receiver
                log.exception("gmmap air: dropping a message that could not be handled")
