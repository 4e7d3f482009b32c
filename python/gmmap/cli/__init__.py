"""The one command-line entry point: ``gmmap``."""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gmmap import __version__

if TYPE_CHECKING:  # the simulator is imported only by the commands that run it
    from gmmap.io.sim import Lidar


def _log(msg: str) -> None:
    click.echo(msg, err=True)


def _sensor_option(help_text: str):
    return click.option(
        "--sensor",
        type=click.Choice(["lidar", "depth"]),  # gmmap.io.sim.ROBOT_SENSORS, kept import-free
        default="lidar",
        show_default=True,
        help=help_text,
    )


_ODOMETRY_DRIFT = click.option(
    "--odometry-drift",
    default=0.02,
    show_default=True,
    help="Odometry noise of the pose graph, per metre (0.002 for motion-capture poses).",
)
_MIN_MATCHES = click.option(
    "--min-matches",
    default=1,
    show_default=True,
    type=click.IntRange(min=1),
    help="Join two robots' maps only once this many of their matches agree (2: a lone "
    "aliased match cannot merge them).",
)
_MIN_CONFIDENCE = click.option(
    "--min-confidence", default=0.75, show_default=True, help="C_thr of the verification."
)


class _Commands(click.Group):
    """Bad input is the user's to fix: one line naming it, not a traceback."""

    def invoke(self, ctx: click.Context):
        from gmmap.errors import GmmapError

        try:
            return super().invoke(ctx)
        except (GmmapError, FileNotFoundError) as exc:
            raise click.ClickException(str(exc)) from exc


@click.group(cls=_Commands, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="gmmap")
def main() -> None:
    """gmmap: multi-robot mapping with Gaussian Mixture Model submaps."""


@main.command()
@click.option("--robots", default=3, show_default=True, help="Simulated robots (processes).")
@click.option("--world", default="office", show_default=True, help="A built-in world.")
@click.option("--seed", default=0, show_default=True, help="Sensor noise and odometry seed.")
@click.option("--frames-per-submap", default=20, show_default=True)
@click.option("--max-frames", type=int, help="Use only each robot's first frames.")
@_sensor_option("Simulated sensor: a 16-beam 360° LiDAR or a 60° depth camera (views alias).")
@click.option("--sim-width", default=320, show_default=True, help="Depth image width (px).")
@click.option(
    "--drift",
    default=0.02,
    show_default=True,
    help="Odometry drift per metre (and rad per rad turned) of the simulated robots.",
)
@_MIN_MATCHES
@click.option("--linger", default=5.0, show_default=True, help="Seconds robots stay after.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder (stores, reports, map.png); default a new temporary folder.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def demo(
    robots: int,
    world: str,
    seed: int,
    frames_per_submap: int,
    max_frames: int | None,
    sensor: str,
    sim_width: int,
    drift: float,
    min_matches: int,
    linger: float,
    out: Path | None,
    as_json: bool,
) -> None:
    """Simulated robots as separate processes share GMM submaps over Zenoh and merge maps."""
    from gmmap.cli.demo import format_report, run_demo

    r = run_demo(
        robots, world, seed, frames_per_submap, max_frames, sensor, sim_width, drift, linger,
        out, _log, min_matches=min_matches,
    )  # fmt: skip
    click.echo(json.dumps(r) if as_json else format_report(r))


@main.command()
@click.option("--id", "robot_id", required=True, help="This robot's name (unique in the fleet).")
@click.option(
    "--fleet", required=True, help="The fleet's name: robots of other fleets are ignored."
)
@click.option("--data", type=click.Path(exists=True, path_type=Path), help="A dataset to map.")
@click.option("--sim", "sim_world", help="Render a simulated robot in this world instead.")
@click.option("--sim-index", type=int, default=0, show_default=True, help="Which simulated robot.")
@click.option("--robots", default=3, show_default=True, help="--sim: robots in the simulation.")
@click.option("--seed", default=0, show_default=True, help="--sim: noise and odometry seed.")
@_sensor_option("--sim: a 16-beam 360° LiDAR or a 60° depth camera (narrow views alias).")
@click.option("--sim-width", default=640, show_default=True, help="--sim: depth image width.")
@click.option(
    "--sim-drift", default=0.02, show_default=True, help="--sim: odometry drift per metre."
)
@click.option("--stride", type=int, help="--data (TUM): pixel stride of the back-projection.")
@click.option("--frames", "frame_range", help="Use only the frames START:STOP.")
@click.option("--max-frames", type=int, help="Use only the first frames (after --frames).")
@click.option("--listen", multiple=True, help="Zenoh listen endpoint (default loopback).")
@click.option("--port", default=0, show_default=True, help="Loopback listen port (0: free).")
@click.option("--peer", multiple=True, help="Zenoh endpoint of another robot to connect to.")
@click.option("--wait-for", multiple=True, help="Wait for these robots before mapping.")
@click.option("--store", type=click.Path(dir_okay=False, path_type=Path), help="Store file.")
@click.option("--frames-per-submap", default=20, show_default=True)
@click.option("--components", default=100, show_default=True, help="Components fitted.")
@click.option(
    "--covariance", type=click.Choice(["diag", "full"]), default="diag", show_default=True
)
@_ODOMETRY_DRIFT
@_MIN_MATCHES
@_MIN_CONFIDENCE
@click.option("--linger", default=5.0, show_default=True, help="Seconds to stay after mapping.")
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--map-png",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the merged map of this robot's group as a PNG (and, with the viz extra, "
    "a Rerun recording beside it: .rrd).",
)
@click.option("--json", "as_json", is_flag=True, help="One JSON status line per submap.")
def robot(
    robot_id: str,
    fleet: str,
    data: Path | None,
    sim_world: str | None,
    sim_index: int,
    robots: int,
    seed: int,
    sensor: str,
    sim_width: int,
    sim_drift: float,
    stride: int | None,
    frame_range: str | None,
    max_frames: int | None,
    listen: tuple[str, ...],
    port: int,
    peer: tuple[str, ...],
    wait_for: tuple[str, ...],
    store: Path | None,
    frames_per_submap: int,
    components: int,
    covariance: str,
    odometry_drift: float,
    min_matches: int,
    min_confidence: float,
    linger: float,
    report_path: Path | None,
    map_png: Path | None,
    as_json: bool,
) -> None:
    """Run one robot node: map, share submaps over Zenoh, match, optimise, report."""
    from gmmap.fleet.robot import RobotConfig, run_robot
    from gmmap.mapping.backend import BackendOptions
    from gmmap.mapping.place import PlaceOptions
    from gmmap.mapping.submap import BuildOptions

    if (data is None) == (sim_world is None):
        raise click.UsageError("give exactly one of --data and --sim")
    if data is not None:
        from gmmap.io import datasets

        frames = datasets.open(data, **({"stride": stride} if stride else {}))
    else:
        from gmmap.io import sim as s
        from gmmap.math.drift import Drift

        world = s.World.load(sim_world) if sim_world.endswith(".json") else s.get_world(sim_world)
        device = s.robot_sensor(sensor, sim_width)
        drift = Drift.per_metre(sim_drift, seed, s.UP)
        run = s.simulate(world, robots, seed, device, odometry=drift)
        if not 0 <= sim_index < len(run):
            raise click.BadParameter(f"0..{len(run) - 1}", param_hint="--sim-index")
        frames = run[sim_index]
    chosen = range(len(frames))[_slice(frame_range)] if frame_range else range(len(frames))
    chosen = chosen[:max_frames] if max_frames else chosen
    view = _Frames(frames, chosen)
    config = RobotConfig(
        robot=robot_id,
        fleet=fleet,
        store=store,
        listen=tuple(listen) if listen else None,
        port=port,
        connect=tuple(peer),
        build=BuildOptions(
            frames_per_submap=frames_per_submap, n_components=components, covariance=covariance
        ),
        linger=linger,
        wait_for=tuple(wait_for),
        backend=BackendOptions.for_drift(odometry_drift, min_matches=min_matches),
        place=PlaceOptions(min_confidence=min_confidence),
    )

    def status(line: dict) -> None:
        if as_json:
            click.echo(json.dumps(line))
        else:
            _log(
                f"{line['robot']}: submap {line['seq']} ({line['bytes']} B), "
                f"{line['received']} received, {line['matches']} matches, groups {line['groups']}"
            )

    r = run_robot(config, view, report_path, map_png, status, _log)
    _log(
        f"{robot_id}: {r['submaps_built']} built, {r['submaps_received']} received, "
        f"{r['matches_accepted']} matches accepted, {r['matches_rejected']} rejected, "
        f"groups {r['groups']}"
    )


class _Frames:
    """Frames ``indices`` of a lazy sequence, itself a lazy sequence."""

    def __init__(self, frames, indices: range) -> None:
        self.frames, self.indices = frames, indices

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int):
        return self.frames[self.indices[i]]


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
    help="Output folder: one folder per robot (TUM RGB-D for depth, PLY scans for lidar), "
    "world.json, sim.json.",
)
@click.option("--frames", "max_frames", type=int, help="Keep only each robot's first frames.")
@click.option("--rate", default=5.0, show_default=True, help="Frames per second.")
@click.option("--speed", default=0.5, show_default=True, help="Driving speed (m/s).")
@click.option(
    "--sensor",
    type=click.Choice(["depth", "lidar"]),
    default="depth",
    show_default=True,
    help="A depth camera (Kinect-like) or a spinning LiDAR (VLP-16-like).",
)
@click.option("--width", default=640, show_default=True, help="Depth: image width (px).")
@click.option("--height", default=480, show_default=True, help="Depth: image height (px).")
@click.option(
    "--beams",
    default=16,
    show_default=True,
    type=click.IntRange(min=1),
    help="Lidar: channels, spread over ±15° of elevation.",
)
@click.option(
    "--lidar-range",
    default=30.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Lidar: maximum range (m).",
)
@click.option(
    "--noise/--no-noise", default=True, show_default=True, help="Sensor noise (depth or range)."
)
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
    help="Odometry heading noise, radians per metre driven.",
)
@click.option(
    "--drift-turn",
    default=0.02,
    show_default=True,
    help="Odometry heading noise, radians per radian turned.",
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
    sensor: str,
    width: int,
    height: int,
    beams: int,
    lidar_range: float,
    noise: bool,
    drift_translation: float,
    drift_rotation: float,
    drift_turn: float,
    as_json: bool,
) -> None:
    """Simulate robots with depth cameras or LiDARs in a world and write their recordings.

    Each robot's folder reads back with `gmmap.io.datasets.open` (and `gmmap info`): depth PNGs in
    a TUM RGB-D folder, or one PLY per LiDAR scan with poses.txt; ground truth in the world
    frame, odometry (with the drift model of gmmap.math.drift, gravity-referenced: heading
    and position drift, roll and pitch do not) in the robot's own map frame. sim.json holds
    each robot's map→world transform, which the robots never see.
    """
    from gmmap.io import sim as s
    from gmmap.math.drift import Drift

    world = s.World.load(world_name) if world_name.endswith(".json") else s.get_world(world_name)
    if sensor == "lidar":
        device = _lidar(beams, lidar_range, noise)
    else:
        device = s.DepthCamera.scaled(width, height, noise)
    drift = Drift(
        translation=drift_translation,
        rotation_per_m=drift_rotation,
        rotation_per_rad=drift_turn,
        up=s.UP,
    )
    run = s.simulate(
        world, robots, seed, device, s.Motion(speed=speed, rate=rate), drift, max_frames=max_frames
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


def _lidar(beams: int, max_range: float, noise: bool) -> Lidar:
    """The default LiDAR with ``beams`` channels over the same elevation span."""
    from gmmap.io.sim import Lidar

    return Lidar(beams=beams, max_range=max_range, noise_std=Lidar.noise_std if noise else 0.0)


@main.command()
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output folder: one file per submap and index.json.",
)
@click.option("--robot", default="robot", show_default=True, help="The robot's name.")
@click.option("--frames-per-submap", default=40, show_default=True, help="Frames per submap.")
@click.option(
    "--strategy",
    type=click.Choice(["points", "gmm-merge", "per-frame"]),
    default="points",
    show_default=True,
)
@click.option("--components", default=100, show_default=True, help="Components fitted.")
@click.option(
    "--covariance", type=click.Choice(["diag", "full"]), default="diag", show_default=True
)
@click.option("--voxel", default=0.05, show_default=True, help="Point-buffer voxel size (m).")
@click.option(
    "--novelty",
    default=0.05,
    show_default=True,
    help="Skip frames whose new voxels are under this fraction of their voxels.",
)
@click.option(
    "--select/--no-select", default=True, show_default=True, help="Adaptive model selection."
)
@click.option(
    "--kl-threshold",
    default=8.0,
    show_default=True,
    help="Selection: merge pairs whose symmetric KL divergence is below this.",
)
@click.option(
    "--holdout",
    default=0.1,
    show_default=True,
    help="Fraction of points withheld from fitting to score the submaps.",
)
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@click.option("--max-frames", type=int, help="Use only the first frames of the data.")
@click.option(
    "--frames",
    "frame_range",
    help="Use only the frames START:STOP (a Python slice, e.g. :400 or 400:).",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def build(
    path: Path,
    out: Path,
    robot: str,
    frames_per_submap: int,
    strategy: str,
    components: int,
    covariance: str,
    voxel: float,
    novelty: float,
    select: bool,
    kl_threshold: float,
    holdout: float,
    stride: int | None,
    max_frames: int | None,
    frame_range: str | None,
    as_json: bool,
) -> None:
    """Build GMM submaps from a dataset (frames → point buffer → EM → model selection)."""
    from gmmap.io import datasets
    from gmmap.mapping.submap import BuildOptions, build_submaps, write_submaps
    from gmmap.math.select import SelectOptions

    frames = datasets.open(path, **({"stride": stride} if stride else {}))
    chosen = range(len(frames))[_slice(frame_range)] if frame_range else range(len(frames))
    chosen = chosen[:max_frames] if max_frames else chosen
    n = len(chosen)
    options = BuildOptions(
        frames_per_submap=frames_per_submap,
        voxel_size=voxel,
        strategy=strategy,
        n_components=components,
        covariance=covariance,
        min_novelty=novelty,
        select=select,
        selection=SelectOptions(kl_threshold=kl_threshold),
        holdout=holdout,
    )
    with click.progressbar(
        (frames[i] for i in chosen),
        length=n,
        file=sys.stderr,
        label=f"building submaps of {path}",
    ) as bar:
        submaps = list(build_submaps(bar, robot, options))
    index = write_submaps(submaps, out, source=str(path), options=options)
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


def _slice(text: str) -> slice:
    try:
        parts = [int(p) if p.strip() else None for p in text.split(":")]
    except ValueError:
        parts = []
    if len(parts) != 2:
        raise click.BadParameter(f"{text!r} is not START:STOP", param_hint="--frames")
    return slice(*parts)


@main.command()
@click.argument(
    "folders",
    nargs=-1,
    required=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), help="Write maps here.")
@click.option("--top-k", default=5, show_default=True, help="Candidates verified per submap.")
@_MIN_CONFIDENCE
@click.option(
    "--wrong-matches",
    default=0.0,
    show_default=True,
    help="Robustness test: replace this fraction of verified matches by wrong ones.",
)
@_ODOMETRY_DRIFT
@_MIN_MATCHES
@click.option("--seed", default=0, show_default=True, help="Seeds --wrong-matches.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def merge(folders: tuple[Path, ...], out: Path | None, top_k: int, min_confidence: float,
          wrong_matches: float, odometry_drift: float, min_matches: int, seed: int,
          as_json: bool) -> None:  # fmt: skip
    """Merge submap folders of several robots (from `gmmap build`): place recognition,
    registration, the robust pose graph and a global map per connected group."""
    import numpy as np

    from gmmap.io import viz
    from gmmap.mapping.backend import BackendOptions
    from gmmap.mapping.mapper import MergeOptions
    from gmmap.mapping.mapper import merge as run_merge
    from gmmap.mapping.place import PlaceOptions
    from gmmap.mapping.submap import read_submaps

    submaps: dict = {}
    for folder in folders:
        subs = read_submaps(folder)
        if not subs:
            raise click.BadParameter(f"{folder} holds no submaps", param_hint="FOLDERS")
        if subs[0].robot in submaps:
            raise click.BadParameter(
                f"two folders of robot {subs[0].robot!r}: name them with gmmap build --robot",
                param_hint="FOLDERS",
            )
        submaps[subs[0].robot] = subs
    options = MergeOptions(
        PlaceOptions(top_k=top_k, min_confidence=min_confidence),
        BackendOptions.for_drift(odometry_drift, min_matches=min_matches),
        wrong_matches=wrong_matches,
        seed=seed,
    )
    result = run_merge(submaps, options, _log)
    report = result.report(submaps)
    if out:
        out.mkdir(parents=True, exist_ok=True)
        for ref, gmap in result.maps.items():
            gmap.save(out / f"globalmap_{ref}.npz")
            gmap.save_ply(out / f"globalmap_{ref}.ply")
            gmap.save_png(out / f"globalmap_{ref}.png")
            if viz.available():
                viz.save_rerun(gmap, out / f"globalmap_{ref}.rrd")
        (out / "merge.json").write_text(json.dumps(report, indent=1))
        _log(f"wrote the global map(s) and merge.json to {out}")
    if as_json:
        click.echo(json.dumps(report))
        return
    click.echo(
        f"{len(submaps)} robots, {report['candidates']} candidates, {report['verified']} "
        f"verified; {report['accepted_edges']} edges accepted, "
        f"{report['rejected_edges']} rejected {report['rejected_by']}"
    )
    click.echo(f"groups: {report['groups']} (reference {report['reference']})")
    for r in report["robots"]:
        t = np.array(r["to_reference"])
        yaw = np.degrees(np.arctan2(t[1, 0], t[0, 0]))
        click.echo(
            f"{r['name']:>12} → {r['reference']:<12} t = {np.round(t[:3, 3], 3).tolist()} m, "
            f"yaw {yaw:.2f}°, {r['submaps']} submaps"
        )
    from gmmap.eval.pairs import describe_pair

    for p in report.get("pairs", []):
        click.echo(f"error {describe_pair(p)}")
    if "ate_before_m" in report:
        click.echo(
            f"ATE of the anchors: {report['ate_before_m']:.3f} m before, "
            f"{report['ate_after_m']:.3f} m after optimisation; rigidly aligned "
            f"{report['ate_aligned_before_m']:.3f} m and {report['ate_aligned_after_m']:.3f} m"
        )
    from gmmap.eval.registration import describe_match_errors

    for line in describe_match_errors(report.get("match_errors", {})):
        click.echo(line)
    if "injected_wrong" in report:
        w = report["injected_wrong"]
        click.echo(f"injected wrong matches: {w['rejected']} of {w['n']} rejected")


@main.group("eval")
def evaluate() -> None:
    """The paper's experiments against ground truth (Table I, …)."""


@evaluate.command("registration")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--frames-per-submap",
    default=5,
    show_default=True,
    help="Frames per submap (the paper's Table I: 5; KITTI scans: 1).",
)
@click.option(
    "--methods",
    default="points,gmm-merge,per-frame,gicp",
    show_default=True,
    help="Comma-separated: points, gmm-merge, per-frame, gicp.",
)
@click.option(
    "--global",
    "global_mode",
    is_flag=True,
    help="Perturb each pair by a random yaw and ≤1 m and register with no guess.",
)
@click.option("--max-pairs", type=int, help="Evaluate only the first pairs.")
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@click.option("--voxel", default=0.05, show_default=True, help="Submap voxel size (m).")
@click.option(
    "--components", default=100, show_default=True, help="Components per submap (KITTI: 300)."
)
@click.option("--seed", default=0, show_default=True, help="Seeds the global perturbations.")
@click.option("--scales", help="Registration coarse-to-fine ladder, e.g. 0.5,0.1,0 (metres).")
@click.option(
    "--odometry-guess",
    is_flag=True,
    help="Start from the odometry's relative pose instead of the identity.",
)
@click.option(
    "--drift",
    type=float,
    help="Simulate odometry drift of this fraction of the distance (datasets whose "
    "poses are ground truth), with the default rotation drift.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def eval_registration(
    path: Path,
    frames_per_submap: int,
    methods: str,
    global_mode: bool,
    max_pairs: int | None,
    stride: int | None,
    voxel: float,
    components: int,
    seed: int,
    scales: str | None,
    odometry_guess: bool,
    drift: float | None,
    as_json: bool,
) -> None:
    """Register consecutive submaps and compare with ground truth (the paper's Table I)."""
    from gmmap.eval.registration import METHODS, evaluate_registration
    from gmmap.io import datasets
    from gmmap.mapping.submap import BuildOptions

    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    unknown = sorted(set(chosen) - set(METHODS))
    if unknown:
        raise click.BadParameter(
            f"unknown {unknown}; choose from {', '.join(METHODS)}", param_hint="--methods"
        )
    if "gicp" in chosen:
        try:
            import small_gicp  # noqa: F401
        except ImportError:
            _log("small_gicp is not installed (pip install small_gicp): skipping gicp")
            chosen.remove("gicp")
    loader_options: dict = {"stride": stride} if stride else {}
    if drift is not None:
        loader_options["drift"] = datasets.Drift(translation=drift)
    frames = datasets.open(path, **loader_options)
    options = BuildOptions(covariance="full", voxel_size=voxel, n_components=components)
    try:
        ladder = tuple(float(v) for v in scales.split(",")) if scales else None
    except ValueError:
        raise click.BadParameter("comma-separated numbers", param_hint="--scales") from None
    r = evaluate_registration(
        frames,
        frames_per_submap,
        chosen,
        global_mode,
        max_pairs,
        options,
        seed,
        _log,
        ladder,
        odometry_guess,
    )
    if as_json:
        click.echo(json.dumps(r))
        return
    click.echo(
        f"{r['pairs']} pairs of {frames_per_submap}-frame submaps"
        f"{' (global: no initial guess)' if global_mode else ''}"
    )
    click.echo(
        f"{'method':<10} {'t mean (m)':>10} {'t RMSE (m)':>10} {'r mean (°)':>10} "
        f"{'r RMSE (°)':>10} {'success':>8} {'time/pair':>10}"
    )
    for name, m in r["methods"].items():
        click.echo(
            f"{name:<10} {m['t_error_mean']:>10.4f} {m['t_rmse']:>10.4f} "
            f"{m['r_error_mean']:>10.3f} {m['r_rmse']:>10.3f} "
            f"{m['success_rate']:>8.1%} {m['time_per_pair_s'] * 1e3:>8.1f} ms"
        )


@evaluate.command("place")
@click.option(
    "--data",
    type=click.Path(exists=True, path_type=Path),
    help="A recording split into two robots (first and second half).",
)
@click.option("--sim", "world", help="A simulator world (default: office, unless --data).")
@click.option("--robots", default=3, show_default=True, help="Simulated robots.")
@_sensor_option("--sim: the robots' sensor.")
@click.option("--frames-per-submap", default=20, show_default=True)
@click.option(
    "--covariance", type=click.Choice(["diag", "full"]), default="full", show_default=True
)
@click.option("--top-k", default=5, show_default=True, help="Candidates verified per query.")
@click.option("--no-gicp", is_flag=True, help="Skip the points + GICP verification baseline.")
@click.option("--seed", default=0, show_default=True)
@click.option(
    "--plots",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write recall@N and precision-recall PNGs here.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def eval_place(
    data: Path | None,
    world: str | None,
    robots: int,
    sensor: str,
    frames_per_submap: int,
    covariance: str,
    top_k: int,
    no_gicp: bool,
    seed: int,
    plots: Path | None,
    as_json: bool,
) -> None:
    """Place recognition recall and verified precision (the paper's Fig. 7 and 8)."""
    from gmmap.eval import place
    from gmmap.io import datasets
    from gmmap.mapping.place import PlaceOptions

    if data is not None and world is not None:
        raise click.UsageError("give --data or --sim, not both")
    if data is not None:
        frames = datasets.open(data)
        place_set = place.split_place_set(frames, frames_per_submap, _log, covariance)
    else:
        place_set = place.sim_place_set(
            world or "office", robots, seed, frames_per_submap, _log, sensor, covariance
        )
    r = place.evaluate_place(place_set, PlaceOptions(top_k=top_k), progress=_log, gicp=not no_gicp)
    if plots:
        for png in place.plot(r, plots):
            _log(f"wrote {png}")
    if as_json:
        click.echo(json.dumps(r))
        return
    click.echo(f"{r['queries']} queries, {r['submaps']} submaps of {r['robots']} robots")
    for name in ("gmm", "points"):
        n = r[name]["recall_at_n"]
        click.echo(
            f"{name:<7} recall@1 {n[0]:.1%}  @5 {n[4]:.1%}  @25 {n[24]:.1%}  "
            f"@top-1% {r[name]['recall_at_1pct']:.1%}"
        )
    v = r["verified"]
    line = f"verified recall at 100% precision: GMM {v['gmm_recall_at_full_precision']:.1%}"
    if "points_gicp_recall_at_full_precision" in v:
        line += f", points + GICP {v['points_gicp_recall_at_full_precision']:.1%}"
    click.echo(line)
    times = ", ".join(f"{k}: {t * 1e3:.2f} ms" for k, t in r["query_time_s"].items())
    click.echo(f"describe {r['describe_time_s'] * 1e3:.1f} ms per submap; query {times}")


@evaluate.command("planner")
@click.option(
    "--scenes",
    default="corner,passage,clutter,front-obstacle",
    show_default=True,
    help="Comma-separated planner scenes.",
)
@click.option("--robot-radius", default=0.2, show_default=True, help="Robot radius (m).")
@click.option("--step", default=0.1, show_default=True, help="GMM planner step (m).")
@click.option("--g-thr", default=1.5, show_default=True, help="Directional gradient threshold.")
@click.option("--seed", default=0, show_default=True, help="Sensor noise seed.")
@click.option("--components", default=200, show_default=True, help="Components per submap.")
@click.option(
    "--plots",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write a PNG per scene (occupancy, gradient field, both paths) here.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def eval_planner(
    scenes: str,
    robot_radius: float,
    step: float,
    g_thr: float,
    seed: int,
    components: int,
    plots: Path | None,
    as_json: bool,
) -> None:
    """The GMM gradient-field planner against A* on an occupancy grid (the paper's Table II)."""
    from gmmap.eval.planner import SCENES, evaluate_planners
    from gmmap.mapping.planner import PlannerOptions

    names = [s.strip() for s in scenes.split(",") if s.strip()]
    unknown = sorted(set(names) - set(SCENES))
    if unknown or not names:
        raise click.BadParameter(f"unknown scene(s) {unknown}; choose from {', '.join(SCENES)}")
    options = PlannerOptions(robot_radius=robot_radius, step=step, g_thr=g_thr)
    r = evaluate_planners(names, options, seed, plots, _log, components)
    if as_json:
        click.echo(json.dumps(r))
        return
    click.echo(f"robot radius {r['robot_radius']} m; length (m), clearance (m), time per step")
    click.echo(f"{'scene':<15}{'A*':>28}{'GMM':>28}")
    for name, s in r["scenes"].items():
        cells = [
            f"{'ok' if m['success'] else 'FAIL'} {m['length']:6.2f} {m['min_clearance']:5.2f} "
            f"{m['time_per_step_s'] * 1e3:7.2f} ms"
            for m in (s["astar"], s["gmm"])
        ]
        click.echo(f"{name:<15}{cells[0]:>28}{cells[1]:>28}")


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
    from gmmap.eval import bench as b

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
    """Summarise a dataset: format, frames, duration, path length, points per frame.

    PATH is detected as one of: a TUM RGB-D folder (depth.txt; also keyframe exports with
    truth_cam_poses.txt, and `gmmap sim` depth runs), a KITTI odometry sequence, a folder of
    PLY/PCD files with a TUM-format poses file (also `gmmap sim --sensor lidar` runs), or a
    ROS 1/2 bag. The path length follows the poses the loader yields (the odometry where there
    is one); the ground truth's is given too when the data has one.
    """
    from gmmap.io import datasets

    given = dict(stride=stride, topic=topic, odom_topic=odom_topic, voxel=voxel)
    options = {k: v for k, v in given.items() if v is not None}
    seq = datasets.open(path, format=fmt, **options)
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


if __name__ == "__main__":
    sys.exit(main())
