"""The shared channel's broadcast (`TransportOptions.broadcast`): each message goes on the air
once, as one UDP multicast datagram, and every robot in the group hears it.

The kernel's UDP multicast, not Zenoh's multicast transport: with three robots on one channel,
Zenoh's multicast sessions (eclipse-zenoh 1.10) were seen to flood it at tens of MB/s, with or
without gossip, in separate processes too, and each robot announces itself on the group every
join interval, which a 500 B/s channel cannot spare. Here nothing goes on the air but the
messages. There is no retransmission: what a robot missed (a lost datagram, a robot out of
range or not yet started) it learns of from the sender's next advert and fetches over its
unicast links (`gmmap.fleet.sharing.fetching`), which also carry everything else (presence,
queries, fetch answers).

A datagram is ``b"GMA1"``, the key's length (u16, big-endian), the key (UTF-8) and the payload.
A message too large for one datagram is not broadcast (`Air.fits`).
"""

from __future__ import annotations

import contextlib
import logging
import socket
import struct
import threading
from collections.abc import Callable

from gmmap.errors import TransportError
from gmmap.fleet_options import multicast_group

log = logging.getLogger(__name__)

MAGIC = b"GMA1"
HEADER = struct.Struct(">4sH")
MAX_DATAGRAM = 65_507  # bytes: IPv4's largest UDP payload


def _mreqn(group: str, iface: str | None) -> bytes:
    """Linux's ``struct ip_mreqn``: the group on the named interface (0: the route's)."""
    index = socket.if_nametoindex(iface) if iface else 0
    return struct.pack("=4s4si", socket.inet_aton(group), bytes(4), index)


class Air:
    """One robot's sender and receiver on the multicast group ``endpoint``; ``on_message(key,
    payload)`` runs on the receiving thread for every datagram heard, own ones included."""

    def __init__(self, endpoint: str, on_message: Callable[[str, bytes], None]) -> None:
        host, port, iface = multicast_group(endpoint)
        self.group = (host, port)
        self._on_message = on_message
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
        except OSError as err:
            self.close()
            raise TransportError(f"cannot join the broadcast group {endpoint}: {err}") from err
        self._closed = False
        self._thread = threading.Thread(target=self._listen, name="gmmap-air", daemon=True)
        self._thread.start()

    @staticmethod
    def fits(key: str, payload_len: int) -> bool:
        return HEADER.size + len(key.encode()) + payload_len <= MAX_DATAGRAM

    def send(self, key: str, payload: bytes) -> None:
        """Puts one message on the air; `TransportError` when the socket refuses it."""
        raw = key.encode()
        try:
            self._send.sendto(HEADER.pack(MAGIC, len(raw)) + raw + payload, self.group)
        except OSError as err:
            raise TransportError(f"cannot broadcast {key}: {err}") from err

    def close(self) -> None:
        """Leaves the group. Idempotent."""
        self._closed = True
        for sock in (getattr(self, "_recv", None), getattr(self, "_send", None)):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
                sock.close()

    def _listen(self) -> None:
        while not self._closed:
            try:
                datagram = self._recv.recv(MAX_DATAGRAM)
            except OSError:
                return  # closed
            message = self._parse(datagram)
            if message is not None:
                try:
                    self._on_message(*message)
                except Exception:  # a bad message must not stop the receiver
                    log.exception("gmmap air: dropping a message that could not be handled")

    @staticmethod
    def _parse(datagram: bytes) -> tuple[str, bytes] | None:
        """(key, payload), or None for a datagram that is not ours or is cut short."""
        if len(datagram) < HEADER.size:
            return None
        magic, n = HEADER.unpack_from(datagram)
        if magic != MAGIC or HEADER.size + n > len(datagram):
            return None
        try:
            key = datagram[HEADER.size : HEADER.size + n].decode()
        except UnicodeDecodeError:
            return None
        return key, datagram[HEADER.size + n :]
