"""The one command-line entry point: ``gmmap``."""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path

import click

from gmmap import __version__


def _log(msg: str) -> None:
    click.echo(msg, err=True)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gmmap")
def main() -> None:
    """gmmap: multi-robot mapping with Gaussian Mixture Model submaps."""


@main.command()
@click.option("--components", default=100, show_default=True, help="GMM components.")
@click.option("--voxel", default=0.02, show_default=True, help="Voxel size before fitting (m).")
@click.option(
    "--covariance", type=click.Choice(["diag", "full"]), default="diag", show_default=True
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def demo(components: int, voxel: float, covariance: str, as_json: bool) -> None:
    """Fit a GMM to real TUM fr1_xyz depth frames shipped with gmmap and report it."""
    from gmmap.demo import run_demo

    r = run_demo(components, voxel, covariance, log=_log)
    if as_json:
        click.echo(json.dumps(r))
        return
    click.echo(
        f"frames          {r['frames']}\n"
        f"points          {r['raw_points']:,} raw, {r['points']:,} voxelised ({voxel} m)\n"
        f"components      {r['components']} ({covariance}), {r['iterations']} EM iterations, "
        f"converged={r['converged']}\n"
        f"log-likelihood  {r['log_likelihood']:.4f} per point\n"
        f"float32 bytes   GMM {r['gmm_float32_bytes']:,} vs points {r['points_float32_bytes']:,} "
        f"({r['compression']:.0f}x smaller)\n"
        f"time            load {r['load_time_s'] * 1e3:.0f} ms, fit {r['fit_time_s'] * 1e3:.1f} ms"
    )


@main.command()
@click.option(
    "--world",
    "world_name",
    default="office",
    show_default=True,
    help="A built-in world (office, corner, passage, clutter, front-obstacle) or a "
    "world .json file.",
)
@click.option("--robots", default=3, show_default=True, help="Number of robots.")
@click.option("--seed", default=0, show_default=True, help="Seeds sensor noise and odometry.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output folder: one TUM-format folder per robot, world.json, sim.json.",
)
@click.option("--frames", "max_frames", type=int, help="Keep only each robot's first frames.")
@click.option("--rate", default=5.0, show_default=True, help="Frames per second.")
@click.option("--speed", default=0.5, show_default=True, help="Driving speed (m/s).")
@click.option("--width", default=640, show_default=True, help="Depth image width (px).")
@click.option("--height", default=480, show_default=True, help="Depth image height (px).")
@click.option("--noise/--no-noise", default=True, show_default=True, help="Depth noise.")
@click.option(
    "--drift-translation",
    default=0.02,
    show_default=True,
    help="Odometry translation noise per axis, as a fraction of the distance driven.",
)
@click.option(
    "--drift-rotation",
    default=0.005,
    show_default=True,
    help="Odometry rotation noise per axis, radians per metre driven.",
)
@click.option(
    "--drift-turn",
    default=0.02,
    show_default=True,
    help="Odometry rotation noise per axis, radians per radian turned.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the run's metadata as JSON.")
def sim(
    world_name: str,
    robots: int,
    seed: int,
    out: Path,
    max_frames: int | None,
    rate: float,
    speed: float,
    width: int,
    height: int,
    noise: bool,
    drift_translation: float,
    drift_rotation: float,
    drift_turn: float,
    as_json: bool,
) -> None:
    """Simulate robots with depth cameras in a world and write their recordings.

    Each robot's folder reads back with `gmmap.datasets.open`: depth PNGs, ground truth in the
    world frame, odometry (with the drift model of gmmap.datasets.drift) in the robot's own map
    frame. sim.json holds each robot's map→world transform, which the robots never see.
    """
    from gmmap import sim as s
    from gmmap.datasets.drift import Drift

    world = s.World.load(world_name) if world_name.endswith(".json") else s.get_world(world_name)
    cam = s.DepthCamera(
        width=width,
        height=height,
        fx=525.0 * width / 640,
        fy=525.0 * height / 480,
        cx=(width - 1) / 2,
        cy=(height - 1) / 2,
        noise=noise,
    )
    drift = Drift(
        translation=drift_translation, rotation_per_m=drift_rotation, rotation_per_rad=drift_turn
    )
    run = s.simulate(
        world, robots, seed, cam, s.Motion(speed=speed, rate=rate), drift, max_frames=max_frames
    )
    total = sum(len(r) for r in run)
    with click.progressbar(
        length=total, label=f"simulating {world.name}", file=sys.stderr, show_pos=True
    ) as bar:
        meta = s.write_run(
            run, out, seed, progress=lambda name, i, n: bar.update(1), drift=asdict(drift)
        )
    if as_json:
        click.echo(json.dumps(meta))
    else:
        for r in meta["robots"]:
            click.echo(f"{r['name']}: {r['frames']} frames → {out / r['name']}")


@main.group()
def bench() -> None:
    """Benchmarks against named baselines (ratios, measured in one run)."""


@bench.command("em")
@click.option("--points", "n", default=50_000, show_default=True, help="Points to fit.")
@click.option("--components", "k", default=100, show_default=True)
@click.option("--iterations", default=30, show_default=True, help="Fixed EM iterations (tol=0).")
@click.option(
    "--covariance", type=click.Choice(["diag", "full"]), default="diag", show_default=True
)
@click.option(
    "--data",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="TUM RGB-D folder (default: ../shared/data/tum_fr1_xyz, else the bundled slice).",
)
@click.option("--repeats", default=3, show_default=True, help="Best time of this many runs.")
@click.option("--scaling", is_flag=True, help="Also time N = 10k…500k and K = 25…400.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def bench_em(
    n: int,
    k: int,
    iterations: int,
    covariance: str,
    data: Path | None,
    repeats: int,
    scaling: bool,
    as_json: bool,
) -> None:
    """EM speed and log-likelihood against scikit-learn's GaussianMixture."""
    from gmmap import bench as b

    root = data or b.default_scene()
    _log(f"scene: {root}")
    pts = b.scene_points(n, root)
    _log(f"comparing on {len(pts):,} points, K={k}, {iterations} iterations")
    result = b.em_comparison(pts, k, iterations, covariance, repeats)
    result["scene"] = str(root)
    if scaling:
        big = b.scene_points(500_000, root, voxel=None, frames=80)
        ns = [10_000, 50_000, 100_000, 200_000, 500_000]
        result["scaling_n"] = b.em_scaling(ns, [k], big, progress=_log)
        result["scaling_k"] = b.em_scaling([n], [25, 50, 100, 200, 400], pts, progress=_log)
    if as_json:
        click.echo(json.dumps(result, indent=2))
        return
    g, s = result["gmmap"], result["sklearn"]
    click.echo(f"gmmap    {g['time_s'] * 1e3:8.1f} ms  log-likelihood {g['log_likelihood']:.4f}")
    if s is None:
        click.echo("sklearn  not installed (pip install scikit-learn): no baseline")
    else:
        click.echo(
            f"sklearn  {s['time_s'] * 1e3:8.1f} ms  log-likelihood {s['log_likelihood']:.4f}"
        )
        click.echo(
            f"speed-up {result['speedup']:.1f}x, log-likelihood difference "
            f"{result['log_likelihood_diff']:+.4f}"
        )
    for key in ("scaling_n", "scaling_k"):
        for row in result.get(key, []):
            click.echo(
                f"N={row['points']:>7,} K={row['components']:>3}: "
                f"{row['time_s'] * 1e3:8.1f} ms, peak +{row['peak_extra_mb']:.1f} MB"
            )


@main.command()
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["tum", "kitti", "pointfiles", "rosbag"]),
    help="Skip format detection.",
)
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@click.option("--topic", help="ROS bag: the PointCloud2 topic.")
@click.option("--odom-topic", help="ROS bag: the odometry / pose topic.")
@click.option("--voxel", type=float, help="KITTI, point files, ROS bag: voxel size (m).")
@click.option(
    "--sample", default=50, show_default=True, help="Frames read to count points per frame."
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def info(
    path: Path,
    fmt: str | None,
    stride: int | None,
    topic: str | None,
    odom_topic: str | None,
    voxel: float | None,
    sample: int,
    as_json: bool,
) -> None:
    """Summarise a dataset: format, frames, duration, path length, points per frame."""
    from gmmap import datasets
    from gmmap.errors import GmmapError

    given = dict(stride=stride, topic=topic, odom_topic=odom_topic, voxel=voxel)
    options = {k: v for k, v in given.items() if v is not None}
    try:
        seq = datasets.open(path, format=fmt, **options)
        r = {"path": str(path), **datasets.describe(seq, max_frames=max(1, sample))}
    except (GmmapError, FileNotFoundError) as exc:
        # Bad data is the user's to fix: one line naming the file, not a traceback.
        raise click.ClickException(str(exc)) from exc
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
        f"points / frame  {r['points_per_frame']:,.0f}{note}"
    )


if __name__ == "__main__":
    sys.exit(main())
