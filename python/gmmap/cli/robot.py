"""``gmmap robot``: one robot node mapping a dataset or a simulated robot, over Zenoh."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from gmmap.cli.common import (
    BROADCAST,
    BUDGET,
    BUNDLE,
    CHANNEL_RATE,
    COVARIANCE,
    MIN_CONFIDENCE,
    MIN_MATCHES,
    PROTOCOL,
    config_option,
    frame_options,
    log,
    odometry_drift_option,
    open_data,
    ros_settings,
    save_trajectories,
    setting,
    sim_settings,
    submap_size,
)
from gmmap.config import Config


@click.command("robot")
@setting("--id", "robot.name", "This robot's name (unique in the fleet).")
@setting("--fleet", "robot.fleet", "The fleet's name: robots of other fleets are ignored.")
@click.option("--data", type=click.Path(exists=True, path_type=Path), help="A dataset to map.")
@click.option("--sim", "simulated", is_flag=True, help="Map a simulated robot (sim section).")
@click.option("--sim-index", type=int, default=0, show_default=True, help="Which simulated robot.")
@click.option(
    "--explore",
    is_flag=True,
    help="Explore the sim section's world as robot --sim-index of a gmmap explore --processes "
    "run (its simulator gives the ticks).",
)
@click.option("--ros2", is_flag=True, help="Map live ROS 2 topics over Zenoh (the ros section).")
@click.option("--ros1", is_flag=True, help="Map live ROS 1 topics (make ros1; the ros section).")
@sim_settings
@click.option("--stride", type=int, help="--data (TUM): pixel stride of the back-projection.")
@ros_settings
@frame_options
@setting("--listen", "transport.listen", "Zenoh listen endpoint (default loopback).",
         multiple=True)  # fmt: skip
@setting("--port", "transport.port", "Loopback listen port (0: free).", type=int)
@setting("--peer", "transport.connect", "Zenoh endpoint of another robot.", multiple=True)
@setting("--wait-for", "robot.wait_for", "Wait for these robots before mapping.", multiple=True)
@setting("--store", "robot.store", "The robot's SQLite store (default: temporary).")
@setting(
    "--credentials",
    "security.credentials",
    "This robot's folder from gmmap fleet add: TLS, access control, signed submaps.",
)
@submap_size
@setting("--components", "build.n_components", "Components fitted.", type=int)
@COVARIANCE
@odometry_drift_option
@MIN_MATCHES
@MIN_CONFIDENCE
@setting("--linger", "robot.linger", "Seconds to stay after mapping.", type=float)
@BUDGET
@BUNDLE
@PROTOCOL
@BROADCAST
@CHANNEL_RATE
@setting(
    "--deadline", "robot.deadline", "Latest end after mapping, peers complete or not.", type=float
)
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--truth",
    "truth_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="For evaluation: write the own anchors' ground truth (where the frames carry it) here.",
)
@click.option(
    "--map-png",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the merged map of this robot's group as a PNG (and, with the viz extra, "
    "a Rerun recording beside it: .rrd).",
)
@click.option("--json", "as_json", is_flag=True, help="One JSON status line per submap.")
@config_option
def command(
    data: Path | None,
    simulated: bool,
    explore: bool,
    ros2: bool,
    ros1: bool,
    sim_index: int,
    stride: int | None,
    pick,
    report_path: Path | None,
    truth_path: Path | None,
    map_png: Path | None,
    as_json: bool,
    config: Config,
) -> None:
    """Run one robot node: map, share submaps over Zenoh, match, optimise, report.

    With --report R.json: R.config.yaml and, per robot held, R.trajectory_<robot>.txt (its
    optimised anchors in its group's reference frame, TUM format) beside it."""
    from gmmap.fleet.node.robot import Built
    from gmmap.fleet.node.runner import run_robot

    if config.security.credentials is None:
        plain = config.transport.link_protocol.upper()
        why = "no --credentials: a trusted lab"
        log(f"{config.robot.name}: plain {plain}, submaps unsigned ({why})")
    if sum((data is not None, simulated, explore, ros2, ros1)) != 1:
        raise click.UsageError("give exactly one of --data, --sim, --explore, --ros2 and --ros1")
    if explore:
        from gmmap.fleet.node.explorer import ExplorerNode
        from gmmap.io.sim import Sensing

        r = ExplorerNode(config, Sensing(config.sim, sim_index)).run()
        log(f"{r['robot']}: {r['status']}, {r['bytes']} B sent")
        return
    bridge = None
    if ros2:
        from gmmap.io.ros2bridge import Ros2Bridge

        o = config.ros
        bridge = Ros2Bridge(config.robot.name, o)
        frames = bridge.live
        at = ", ".join(o.connect)
        log(f"{config.robot.name}: ROS 2 over Zenoh ({o.key_format}, {o.distro}) at {at}")
    elif ros1:
        from gmmap.io.ros1bridge import Ros1Bridge

        bridge = Ros1Bridge(config.robot.name, config.ros)
        frames = bridge.live
        log(f"{config.robot.name}: ROS 1 node gmmap_{config.robot.name}")
    else:
        frames = pick(_frames(data, simulated, sim_index, stride, config))
    truth: dict[str, list] = {}

    def on_built(built: Built) -> None:
        line = built.status
        if built.submap.gt_anchor is not None:
            truth[str(built.submap.seq)] = built.submap.gt_anchor.tolist()
        if as_json:
            click.echo(json.dumps(line))
        else:
            log(
                f"{line['robot']}: submap {line['seq']} ({line['bytes']} B), "
                f"{line['received']} received, {line['matches']} matches, groups {line['groups']}"
            )

    def on_finish(mapper) -> dict:
        saved: dict = {}
        if report_path is not None:  # the trajectories beside the report
            prefix = f"{report_path.stem}."
            paths = save_trajectories(mapper, report_path.parent, prefix)
            saved["trajectories"] = [str(p) for p in paths]
        gmap = mapper.global_map(config.robot.name) if map_png is not None else None
        if gmap is not None:
            saved.update(save_map(gmap, map_png))
        return saved

    try:
        attach = None if bridge is None else bridge.attach
        r = run_robot(config, frames, report_path, on_finish, on_built, log, attach)
    finally:
        if bridge is not None:
            bridge.close()
    if report_path is not None:  # the effective configuration beside the report
        config.save(report_path.with_suffix(".config.yaml"))
    if truth_path is not None:
        truth_path.parent.mkdir(parents=True, exist_ok=True)
        truth_path.write_text(json.dumps(truth))
    log(
        f"{config.robot.name}: {r['submaps_built']} built, {r['submaps_received']} received, "
        f"{r['matches_accepted']} matches accepted, {r['matches_rejected']} rejected, "
        f"groups {r['groups']}"
    )


def _frames(data: Path | None, simulated: bool, index: int, stride: int | None, config: Config):
    if data is not None:
        return open_data(data, stride, config.ros)
    from gmmap.io.sim import Paced, simulate_options

    sim = config.sim
    run = simulate_options(sim)
    if not 0 <= index < len(run):
        raise click.BadParameter(f"0..{len(run) - 1}", param_hint="--sim-index")
    if sim.pace is None:
        return run[index]
    return Paced(run[index], sim.pace, time.time() if sim.start is None else sim.start)


def save_map(gmap, path: Path) -> dict:
    """The merged map as a PNG and, with the viz extra, a Rerun recording beside it."""
    from gmmap.io import viz

    path.parent.mkdir(parents=True, exist_ok=True)
    gmap.save_png(path)
    saved = {"map_png": str(path)}
    if viz.available():
        saved["map_rrd"] = str(viz.save_rerun(gmap, path.with_suffix(".rrd")))
    return saved
