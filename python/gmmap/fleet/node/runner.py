"""The ``gmmap robot`` process around a `RobotNode`: signals, lingering, the report and the map."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from gmmap.config import Config
from gmmap.fleet.node.robot import BuiltCallback, RobotNode
from gmmap.mapping.frame import Frame
from gmmap.mapping.live import LiveInput

if TYPE_CHECKING:
    from gmmap.mapping.mapper import Mapper


def run_robot(
    config: Config,
    frames: Sequence[Frame] | LiveInput,
    report_path: Path | None = None,
    on_finish: Callable[[Mapper], dict] | None = None,
    on_built: BuiltCallback | None = None,
    progress: Callable[[str], None] | None = None,
    on_start: Callable[[RobotNode], object] | None = None,
) -> dict:
    """Run a node over ``frames``, linger, report, shut down. SIGINT/SIGTERM stop it cleanly
    (the report is still written, with what was done). ``on_finish`` receives the node's
    mapper at the end, unless interrupted (to save its map, trajectories, …), and returns what
    to add to the report. ``on_start`` receives the node once it started (a ROS bridge that
    publishes its outputs, say)."""
    import signal

    say = progress or (lambda _m: None)
    name = config.robot.name
    node = RobotNode(config, on_built)
    stopped = threading.Event()

    def on_signal(signum, _frame):
        say(f"{name}: signal {signum}, stopping")
        stopped.set()
        node.request_stop()

    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, on_signal)
    try:
        node.start()
        if on_start is not None:
            on_start(node)
        if config.robot.wait_for:
            ok = node.transport.wait_for_peers(config.robot.wait_for, config.robot.wait_timeout)
            peers = ", ".join(node.transport.peers()) or "none"
            say(f"{name}: peers {'present' if ok else 'missing'}: {peers}")
        count = f"{len(frames)} frames" if hasattr(frames, "__len__") else "live frames"
        resumed = f"resuming at {node.frames_consumed}, {node.reloaded} submaps reloaded"
        say(f"{name}: {count}, {resumed}")
        builder = node.start_frames(frames)
        while builder.is_alive() and not stopped.is_set():
            builder.join(0.1)
        complete = node.linger(config.robot.linger, progress=say)
        report = node.report()
        report["interrupted"] = stopped.is_set()
        report["complete"] = complete
        if on_finish is not None and not stopped.is_set():
            report.update(on_finish(node.mapper))
        if report_path is not None:
            report_path.parent.mkdir(parents=True, exist_ok=True)
            report_path.write_text(json.dumps(report, indent=1))
    finally:
        node.stop()
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return report
