"""``gmmap sim``: simulated robots' recordings written as datasets."""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path

import click

from gmmap.cli.common import as_json_option, config_option, setting, sim_settings
from gmmap.config import Config


@click.command("sim")
@sim_settings
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output folder: one folder per robot (TUM RGB-D for depth, PLY scans for lidar), "
    "world.json, sim.json, config.yaml.",
)
@click.option("--max-frames", type=int, help="Keep only each robot's first frames.")
@setting("--lidar-range", "sim.lidar_range", "LiDAR maximum range (m).", type=float)
@setting("--noise/--no-noise", "sim.noise", "Sensor noise (depth or range).")
@config_option
@as_json_option
def command(out: Path, max_frames: int | None, config: Config, as_json: bool) -> None:
    """Simulate robots with depth cameras or LiDARs in a world and write their recordings.

    Each robot's folder reads back with `gmmap.io.datasets.open` (and `gmmap info`): depth PNGs
    in a TUM RGB-D folder, or one PLY per LiDAR scan with poses.txt; ground truth in the world
    frame, odometry (the drift model of gmmap.math.drift, gravity-referenced: heading and
    position drift, roll and pitch do not) in the robot's own map frame. sim.json holds each
    robot's map→world transform, which the robots never see.
    """
    from gmmap.io import sim as s
    from gmmap.math.drift import Drift

    o = config.sim
    run = s.simulate_options(o, max_frames)
    drift = Drift.per_metre(o.drift, o.seed, s.UP)
    total = sum(len(r) for r in run)
    with click.progressbar(
        length=total, label=f"simulating {o.world}", file=sys.stderr, show_pos=True
    ) as bar:
        meta = s.write_run(
            run, out, o.seed, progress=lambda name, i, n: bar.update(1), drift=asdict(drift)
        )
    config.save(out)
    if as_json:
        click.echo(json.dumps(meta))
    else:
        for r in meta["robots"]:
            click.echo(f"{r['name']}: {r['frames']} frames → {out / r['name']}")
