"""``gmmap info``: what a dataset holds."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gmmap.cli.common import config_option, open_data, ros_settings
from gmmap.config import Config


@click.command("info")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["tum", "kitti", "pointfiles", "rosbag"]),
    help="Skip format detection.",
)
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@ros_settings
@click.option("--voxel", type=float, help="KITTI, point files, ROS bag: voxel size (m).")
@click.option(
    "--sample", default=50, show_default=True, help="Frames read to count points per frame."
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@config_option
def command(
    path: Path,
    fmt: str | None,
    stride: int | None,
    voxel: float | None,
    sample: int,
    as_json: bool,
    config: Config,
) -> None:
    """Summarise a dataset: format, frames, duration, path length, points per frame.

    PATH is detected as one of: a TUM RGB-D folder (depth.txt; also keyframe exports with
    truth_cam_poses.txt, and `gmmap sim` depth runs), a KITTI odometry sequence, a folder of
    PLY/PCD files with a TUM-format poses file (also `gmmap sim --sensor lidar` runs), or a
    ROS 1/2 bag (its topics and frames: the flags, or the config's ros section). The path
    length follows the poses the loader yields (the odometry where there is one); the ground
    truth's is given too when the data has one.
    """
    from gmmap.io import datasets

    options = {} if voxel is None else {"voxel": voxel}
    seq = open_data(path, stride, config.ros, fmt, **options)
    r = {"path": str(path), **datasets.describe(seq, max_frames=max(1, sample))}
    if as_json:
        click.echo(json.dumps(r))
        return
    sampled = r.get("points_per_frame_sampled")
    note = f" (mean of {sampled} frames spread evenly)" if sampled else ""
    click.echo(
        f"format          {r['format']}\n"
        f"frames          {r['frames']}\n"
        f"duration        {r['duration_s']:.2f} s\n"
        f"path length     {r['path_length_m']:.2f} m\n"
        + (f"gt path length  {r['gt_path_length_m']:.2f} m\n" if "gt_path_length_m" in r else "")
        + f"points / frame  {r['points_per_frame']:,.0f}{note}"
    )
