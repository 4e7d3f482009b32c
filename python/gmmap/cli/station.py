"""``gmmap station``: watch a fleet live in the browser (`gmmap.fleet.node.station`,
`gmmap.io.liveview`)."""

from __future__ import annotations

import json
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path

import click

from gmmap.cli.common import config_option, log, setting
from gmmap.config import Config


@click.command("station")
@setting("--fleet", "robot.fleet", "The fleet to watch.")
@setting("--id", "station.name", "The station's name in the fleet.")
@setting("--peer", "transport.connect", "Zenoh endpoint of a robot.", multiple=True)
@setting("--port", "transport.port", "Loopback listen port (0: free).", type=int)
@setting("--listen", "transport.listen", "Zenoh listen endpoint.", multiple=True)
@setting("--credentials", "security.credentials", "The station's folder (gmmap fleet add "
         "--role station): TLS, and Zenoh lets it subscribe and query only.")  # fmt: skip
@setting("--web-port", "station.web_port", "Where Rerun's web viewer is served (0: not).",
         type=int)  # fmt: skip
@setting("--grpc-port", "station.grpc_port", "Where the view data is served (Rerun gRPC).",
         type=int)  # fmt: skip
@setting("--host", "station.host", "Address to serve the view on.")
@setting("--every", "station.every_s", "Seconds between view updates.", type=float)
@click.option("--save", type=click.Path(dir_okay=False, path_type=Path),
              help="Also record the view to this .rrd (replay: rerun FILE).")  # fmt: skip
@click.option("--duration", type=float, help="Stop after this many seconds (default: Ctrl-C).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path))
@config_option
def command(
    save: Path | None,
    duration: float | None,
    report_path: Path | None,
    config: Config,
) -> None:
    """Watch a fleet: receive every submap, merge, and serve a live view in the browser.

    The station sends nothing of its own (no adverts, no answers, no liveliness token); it
    catches up on what it missed by fetching. Open the printed address; Ctrl-C stops it."""
    from gmmap.fleet.node.station import StationNode
    from gmmap.io.liveview import LiveView

    o = config.station
    config = replace(config, robot=replace(config.robot, name=o.name))
    view = LiveView(o.name, o.grpc_port, o.web_port or None, save, o.host)
    node = StationNode(config)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    node.start()
    plain = f"plain {config.transport.link_protocol.upper()}"
    secured = "secured" if config.security.credentials else plain
    log(f"{o.name}: watching fleet {config.robot.fleet} ({secured}); view at {view.url or '-'}"
        f" (data: {view.data_url})")  # fmt: skip
    end = None if duration is None else time.monotonic() + duration
    try:
        watch(node, view, o.every_s, stop, end)
    finally:
        report = node.report()
        node.stop()
    shown = {f"{r}/{seq}": t for (r, seq), t in sorted(view.first_shown.items())}
    report.update(view_updates=view.updates, shown_at=shown, url=view.url)
    if report_path is not None:
        report_path.parent.mkdir(parents=True, exist_ok=True)
        report_path.write_text(json.dumps(report, indent=1, default=str))


def watch(node, view, every: float, stop: threading.Event, end: float | None) -> None:
    """Updates ``view`` every ``every`` s until ``stop`` or ``end``; a line per change."""
    last = None
    while not stop.is_set() and (end is None or time.monotonic() < end):
        view.update(node)
        held = list(node.mapper.submaps.copy())
        now = (len(held), node.counts["optimised"])
        if now != last:
            robots = len({r for r, _ in held})
            log(f"{node.robot}: {now[0]} submaps of {robots} robots, groups {node.groups()}")
            last = now
        stop.wait(every)
