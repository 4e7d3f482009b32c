"""What a robot lets in and how it signs what it sends (`gmmap.fleet.node.robot`): every message of
another robot, received or fetched, passes `Door.admit` (size cap, rate limit, and in a
secured fleet the seal: `gmmap.fleet.security.seal`) before anything parses or queues it.

In a secured fleet (``credentials``: `gmmap.fleet.security.credentials`) the robot's own submaps and
adverts are sealed as they are built, and stored sealed; a robot's store holds what arrived as
it arrived, so what it hands on to others is the owner's bytes and the owner's seal. Without
credentials (a trusted lab, tests) nothing is sealed and only the guard applies.
"""

from __future__ import annotations

import logging
import threading
import time

from gmmap.errors import GmmapError, RefusedError
from gmmap.fleet.security.guard import Guard, Refusals
from gmmap.fleet.security.seal import OVERHEAD, VERSION, open_sealed, seal
from gmmap.fleet_options import SecurityOptions

log = logging.getLogger(__name__)

CRL_EVERY_S = 2.0  # how often the door looks whether crl.pem changed


class Door:
    """One robot's admission and sealing; ``credentials`` None: an unsecured fleet."""

    def __init__(self, fleet: str, options: SecurityOptions | None = None, credentials=None):
        self.fleet = fleet
        self.credentials = credentials
        self.refusals = Refusals()
        self.guard = Guard(options, self.refusals)
        self._lock = threading.Lock()
        self._crl_at, self._crl_seen = time.monotonic(), self._crl_mtime()

    @property
    def secure(self) -> bool:
        return self.credentials is not None

    def seal(self, robot: str, kind: str, seq: int, payload: bytes) -> bytes:
        """What goes on the wire (and into the store) for our own ``payload``."""
        if self.credentials is None:
            return payload
        return seal(self.credentials.sign, self.fleet, robot, kind, seq, payload)

    def admit(self, robot: str, kind: str, seq: int, wire: bytes) -> bool:
        """Whether another robot's message may go on; refusals are counted by cause."""
        if not self.guard.admit(robot, len(wire)):
            return False
        if self.credentials is None:
            return True
        self._take_revocations()
        try:
            open_sealed(self.credentials.member_key, self.fleet, robot, kind, seq, wire)
        except RefusedError as err:
            self.refusals.add(robot, err.cause)
            log.debug("refused: %s", err)
            return False
        return True

    def inner(self, wire: bytes) -> bytes:
        """The payload of a message admitted (or our own): the seal stripped. A store written
        before the fleet was secured holds unsealed payloads: those stay as they are (and
        peers refuse them, unsigned)."""
        sealed = self.credentials is not None and wire[:1] == bytes([VERSION])
        return wire[OVERHEAD:] if sealed else wire

    def _crl_mtime(self) -> int | None:
        if self.credentials is None:
            return None
        try:
            return self.credentials.crl_path.stat().st_mtime_ns
        except OSError:
            return None

    def _take_revocations(self) -> None:
        """A revocation list changed on disk (``gmmap fleet revoke``) is taken in while the
        robot runs: the revoked robots' submaps are refused from then on."""
        with self._lock:
            now = time.monotonic()
            if now < self._crl_at + CRL_EVERY_S:
                return
            self._crl_at, seen = now, self._crl_mtime()
            if seen == self._crl_seen:
                return
            self._crl_seen = seen
        try:
            gone = self.credentials.reread_crl()
        except GmmapError as err:
            log.warning("%s: the changed revocation list is not taken: %s", self.fleet, err)
            return
        if gone:
            log.warning("%s: revoked from the fleet now: %s", self.fleet, ", ".join(gone))
