"""What a robot lets in and how it signs what it sends (`gmmap.fleet.robot`): every message of
another robot, received or fetched, passes `Door.admit` (size cap, rate limit, and in a
secured fleet the seal: `gmmap.fleet.seal`) before anything parses or queues it.

In a secured fleet (``credentials``: `gmmap.fleet.credentials`) the robot's own submaps and
adverts are sealed as they are built, and stored sealed; a robot's store holds what arrived as
it arrived, so what it hands on to others is the owner's bytes and the owner's seal. Without
credentials (a trusted lab, tests) nothing is sealed and only the guard applies.
"""

from __future__ import annotations

import logging

from gmmap.errors import RefusedError
from gmmap.fleet.guard import Guard, Refusals
from gmmap.fleet.seal import OVERHEAD, open_sealed, seal
from gmmap.fleet_options import SecurityOptions

log = logging.getLogger(__name__)


class Door:
    """One robot's admission and sealing; ``credentials`` None: an unsecured fleet."""

    def __init__(self, fleet: str, options: SecurityOptions | None = None, credentials=None):
        self.fleet = fleet
        self.credentials = credentials
        self.refusals = Refusals()
        self.guard = Guard(options, self.refusals)

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
        try:
            open_sealed(self.credentials.member_key, self.fleet, robot, kind, seq, wire)
        except RefusedError as err:
            self.refusals.add(robot, err.cause)
            log.debug("refused: %s", err)
            return False
        return True

    def inner(self, wire: bytes) -> bytes:
        """The payload of a message admitted (or our own): the seal stripped."""
        return wire if self.credentials is None else wire[OVERHEAD:]
