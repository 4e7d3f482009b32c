"""``gmmap explore``: simulated robots explore a world they do not know, on shared GMM maps."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gmmap.cli.common import as_json_option, config_option, log, setting, sim_settings
from gmmap.config import Config

BASELINES = {"alone": ("shared", 1), "no_sharing": ("no-sharing", None), "dense": ("dense", None)}


@click.command("explore")
@sim_settings
@setting("--lidar-range", "sim.lidar_range", "LiDAR maximum range (m).", type=float)
@setting("--time-budget", "explore.time_budget", "Simulated seconds before a run ends.", type=float)
@click.option(
    "--baselines/--no-baselines",
    default=True,
    show_default=True,
    help="Also run one robot alone, the same robots without sharing, and the dense-grid "
    "baseline on the same world (each as long as the run itself).",
)
@click.option(
    "--processes/--in-process",
    default=True,
    show_default=True,
    help="Each robot sharing GMMs is a gmmap robot --explore process talking to its peers "
    "over Zenoh (the baselines run in this process), or every robot runs in this process.",
)
@click.option(
    "--aerial",
    is_flag=True,
    help="One aerial robot with a 32-beam ±45° LiDAR explores in 3D (try --world two-storey); "
    "the baselines are for ground robots and are not run.",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for result.json, config.yaml, coverage.png and explore.rrd (with Rerun).",
)
@config_option
@as_json_option
def command(
    baselines: bool, processes: bool, aerial: bool, out: Path | None, config: Config, as_json: bool
) -> None:
    """Explore a simulated world with robots that share GMM submaps and free-space horizons.

    No route is scripted: each robot chooses frontiers of what the team has seen, routes
    through the viewpoints of the team's submaps and steers with the GMM gradient planner;
    the simulator moves it and checks collisions against the true world. Coverage is measured
    against the true world: its vertical surfaces within 10 cm of the team's map (placed by
    ground truth) and the share of its floor the team knows is free. The run ends when no
    robot has a frontier left or after explore.time_budget simulated seconds. With
    --aerial, one flying robot explores in 3D and coverage counts surfaces at every height.
    """
    explore_and_report(config, baselines, out, as_json, aerial, processes)


def explore_and_report(
    config: Config,
    baselines: bool,
    out: Path | None,
    as_json: bool,
    aerial: bool = False,
    processes: bool = True,
) -> None:
    """Runs the exploration (and its baselines), writes ``out`` and prints the report."""
    from gmmap.eval.explore.aerial import run_aerial
    from gmmap.eval.explore.processes import run_processes
    from gmmap.eval.explore.team import run_explore

    o = config.sim
    if aerial:
        log(f"exploring {o.world} in 3D with one aerial robot (32-beam ±45° LiDAR)")
        main = run_aerial(config, progress=log)
    else:
        log(f"exploring {o.world} with {o.robots} robots ({o.sensor}), sharing GMM submaps")
        run = run_processes if processes else run_explore
        main = run(config, progress=log)
    report = {**main.summary(), "processes": processes and not aerial}
    runs = {"aerial" if aerial else "shared": main}
    if baselines and not aerial:
        report["baselines"] = {}
        for name, (mode, robots) in BASELINES.items():
            log(f"baseline {name}: {mode}, {robots or o.robots} robots")
            runs[name] = run_explore(config, mode, robots, progress=log)
            report["baselines"][name] = runs[name].summary()
    if out is not None:
        _write(out, config, report, runs)
    if as_json:
        click.echo(json.dumps(report))
        return
    for name, r in runs.items():
        t90 = "never" if r.time_to_90_s is None else f"{r.time_to_90_s:.0f} s"
        click.echo(
            f"{name:>10}: coverage {r.coverage:.0%} (area {r.area:.0%}), 90% at {t90}, "
            f"{r.collisions} collisions, {sum(r.bytes_per_robot) / 1e3:.1f} kB sent, "
            f"{r.sim_time_s:.0f} s; {', '.join(sorted(set(r.statuses)))}"
        )


def _write(out: Path, config: Config, report: dict, runs: dict) -> None:
    from gmmap.eval.explore.plots import plot_coverage
    from gmmap.io import viz

    out.mkdir(parents=True, exist_ok=True)
    config.save(out)
    full = {name: {**r.summary(), "curve": r.curve, "paths": r.paths} for name, r in runs.items()}
    (out / "result.json").write_text(json.dumps({**report, "runs": full}))
    plot_coverage(runs, out / "coverage.png")
    if viz.available():
        main = next(iter(runs.values()))  # the robots sharing GMMs; the baselines follow
        viz.save_paths(main.paths, 1.0 / config.sim.rate, out / "explore.rrd", main.curve)
    log(f"wrote {out}")
