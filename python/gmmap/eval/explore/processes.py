"""Exploration with each robot its own process (`gmmap explore --processes`).

Each robot is a ``gmmap robot --explore`` process (`gmmap.fleet.node.explorer`) that maps,
decides and talks to its peers over Zenoh; this simulator moves the bodies, checks
collisions against the true world and measures coverage, as `Team` does. One tick is one
lockstep: the simulator sends every true pose, the robots sense, map and decide at once, each
in its own process, and the simulator moves them by their answers. It hears the robots'
submaps and horizons as any peer does and places them by each robot's true start (odometry
is perfect); the area known free counts the horizons sent, not those of a submap still being
built.
"""

from __future__ import annotations

import contextlib
import os
import queue
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gmmap.config import Config
from gmmap.errors import DecodeError, FileFormatError
from gmmap.eval.explore.team import Progress, RunResult, Team
from gmmap.fleet.net.transport import Transport, TransportConfig
from gmmap.fleet.node.explorer import SIM, TICK_TIMEOUT_S
from gmmap.fleet.wire.codec import decode
from gmmap.fleet.wire.explore import DATA, Step, Tick, decode_step, encode_json
from gmmap.mapping.explore import moving_on
from gmmap.mapping.frontier import Horizon, decode_horizons

START_TIMEOUT_S = 120.0  # for every robot process to start and say it is ready
EXIT_TIMEOUT_S = 60.0


class ProcessTeam(Team):
    """`Team` (mode ``shared``) whose robots are processes; ``log`` gets their output."""

    def __init__(self, config: Config, robots: int | None = None, log: Progress = print) -> None:
        super().__init__(config, "shared", robots)
        self.log = log
        self.inbox: queue.Queue[tuple[str, str, int, bytes]] = queue.Queue()
        self.procs: list[subprocess.Popen] = []
        self.readers: list[threading.Thread] = []
        self.transport: Transport | None = None
        self.ready: set[str] = set()
        self.steps: dict[tuple[str, int], Step] = {}
        self.answers: list[Step] = []
        self.sent = dict.fromkeys(self.names, 0)  # data messages each robot sent
        self.heard: dict[str, int] = defaultdict(int)  # and those the simulator heard
        self.anchors: dict[tuple[str, int], np.ndarray] = {}  # submaps' anchors, world frame
        self.pending: dict[tuple[str, int], list[Horizon]] = {}
        self.placed: list[Horizon] = []
        self.seq, self.t = 0, 0.0
        self.ending = False  # the last tick is out: a robot that answered it may have left

    def _agent(self, i: int) -> None:
        return None  # robot i is a process

    def run(self, progress: Progress | None = None) -> RunResult:
        with tempfile.TemporaryDirectory(prefix="gmmap-explore-") as out:  # the robots' configs
            try:
                self._start(Path(out))
                return super().run(progress)
            finally:
                self._stop()

    def _start(self, out: Path) -> None:
        from gmmap.eval.emulation import launch, robot_config
        from gmmap.fleet.net.keys import listen_port

        names = [*self.names, SIM]
        ports = [listen_port() for _ in names]
        fleet = f"explore{os.getpid()}"
        own = robot_config(self.config, self.n, names, ports, fleet, out)
        self.transport = Transport(TransportConfig(fleet, SIM, own.transport))
        self.transport.subscribe(lambda *message: self.inbox.put(message))
        for i, name in enumerate(self.names):
            path = robot_config(self.config, i, names, ports, fleet, out).save(out / f"{name}.yaml")
            cmd = [
                sys.executable, "-c", "from gmmap.cli import main; main()", "robot",
                "--explore", "--sim-index", str(i), "--config", str(path),
            ]  # fmt: skip
            self.procs.append(launch(cmd, self.log, self.readers))
        self.log(f"{self.n} robot processes exploring {self.world.name} (fleet {fleet})")
        self._wait(lambda: self.ready >= set(self.names), "every robot ready", START_TIMEOUT_S)

    def _stop(self) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.wait()
        for reader in self.readers:
            reader.join(timeout=5)
        if self.transport is not None:
            self.transport.close()

    # ---- one lockstep -----------------------------------------------------------------------

    def _tick(self, t: float, dt: float, spin: float) -> list[bool]:
        self.t = t
        self._exchange(Tick(t, self._poses(), dict(self.sent), decide=t >= spin))
        return [self._move(i, t, dt, spin) for i in range(self.n)]

    def _finish(self) -> list[str]:
        self.ending = True
        self._exchange(Tick(self.t, self._poses(), dict(self.sent), end=True))
        deadline = time.monotonic() + EXIT_TIMEOUT_S
        codes = [p.wait(timeout=max(deadline - time.monotonic(), 0.1)) for p in self.procs]
        if any(codes):
            raise RuntimeError(f"robot processes exited with {codes}; see the log above")
        return [s.status for s in self.answers]

    def _decide(self, i: int, t: float) -> tuple[np.ndarray | None, bool]:
        step = self.answers[i]
        direction = None if step.direction is None else np.array(step.direction)
        return direction, moving_on(step.status)

    def _horizons(self) -> list[Horizon]:
        return self.placed

    def _poses(self) -> dict[str, list[float]]:
        bodies = zip(self.names, self.bodies, strict=True)
        return {name: [*map(float, b.xy), float(b.yaw)] for name, b in bodies}

    def _exchange(self, tick: Tick) -> None:
        """Sends ``tick``; waits for every robot's answer and for every message it sent."""
        assert self.transport is not None
        self.transport.publish("tick", self.seq, encode_json(tick))
        keys = [(name, self.seq) for name in self.names]
        self._wait(lambda: all(k in self.steps for k in keys), f"the answers to tick {self.seq}")
        self.answers = [self.steps.pop(k) for k in keys]
        for i, (name, step) in enumerate(zip(self.names, self.answers, strict=True)):
            self.sent[name], self.bytes[i] = step.sent, step.bytes
        heard = lambda: all(self.heard[n] >= self.sent[n] for n in self.names)  # noqa: E731
        self._wait(heard, f"the messages sent by tick {self.seq}")
        self.seq += 1

    def _wait(self, done: Callable[[], bool], what: str, timeout: float = TICK_TIMEOUT_S) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            codes = [p.poll() for p in self.procs]
            if any(c is not None and (c != 0 or not self.ending) for c in codes):
                raise RuntimeError(f"a robot process ended ({codes}) before {what}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"no {what} in {timeout:.0f} s")
            with contextlib.suppress(queue.Empty):
                self._take(*self.inbox.get(timeout=0.5))

    def _take(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        if robot not in self.sent:
            return
        if kind == "ready":
            self.ready.add(robot)
        elif kind == "step":
            self.steps[(robot, seq)] = decode_step(payload)
        elif kind in DATA:
            self.heard[robot] += 1
            try:
                self._place(robot, kind, seq, payload)
            except (DecodeError, FileFormatError) as exc:  # heard: the tick goes on
                self.log(f"dropping {kind} {seq} of {robot}: {exc}")

    def _place(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        """A robot's submap or horizons, placed in the world for coverage."""
        start = self.map_to_world[self.names.index(robot)]
        if kind == "submap":
            submap = decode(payload)
            anchor = start @ submap.anchor
            self.coverage.add_gmm(submap.gmm.transform(anchor))
            self.anchors[(robot, seq)] = anchor
        elif kind == "horizons":
            self.pending[(robot, seq)] = decode_horizons(payload)
        for key in set(self.pending) & set(self.anchors):
            self.placed += [h.moved(self.anchors[key]) for h in self.pending.pop(key)]


def run_processes(
    config: Config, robots: int | None = None, progress: Progress | None = None
) -> RunResult:
    """One exploration run of ``config``'s world with each robot a process; ``progress``
    also gets their output."""
    return ProcessTeam(config, robots, progress or (lambda line: None)).run(progress)
