"""``gmmap eval``: the paper's experiments against ground truth (Table I, Fig. 7-8, Table II)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gmmap.cli.common import (
    COVARIANCE,
    DESCRIPTOR,
    MIN_CONFIDENCE,
    MIN_MATCHES,
    as_json_option,
    config_option,
    log,
    odometry_drift_option,
    setting,
    sim_settings,
    submap_size,
)
from gmmap.config import Config


@click.group("eval")
def command() -> None:
    """The paper's experiments against ground truth (Table I, Fig. 7-8, Table II) and the
    cross-session merge."""


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
@click.option(
    "--guess-error",
    help="Start every method from the truth turned by a random LOW-HIGH degrees (e.g. "
    "10-20) about a random axis and moved ≤ 5 cm.",
)
@click.option("--max-pairs", type=int, help="Evaluate only the first pairs.")
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@setting("--voxel", "build.voxel_size", "Submap voxel size (m).", type=float)
@setting("--components", "build.n_components", "Components per submap (KITTI: 300).", type=int)
@click.option("--seed", default=0, show_default=True, help="Seeds the global perturbations.")
@click.option(
    "--repeats",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Build the pairs this many times (EM and perturbation seeds counted up) and pool them.",
)
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
    guess_error: str | None,
    max_pairs: int | None,
    stride: int | None,
    config: Config,
    seed: int,
    repeats: int,
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
    guess_deg = _degree_range(guess_error) if guess_error else None
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
        guess_deg,
        repeats,
    )
    click.echo(json.dumps(r) if as_json else _registration_table(r, frames_per_submap, global_mode))


def _degree_range(text: str) -> tuple[float, float]:
    try:
        low, high = (float(v) for v in text.split("-"))
    except ValueError:
        raise click.BadParameter(
            "LOW-HIGH in degrees, e.g. 10-20", param_hint="--guess-error"
        ) from None
    return low, high


def _registration_table(r: dict, frames_per_submap: int, global_mode: bool) -> str:
    mode = " (global: no initial guess)" if global_mode else ""
    if r.get("guess_deg"):
        mode = " (from a guess {:g}-{:g}° off)".format(*r["guess_deg"])
    lines = [
        f"{r['pairs']} pairs of {frames_per_submap}-frame submaps{mode}",
        f"{'method':<10} {'t mean (m)':>10} {'t median':>10} {'r mean (°)':>10} "
        f"{'r median':>10} {'success':>8} {'time/pair':>10}",
    ]
    for name, m in r["methods"].items():
        lines.append(
            f"{name:<10} {m['t_error_mean']:>10.4f} {m['t_error_median']:>10.4f} "
            f"{m['r_error_mean']:>10.3f} {m['r_error_median']:>10.3f} "
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
@click.option(
    "--frames-per-submap",
    type=click.IntRange(min=1),
    default=20,
    show_default=True,
    help="Frames per submap (the paper's protocol, by frame count).",
)
@COVARIANCE
@setting("--top-k", "place.top_k", "Candidates verified per query.", type=int)
@DESCRIPTOR
@click.option("--no-gicp", is_flag=True, help="Skip the points + GICP verification baseline.")
@click.option(
    "--plots",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write recall@N and precision-recall PNGs here.",
)
@config_option
@as_json_option
def eval_place(
    data: Path | None,
    frames_per_submap: int,
    no_gicp: bool,
    plots: Path | None,
    config: Config,
    as_json: bool,
) -> None:
    """Place recognition recall and verified precision (the paper's Fig. 7 and 8)."""
    from gmmap.eval import place
    from gmmap.io import datasets

    b, s = config.build, config.sim
    if data is not None:
        frames = datasets.open(data)
        place_set = place.split_place_set(frames, frames_per_submap, log, b.covariance)
    else:
        place_set = place.sim_place_set(
            s.world, s.robots, s.seed, frames_per_submap, log, s.sensor, b.covariance, s
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


@command.command("merge")
@click.argument("sessions", nargs=-1, required=True)
@submap_size
@COVARIANCE
@MIN_CONFIDENCE
@MIN_MATCHES
@odometry_drift_option
@click.option("--stride", type=int, help="TUM: pixel stride of the back-projection.")
@click.option("--no-gicp", is_flag=True, help="Skip the points + GICP baseline and the floor.")
@config_option
@as_json_option
def eval_merge(
    sessions: tuple[str, ...], stride: int | None, no_gicp: bool, config: Config, as_json: bool
) -> None:
    """Merge recordings of one place made at different times, each one robot, against ground
    truth: joined or not, frame errors, verified precision and recall, beside points + GICP
    verification on the same candidates and the data's floor (GICP started at the truth).

    SESSIONS are dataset paths, each optionally sliced as PATH@START:STOP[:STEP] (a Python
    slice of its frames; e.g. a 30 Hz recording @5::3 is another 10 Hz session of it)."""
    from gmmap.eval.sessions import evaluate_sessions
    from gmmap.mapping.submap import build_submaps

    built = {}
    for i, spec in enumerate(sessions):
        frames = _session_frames(spec, stride)
        name = f"s{i}"
        log(f"{name}: building {len(frames)} frames of {spec}")
        built[name] = list(build_submaps(iter(frames), name, config.build, config.select))
        if not built[name]:
            raise click.BadParameter(f"{spec}: no submaps", param_hint="SESSIONS")
    r = evaluate_sessions(built, config, log, gicp=not no_gicp)
    r["paths"] = dict(zip(built, sessions, strict=True))
    click.echo(json.dumps(r) if as_json else _sessions_summary(r))


def _session_frames(spec: str, stride: int | None):
    from gmmap.cli.common import Frames, open_data

    path, _, cut = spec.partition("@")
    if not Path(path).exists():
        raise click.BadParameter(f"{path}: no such dataset", param_hint="SESSIONS")
    frames = open_data(Path(path), stride)
    if not cut:
        return frames
    try:
        parts = [int(x) if x.strip() else None for x in cut.split(":")]
        chosen = range(len(frames))[slice(*parts)]
    except (ValueError, TypeError):
        raise click.BadParameter(f"{spec!r}: not PATH@START:STOP[:STEP]") from None
    return Frames(frames, chosen)


def _sessions_summary(r: dict) -> str:
    def pct(x):
        return "—" if x is None else f"{x:.0%}"

    lines = [f"sessions {r['paths']}: {r['sessions']} submaps"]
    if r["joined"]:
        lines.append(
            f"joined: map frames {r['frame_t_error'] * 100:.1f} cm, "
            f"{r['frame_r_error_deg']:.2f}° off the truth (worst pair)"
        )
    else:
        lines.append(f"not joined: groups {r['merge']['groups']}")
    lines.append(
        f"{r['candidates']} candidates, {r['verified']} verified, {r['positives']} positive pairs;"
        f" precision {pct(r['precision'])}, recall {pct(r['recall'])};"
        f" {r['candidates_registered_right']} candidates registered right"
    )
    if "gicp" in r:
        g, f = r["gicp"], r["floor"]
        lines.append(
            f"points + GICP: {g['candidates_registered_right']} registered right, recall at "
            f"100 % precision {pct(g['recall_at_full_precision'])}"
        )
        if f["n"]:
            lines.append(
                f"floor (GICP from the truth, {f['n']} pairs): median "
                f"{f['t_median'] * 100:.1f} cm / {f['r_median_deg']:.2f}°"
            )
    return "\n".join(lines)
