"""An exploring robot as its own process (`gmmap robot --explore`): its `Explorer`, a Zenoh
transport to its peers, and the simulator's ticks standing in for its wheels
(`gmmap.fleet.wire.explore`); its sensor renders a frame at the true pose a tick gives.

On each tick the robot first takes in every message its peers had sent by their previous
step (the tick says how many; it waits for them, so what a robot knows does not depend on
how Zenoh interleaves its links), renders its sensor at the true pose the tick gives, maps
the frame and sends a submap it completed (kinds ``submap`` and ``horizons``), chooses its
direction, tells a changed goal (``claim``) and answers (``step``). Peers' submaps arrive as
every robot decodes them: quantised, as sent.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import time
from collections import defaultdict
from collections.abc import Callable

from gmmap.config import Config
from gmmap.errors import DecodeError, FileFormatError, TransportError
from gmmap.fleet.net.transport import Transport, TransportConfig
from gmmap.fleet.wire.codec import decode, encode
from gmmap.fleet.wire.explore import (
    DATA,
    Step,
    Tick,
    decode_claim,
    decode_tick,
    encode_claim,
    encode_json,
)
from gmmap.mapping.explore import Explorer, SharedSubmap, next_move
from gmmap.mapping.frame import Frame
from gmmap.mapping.frontier import decode_horizons, encode_horizons

log = logging.getLogger(__name__)

SIM = "sim"  # the simulator's name in the fleet
PEERS_TIMEOUT_S = 60.0  # to meet the simulator and every peer at the start
TICK_TIMEOUT_S = 600.0  # for the next tick and the messages it says were sent
READY_EVERY_S = 2.0  # the robot says it is ready again until the first tick comes


Sense = Callable[[float, float, float, float], Frame]
"""``sense(t, x, y, yaw)``: the robot's frame at time t, at that true pose on the floor."""


class ExplorerNode:
    """The robot ``config.robot`` names, its frames from ``sense``; `run` it."""

    def __init__(self, config: Config, sense: Sense) -> None:
        self.config, self.sense = config, sense
        self.robot = config.robot.name
        self.explorer = Explorer(self.robot, config)
        self.inbox: queue.Queue[tuple[str, str, int, bytes]] = queue.Queue()
        self.ticks: dict[int, Tick] = {}
        self.received: dict[str, int] = defaultdict(int)
        self.parts: dict[tuple[str, int], dict[str, bytes]] = defaultdict(dict)
        self.sent = self.bytes = 0

    def run(self) -> dict:
        """Explores until the simulator's last tick; this robot's summary."""
        o = self.config
        with Transport(TransportConfig(o.robot.fleet, self.robot, o.transport)) as transport:
            self.transport = transport
            transport.subscribe(lambda *message: self.inbox.put(message))
            peers = {SIM, *o.robot.wait_for}
            if not transport.wait_for_peers(peers, PEERS_TIMEOUT_S):
                missing = sorted(peers - set(transport.peers()))
                raise TransportError(f"{self.robot}: {missing} not met in {PEERS_TIMEOUT_S:.0f} s")
            transport.publish("ready", 0, b"")
            seq = 0
            while True:
                tick = self._next_tick(seq)
                transport.publish("step", seq, encode_json(self._step(tick)))
                if tick.end:
                    break
                seq += 1
        return {"robot": self.robot, "status": self.explorer.status, "bytes": self.bytes}

    def _next_tick(self, seq: int) -> Tick:
        deadline = time.monotonic() + TICK_TIMEOUT_S
        ready_at = time.monotonic()
        while True:
            tick = self.ticks.get(seq)
            if tick is not None and all(
                self.received[r] >= n for r, n in tick.sent.items() if r != self.robot
            ):
                return self.ticks.pop(seq)
            if tick is None and seq == 0 and time.monotonic() - ready_at > READY_EVERY_S:
                self.transport.publish("ready", 0, b"")  # the simulator may have missed it
                ready_at = time.monotonic()
            if time.monotonic() > deadline:
                raise TransportError(f"{self.robot}: tick {seq} or its peers' messages lacking")
            with contextlib.suppress(queue.Empty):
                self._take(*self.inbox.get(timeout=0.5))

    def _take(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        if robot == SIM or kind not in DATA:
            if robot == SIM and kind == "tick":
                self._tick(seq, payload)
            return  # other robots' steps, readies
        self.received[robot] += 1
        try:
            if kind == "claim":
                self.explorer.receive_claim(robot, decode_claim(payload))
                return
            parts = self.parts[(robot, seq)]
            parts[kind] = payload
            if len(parts) == 2:
                del self.parts[(robot, seq)]
                submap = decode(parts["submap"])
                self.explorer.receive(SharedSubmap(submap, decode_horizons(parts["horizons"])))
        except (DecodeError, FileFormatError) as exc:  # counted: the tick's wait goes on
            log.warning("%s: dropping %s %d of %s: %s", self.robot, kind, seq, robot, exc)

    def _tick(self, seq: int, payload: bytes) -> None:
        try:
            self.ticks[seq] = decode_tick(payload)
        except DecodeError as exc:
            log.warning("%s: dropping tick %d: %s", self.robot, seq, exc)

    def _step(self, tick: Tick) -> Step:
        if tick.end:
            self._send(self.explorer.flush())
            return Step(None, self.explorer.status, self.sent, self.bytes)
        frame = self.sense(tick.t, *tick.poses[self.robot])
        self._send(self.explorer.observe(frame))
        if not tick.decide:
            return Step(None, self.explorer.status, self.sent, self.bytes)
        direction, claim = next_move(self.explorer, frame.stamp)
        if claim is not None:
            self._publish("claim", self.sent, encode_claim(claim))
        moving = None if direction is None else [float(v) for v in direction[:2]]
        return Step(moving, self.explorer.status, self.sent, self.bytes)

    def _send(self, shared: SharedSubmap | None) -> None:
        if shared is not None:
            seq = shared.submap.seq
            self._publish("submap", seq, encode(shared.submap))
            self._publish("horizons", seq, encode_horizons(shared.horizons))

    def _publish(self, kind: str, seq: int, payload: bytes) -> None:
        self.transport.publish(kind, seq, payload)
        self.sent += 1
        self.bytes += len(payload)
