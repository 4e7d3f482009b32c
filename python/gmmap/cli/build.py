"""``gmmap build``: frames → point buffer → EM → model selection → a folder of submaps."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from gmmap.cli.common import (
    COVARIANCE,
    as_json_option,
    config_option,
    frame_options,
    open_data,
    ros_settings,
    setting,
    submap_size,
)
from gmmap.config import Config


@click.command("build")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output folder: one file per submap, index.json and config.yaml.",
)
@click.option("--robot", default="robot", show_default=True, help="The robot's name.")
@submap_size
@setting("--strategy", "build.strategy", "How a submap is fitted.",
         type=click.Choice(["points", "gmm-merge", "per-frame"]))  # fmt: skip
@setting("--components", "build.n_components", "Components fitted.", type=int)
@COVARIANCE
@setting("--voxel", "build.voxel_size", "Point-buffer voxel size (m).", type=float)
@setting("--novelty", "build.min_novelty", "Skip frames adding fewer new voxels.", type=float)
@setting("--select/--no-select", "build.select", "Adaptive model selection.")
@setting("--kl-threshold", "select.kl_threshold", "Merge pairs under this KL.", type=float)
@setting("--holdout", "build.holdout", "Points withheld to score the submaps.", type=float)
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@ros_settings
@frame_options
@config_option
@as_json_option
def command(
    path: Path, out: Path, robot: str, stride: int | None, pick, config: Config, as_json: bool
) -> None:
    """Build GMM submaps from a dataset (frames → point buffer → EM → model selection)."""
    from gmmap.mapping.submap import build_submaps, write_submaps

    frames = pick(open_data(path, stride, config.ros))
    with click.progressbar(
        iter(frames), length=len(frames), file=sys.stderr, label=f"building submaps of {path}"
    ) as bar:
        submaps = list(build_submaps(bar, robot, config.build, config.select))
    index = write_submaps(submaps, out, source=str(path), options=config.build)
    config.save(out)
    if as_json:
        click.echo(json.dumps({"submaps": index["submaps"]}))
        return
    click.echo(
        f"{'seq':>4} {'frames':>6} {'points':>7} {'K before':>8} {'K after':>7} "
        f"{'bytes':>6} {'held-out LL before → after':>27} {'time':>8}"
    )
    for s in index["submaps"]:
        ll = (
            "—"
            if s["heldout_ll_before"] is None
            else f"{s['heldout_ll_before']:+.4f} → {s['heldout_ll_after']:+.4f}"
        )
        click.echo(
            f"{s['seq']:>4} {s['frames']:>6} {s['points']:>7} {s['components_before']:>8} "
            f"{s['components_after']:>7} {s['bytes_float32']:>6} {ll:>27} "
            f"{s['time_s'] * 1e3:>6.0f} ms"
        )
    click.echo(f"{len(submaps)} submaps → {out}")
