"""What a robot has received of each other robot, stored or still queued, for its fetches
(`gmmap.fleet.node.robot`): where a fetch starts, and whether the robots in between must answer.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterable

from gmmap.options import RobotOptions

# A present robot that has sent nothing directly for this long, while others hold more of it,
# is fetched through them: a rendezvous link that went down stays "present" until Zenoh's
# lease expires (60 s), and a short meeting with a robot in between would pass unused.
QUIET_S = 5.0


def quiet_for(robot: RobotOptions) -> float:
    """How long a present robot may send nothing before it counts as quiet, in a fleet whose
    robots bundle their submaps as ``robot`` does (`RobotOptions.bundle`): a robot that
    bundles is quiet longer by design."""
    return QUIET_S if robot.bundle_size <= 1 else max(QUIET_S, robot.bundle_wait + 1.0)


class Arrivals:
    """The sequence numbers received per robot, and the robots that are present yet did not
    answer a fetch for their own submaps or have been quiet (thread-safe: Zenoh's threads and
    the fetcher). Times are ``clock()`` seconds."""

    def __init__(
        self,
        clock=time.monotonic,
        quiet_s: float = QUIET_S,
        patient: bool = True,
        shared_channel: bool = False,
    ) -> None:
        self._lock = threading.Lock()
        self._seqs: dict[str, set[int]] = {}
        self._silent: set[str] = set()
        self._heard: dict[str, float] = {}  # when it joined or last sent us something itself
        self._latest: dict[str, int] = {}  # the newest seq it sent us itself since it joined
        self._clock, self._quiet_s = clock, quiet_s
        # Whether a gap behind the latest arrival is more likely queued than cut off: where
        # robots bundle (stable links, `RobotOptions.bundle`), not where each submap leaves at
        # once because a contact may last a second.
        self.patient = patient
        # On a channel the fleet shares, a robot paced to its share of the air sends its
        # newest submaps first and the older ones behind, all heard by every robot in range:
        # while it talks, whatever we lack of it is on its way, older or newer.
        self.shared_channel = shared_channel

    def met(self, robot: str) -> None:
        """``robot`` joined: its quiet time starts now."""
        with self._lock:
            self._heard[robot] = self._clock()
            self._latest.pop(robot, None)  # what it sent before is no guide to what is on its way

    def hear(self, robot: str) -> None:
        """``robot`` sent us something itself (an advert): it is neither silent nor quiet."""
        with self._lock:
            self._silent.discard(robot)
            self._heard[robot] = self._clock()

    def latest(self, robot: str) -> int:
        """The newest seq ``robot`` sent us itself since it joined; -1 if none."""
        with self._lock:
            return self._latest.get(robot, -1)

    def add(self, robot: str, seq: int, direct: bool = False) -> bool:
        """Notes that ``robot``'s ``seq`` arrived (``direct``: from that robot itself, which is
        then not silent); False if it had arrived already."""
        with self._lock:
            seqs = self._seqs.setdefault(robot, set())
            if direct:
                self._silent.discard(robot)
                self._heard[robot] = self._clock()
                self._latest[robot] = max(seq, self._latest.get(robot, seq))
            new = seq not in seqs
            seqs.add(seq)
        return new

    def held(self, robot: str, stored: Iterable[int]) -> set[int]:
        """``robot``'s submaps that arrived, stored or still queued: asking again for those
        waiting in a busy robot's inbox would have them sent twice."""
        with self._lock:
            return set(stored) | self._seqs.get(robot, set())

    def since(self, robot: str, stored: Iterable[int]) -> int:
        """Where a fetch of ``robot`` starts: its first gap (`held`), else after its latest."""
        have = self.held(robot, stored)
        return next(seq for seq in range(len(have) + 1) if seq not in have)

    def relayed(self, robot: str, present: Iterable[str]) -> bool:
        """Whether the robots in between must answer for ``robot``: it is out of reach, or
        present and silent or quiet for ``quiet_s`` (a link that stalled: Zenoh sees it leave only
        when its lease expires)."""
        with self._lock:
            quiet = self._clock() > self._heard.get(robot, -float("inf")) + self._quiet_s
            return robot not in set(present) or robot in self._silent or quiet

    def quiet(self, present: Iterable[str]) -> list[str]:
        """The present robots the robots in between must answer for (`relayed`)."""
        present = list(present)
        return [r for r in present if self.relayed(r, present)]

    def on_its_way(self, robot: str, since: int) -> bool:
        """Whether what we lack of ``robot`` from ``since`` on is on its way from the robot
        itself: it talks to us (sent us something directly within ``quiet_s``) and ``since``
        lies past the newest submap it sent us since it joined. A robot sends each of its
        submaps to every present peer in order, so on a slow link the rest is queued behind
        that one, and fetching it would send it twice. Never where not ``patient``: there a
        robot that sent nothing newer more likely went out of reach. On a shared channel
        (``shared_channel``) all we lack of it is on its way while it talks."""
        with self._lock:
            latest = self._latest.get(robot)
            heard = self._heard.get(robot, -float("inf"))
            talking = robot not in self._silent and self._clock() <= heard + self._quiet_s
            if self.shared_channel:
                return talking
            return self.patient and talking and latest is not None and since > latest

    @property
    def quiet_s(self) -> float:
        return self._quiet_s

    @quiet_s.setter
    def quiet_s(self, seconds: float) -> None:
        with self._lock:
            self._quiet_s = seconds

    def now(self) -> float:
        return self._clock()

    def unanswered(self, robot: str, asked: float) -> bool:
        """``robot``, present, sent nothing of its own when asked at ``asked`` (`now`): unless
        something of it arrived directly meanwhile (its link is slow, not down: the answer is
        queued behind), relays answer from now on, until something of it arrives directly.
        Whether it was so marked."""
        with self._lock:
            if self._heard.get(robot, -float("inf")) >= asked:
                return False
            self._silent.add(robot)
            return True
