"""``gmmap eval``: the paper's experiments against ground truth (Table I, Fig. 7-8, Table II)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gmmap.cli.common import (
    COVARIANCE,
    FRAMES_PER_SUBMAP,
    as_json_option,
    config_option,
    log,
    setting,
    sim_settings,
)
from gmmap.config import Config


@click.group("eval")
def command() -> None:
    """The paper's experiments against ground truth (Table I, …)."""


@command.command("registration")
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
@setting("--voxel", "build.voxel_size", "Submap voxel size (m).", type=float)
@setting("--components", "build.n_components", "Components per submap (KITTI: 300).", type=int)
@click.option("--seed", default=0, show_default=True, help="Seeds the global perturbations.")
@click.option("--scales", help="Registration coarse-to-fine ladder, e.g. 0.5,0.1,0 (metres).")
@click.option(
    "--odometry-guess",
    is_flag=True,
    help="Start from the odometry's relative pose instead of the identity.",
)
@click.option(
    "--sim-drift",
    "drift",
    type=float,
    help="Simulate odometry drift of this fraction of the distance (datasets whose "
    "poses are ground truth), with the default rotation drift.",
)
@config_option
@as_json_option
def eval_registration(
    path: Path,
    frames_per_submap: int,
    methods: str,
    global_mode: bool,
    max_pairs: int | None,
    stride: int | None,
    config: Config,
    seed: int,
    scales: str | None,
    odometry_guess: bool,
    drift: float | None,
    as_json: bool,
) -> None:
    """Register consecutive submaps and compare with ground truth (the paper's Table I)."""
    from gmmap.eval.registration import METHODS, evaluate_registration
    from gmmap.io import datasets

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
            log("small_gicp is not installed (pip install small_gicp): skipping gicp")
            chosen.remove("gicp")
    loader_options: dict = {"stride": stride} if stride else {}
    if drift is not None:
        loader_options["drift"] = datasets.Drift(translation=drift)
    frames = datasets.open(path, **loader_options)
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
        config.build,
        seed,
        log,
        ladder,
        odometry_guess,
    )
    click.echo(json.dumps(r) if as_json else _registration_table(r, frames_per_submap, global_mode))


def _registration_table(r: dict, frames_per_submap: int, global_mode: bool) -> str:
    lines = [
        f"{r['pairs']} pairs of {frames_per_submap}-frame submaps"
        f"{' (global: no initial guess)' if global_mode else ''}",
        f"{'method':<10} {'t mean (m)':>10} {'t RMSE (m)':>10} {'r mean (°)':>10} "
        f"{'r RMSE (°)':>10} {'success':>8} {'time/pair':>10}",
    ]
    for name, m in r["methods"].items():
        lines.append(
            f"{name:<10} {m['t_error_mean']:>10.4f} {m['t_rmse']:>10.4f} "
            f"{m['r_error_mean']:>10.3f} {m['r_rmse']:>10.3f} "
            f"{m['success_rate']:>8.1%} {m['time_per_pair_s'] * 1e3:>8.1f} ms"
        )
    return "\n".join(lines)


@command.command("place")
@click.option(
    "--data",
    type=click.Path(exists=True, path_type=Path),
    help="A recording split into two robots (first and second half); default: the simulator.",
)
@sim_settings
@FRAMES_PER_SUBMAP
@COVARIANCE
@setting("--top-k", "place.top_k", "Candidates verified per query.", type=int)
@click.option("--no-gicp", is_flag=True, help="Skip the points + GICP verification baseline.")
@click.option(
    "--plots",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write recall@N and precision-recall PNGs here.",
)
@config_option
@as_json_option
def eval_place(
    data: Path | None, no_gicp: bool, plots: Path | None, config: Config, as_json: bool
) -> None:
    """Place recognition recall and verified precision (the paper's Fig. 7 and 8)."""
    from gmmap.eval import place
    from gmmap.io import datasets

    b, s = config.build, config.sim
    if data is not None:
        frames = datasets.open(data)
        place_set = place.split_place_set(frames, b.frames_per_submap, log, b.covariance)
    else:
        place_set = place.sim_place_set(
            s.world, s.robots, s.seed, b.frames_per_submap, log, s.sensor, b.covariance
        )
    r = place.evaluate_place(place_set, config.place, progress=log, gicp=not no_gicp)
    if plots:
        for png in place.plot(r, plots):
            log(f"wrote {png}")
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


@command.command("planner")
@click.option(
    "--scenes",
    default="corner,passage,clutter,front-obstacle",
    show_default=True,
    help="Comma-separated planner scenes.",
)
@setting("--robot-radius", "planner.robot_radius", "Robot radius (m).", type=float)
@setting("--step", "planner.step", "GMM planner step (m).", type=float)
@setting("--g-thr", "planner.g_thr", "Directional gradient threshold.", type=float)
@click.option("--seed", default=0, show_default=True, help="Sensor noise seed.")
@click.option("--components", default=200, show_default=True, help="Components per submap.")
@click.option(
    "--plots",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write a PNG per scene (occupancy, gradient field, both paths) here.",
)
@config_option
@as_json_option
def eval_planner(
    scenes: str,
    config: Config,
    seed: int,
    components: int,
    plots: Path | None,
    as_json: bool,
) -> None:
    """The GMM gradient-field planner against A* on an occupancy grid (the paper's Table II)."""
    from gmmap.eval.planner import SCENES, evaluate_planners

    names = [s.strip() for s in scenes.split(",") if s.strip()]
    unknown = sorted(set(names) - set(SCENES))
    if unknown or not names:
        raise click.BadParameter(f"unknown scene(s) {unknown}; choose from {', '.join(SCENES)}")
    r = evaluate_planners(names, config.planner, seed, plots, log, components)
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
