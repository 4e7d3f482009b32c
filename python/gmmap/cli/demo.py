"""``gmmap demo``: simulated robots in the office world, each a separate ``gmmap robot`` process.

The robots talk over Zenoh on loopback only (each listens on its own free port and connects to
the others' endpoints; multicast scouting off) and share nothing but encoded submaps. When they
are done, the demo reads their reports and compares each robot's recovered frame (its
``to_reference``) with the simulator's ground truth, which the robots never see: the true
transform from robot r's map frame into its reference's is inv(M_ref) @ M_r, M being each
robot's map→world. The errors are reported as they come out: place recognition in the office
is weak (corridors alias), so wrong or missing merges are possible and are shown as such.
"""

from __future__ import annotations

import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path

import click

from gmmap.cli.common import (
    BROADCAST,
    BUDGET,
    BUNDLE,
    CHANNEL_RATE,
    MIN_MATCHES,
    PROTOCOL,
    as_json_option,
    config_option,
    log,
    setting,
    sim_settings,
)
from gmmap.config import Config
from gmmap.errors import InvalidInputError
from gmmap.eval.emulation import launch, paced, rendezvous, robot_config, start_relays
from gmmap.eval.fleetrun import summarise
from gmmap.fleet.security.access import secured
from gmmap.fleet_options import TOPOLOGIES
from gmmap.options import drift_overrides

# A contact that carries a submap to a robot that met no one for longer than the lease: a
# session opens (Zenoh retries its connection every second at first), its advert follows
# holdings.SETTLE_S later, and a fetch crosses.
LASTING_S = 2.0


def run_demo(
    config: Config,
    max_frames: int | None = None,
    out: Path | None = None,
    log=print,
    crash: tuple[int, int] | None = None,
    secure: bool = False,
    station: bool = False,
) -> dict:
    """Runs ``config.sim.robots`` robot processes, each started with its own configuration
    file (this tree with its name, store and endpoints), and summarises their reports.
    ``crash`` (i, n): robot i is killed with SIGKILL once it has stored n submaps of its own,
    and started again on its store. ``secure``: a new fleet authority and credentials for each
    robot in ``out/fleet``, TLS links, access control and sealed submaps
    (`gmmap.fleet.security.access`). ``station``: a ``gmmap station`` beside them, on the tree's
    station section (`station_command`)."""
    # The robots run in this interpreter: a missing fleet extra is named here, not in n logs.
    import zenoh  # noqa: F401

    # Below the ephemeral range: a relay's port or an outgoing connection cannot take one
    # before its robot listens on it.
    from gmmap.fleet.net.keys import listen_port

    start = time.perf_counter()
    if out is None:
        out = Path(tempfile.mkdtemp(prefix="gmmap-demo-"))
    out.mkdir(parents=True, exist_ok=True)
    config = paced(config, secure)
    sim = config.sim
    names = [f"robot_{i}" for i in range(sim.robots)]
    for name in names:  # a demo starts afresh: robots would resume from an earlier run's stores
        for stale in out.glob(f"{name}.sqlite*"):
            stale.unlink()
    ports = [listen_port() for _ in names]
    fleet = f"demo{os.getpid()}"
    config.save(out)
    members = _credentials(config, out / "fleet", fleet, names) if secure else {}
    procs: list[subprocess.Popen] = []
    readers: list[threading.Thread] = []
    router = None
    if config.link.topology == "router":
        from gmmap.fleet.net.session import open_router

        ports.append(listen_port())
        router = open_router(ports[-1], protocol=config.transport.link_protocol)
    reach = rendezvous(config, max_frames)
    relays = start_relays(config, ports, reach)
    log(f"starting {sim.robots} robot processes in {sim.world} (fleet {fleet}, output {out})")
    for i, name in enumerate(names):
        own = robot_config(config, i, names, ports, fleet, out, relays, reach)
        if secure:
            own = secured(own, members[name])
        cmd = [
            sys.executable, "-c", "from gmmap.cli import main; main()", "robot",
            "--config", str(own.save(out / f"{name}.yaml")), "--sim", "--sim-index", str(i),
            "--report", str(out / f"{name}.json"), "--truth", str(out / f"{name}.truth.json"),
            "--json",
        ]  # fmt: skip
        if max_frames:
            cmd += ["--max-frames", str(max_frames)]
        if i == 0:  # the lowest name: the reference of whatever group it is in
            cmd += ["--map-png", str(out / "map.png")]
        procs.append(launch(cmd, log, readers))
        if crash and crash[0] == i:
            store = out / f"{name}.sqlite"
            args = (procs, i, cmd, store, crash[1], log, readers)
            crasher = threading.Thread(target=_crash, args=args)
            crasher.start()
    watcher = None
    if station:
        cmd = station_command(config, fleet, ports, out, members.get("station"))
        watcher = launch(cmd, log, readers)
    if crash:
        crasher.join()
    codes = [p.wait() for p in procs]
    if watcher is not None:
        watcher.send_signal(signal.SIGINT)
        codes.append(watcher.wait(timeout=60))
    for t in readers:
        t.join(timeout=5)
    for relay in relays.values():
        relay.close()
    if router is not None:
        router.close()
    if any(codes):
        raise RuntimeError(f"robot processes exited with {codes}; see the log above")
    reports = {n: json.loads((out / f"{n}.json").read_text()) for n in names}
    truth = {n: json.loads((out / f"{n}.truth.json").read_text()) for n in names}
    report = summarise(reports, truth, sim)
    if reach is None:  # every robot in reach of every other, directly or through others
        from gmmap.eval.delivery import lost

        report["lost"] = lost(reports)
    else:  # links that come and go: lost is what a peer in reach never got
        report.update(_reach_losses(config, reach, names, out))
    if relays:
        from gmmap.eval.wire import delivered, wire_report

        report.update(wire_report(relays, names, delivered(reports)))
    if watcher is not None:
        report["station"] = station_summary(out, reports)
    report["out"] = str(out)
    report["map_png"] = reports[names[0]].get("map_png")
    report["map_rrd"] = reports[names[0]].get("map_rrd")
    report["wall_s"] = time.perf_counter() - start
    (out / "demo.json").write_text(json.dumps(report, indent=1))
    return report


def _credentials(config: Config, folder: Path, fleet: str, names: list[str]) -> dict:
    """A new fleet authority in ``folder`` (an earlier run's is replaced) and each robot's
    member folder."""
    import shutil

    from gmmap.fleet.security.access import issue_fleet
    from gmmap.fleet.security.credentials import add_member

    if config.link.topology == "router":
        raise InvalidInputError("--secure runs mesh or chain links; the router is not secured")
    shutil.rmtree(folder, ignore_errors=True)
    members = issue_fleet(folder, fleet, names)
    return {**members, "station": add_member(folder, "station", role="station")}


def station_summary(out: Path, reports: dict[str, dict]) -> dict:
    """What the demo's station held, cost and how soon it showed each submap after its robot
    built and sent it (``view_latency_s``: median, max; clock times of one machine)."""
    seen = json.loads((out / "station.json").read_text())
    built = {f"{n}/{s['seq']}": s.get("built_at") for n, r in reports.items() for s in r["submaps"]}
    lags = [t - built[k] for k, t in seen["shown_at"].items() if built.get(k) is not None]
    summary = {k: seen[k] for k in ("held", "groups", "submaps_fetched", "resources")}
    median = statistics.median(lags) if lags else None
    summary["view_latency_s"] = {"median": median, "max": max(lags, default=None)}
    return {**summary, "shown": len(seen["shown_at"]), "rrd": str(out / "station.rrd")}


def station_command(
    config: Config, fleet: str, ports: list[int], out: Path, credentials=None
) -> list[str]:
    """``gmmap station`` on the demo's tree (out/config.yaml: its station section, the robots'
    mapping settings) watching the demo's robots straight at their endpoints, its view saved
    to out/station.rrd, its report out/station.json."""
    scheme = "tcp" if credentials is None else "tls"
    cmd = [sys.executable, "-c", "from gmmap.cli import main; main()", "station",
           "--config", str(config.save(out / "station.yaml")), "--fleet", fleet,
           "--save", str(out / "station.rrd"), "--report", str(out / "station.json")]  # fmt: skip
    for port in ports[: config.sim.robots]:
        cmd += ["--peer", f"{scheme}/127.0.0.1:{port}"]
    return cmd + ([] if credentials is None else ["--credentials", str(credentials)])


def _crash(procs: list, i: int, cmd: list[str], store: Path, after: int, log, readers) -> None:
    """Kills robot i with SIGKILL once its store holds ``after`` submaps of its own, and
    starts it again on that store (``procs[i]`` becomes the new process)."""
    import signal
    import sqlite3

    name = f"robot_{i}"
    while procs[i].poll() is None:
        try:
            with sqlite3.connect(f"file:{store}?mode=ro", uri=True, timeout=1) as db:
                sql = "SELECT COUNT(*) FROM submaps WHERE robot = ? AND own = 1"
                if db.execute(sql, (name,)).fetchone()[0] >= after:
                    break
        except sqlite3.Error:  # not created yet
            pass
        time.sleep(0.05)
    else:
        return  # it ended first
    os.kill(procs[i].pid, signal.SIGKILL)
    procs[i].wait()
    log(f"{name}: killed with SIGKILL after {after} submaps; starting it again on its store")
    procs[i] = launch(cmd, log, readers)


def _reach_losses(config: Config, reach, names: list[str], out: Path) -> dict:
    """On rendezvous links (``reach``), per robot its submaps a peer in reach after them never
    got (``lost``), those no peer could reach (``out_of_reach``), and of the lost those that
    contacts of at least `LASTING_S` could have carried, each robot in between holding
    them that long in one before it ends (``lost_lasting``; the rest had only briefer ones),
    from the robots' stores (`gmmap.eval.delivery`)."""
    from gmmap.eval.delivery import lasting, links_up, lost_in_reach

    n = len(names)
    linked = links_up(reach.up, config.link.pairs(n), n, reach.frames)
    stores = {name: out / f"{name}.sqlite" for name in names}
    lost, unreachable = lost_in_reach(stores, linked, reach.frame)
    hold = round(LASTING_S * config.sim.rate * config.sim.pace)
    lost_lasting, _ = lost_in_reach(stores, lasting(linked, hold), reach.frame, hold)
    return {"lost": lost, "out_of_reach": unreachable, "lost_lasting": lost_lasting}


def format_report(r: dict) -> str:
    from gmmap.eval.pairs import describe_pair
    from gmmap.eval.registration import describe_match_errors

    b = r["bytes_per_submap"]
    lines = [
        f"robots          {r['robots']} in {r['world']}, {r['submaps']} submaps",
        f"groups          {r['groups']} (view of {r['view']})",
        f"bytes/submap    wire {b['wire']:.0f} B vs points (float32) {b['points_float32']:.0f} B"
        f" vs GMM float32 + descriptor {b['gmm_float32_plus_descriptor']:.0f} B",
        f"reduction       {r['reduction_vs_points']:.0f}x vs points, "
        f"{r['reduction_vs_gmm_float32_plus_descriptor']:.1f}x vs GMM + descriptor",
    ]
    for p in r["pairs"]:
        lines.append(f"pair            {describe_pair(p)}")
    for n, m in r["matches"].items():
        lines.append(
            f"matches         {n}: {m['accepted']} of {m['accepted'] + m['rejected']} over "
            f"C_thr, {m['backend_accepted']} kept by PCM/GNC; {r['received'][n]} submaps received"
        )
    for i, line in enumerate(describe_match_errors(r.get("match_errors", {}))):
        lines.append(f"{'where they met' if i == 0 else '':<16}{line}")
    if r.get("wire"):
        sent = ", ".join(f"{n} {w['bytes']} B" for n, w in r["wire"].items())
        per = r["wire_bytes_per_delivered_submap"]
        per_text = f"{per:.0f} B on the wire per delivered submap" if per else "none delivered"
        lines.append(f"wire            {sent}; {per_text}")
    delivery = f"{sum(r.get('lost', {}).values())} submaps lost"
    if "out_of_reach" in r:
        lasting, away = (sum(r[k].values()) for k in ("lost_lasting", "out_of_reach"))
        delivery += f" ({lasting} in contacts of {LASTING_S:.0f} s or more), {away} out of reach"
    lines.append(f"delivery        {delivery}")
    lines.append(f"map             {r.get('map_png')}")
    if r.get("map_rrd"):
        lines.append(f"rerun           {r['map_rrd']} (open with: rerun {r['map_rrd']})")
    for path in r.get("plots", []):
        lines.append(f"plot            {path}")
    lines.append(f"output          {r['out']}")
    lines.append(f"wall time       {r['wall_s']:.1f} s")
    return "\n".join(lines)


@click.command("demo")
@sim_settings
@MIN_MATCHES
@setting("--linger", "robot.linger", "Seconds robots stay after their frames.", type=float)
@BUDGET
@BUNDLE
@PROTOCOL
@BROADCAST
@CHANNEL_RATE
@setting(
    "--deadline",
    "robot.deadline",
    "Latest end after the frames, peers complete or not.",
    type=float,
)
@setting(
    "--emulate-links", "link.emulate", "Robot pairs talk through counting relays.", is_flag=True
)
@setting("--link-rate", "link.rate", "Emulated links' cap, bytes/s each way.", type=float)
@setting("--link-delay", "link.delay_s", "Emulated links' one-way delay (s).", type=float)
@setting(
    "--link-loss",
    "link.loss",
    "Emulated links' loss per chunk: a TCP stall, or a dropped datagram over UDP.",
    type=float,
)
@setting(
    "--link-topology",
    "link.topology",
    "Which robots are linked: mesh (all pairs), chain (i to i + 1; the rest multi-hop) or "
    "router (each a Zenoh client of one router).",
    type=click.Choice(TOPOLOGIES),
)
@setting(
    "--link-range",
    "link.range_m",
    "Rendezvous links: up only while their robots are this close (m); the robots move in "
    "step (sim.pace, 2 unless set).",
    type=float,
)
@setting(
    "--link-sight",
    "link.line_of_sight",
    "Rendezvous links: up only while their robots see each other.",
    is_flag=True,
)
@click.option("--max-frames", type=int, help="Use only each robot's first frames.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    help="Output folder (configs, stores, reports, map.png); default a new temporary folder.",
)
@click.option(
    "--plots",
    type=click.Path(file_okay=False, path_type=Path),
    help="Write bytes over time (the paper's Fig. 9) and map completeness PNGs here.",
)
@click.option(
    "--station",
    is_flag=True,
    help="Watch the robots from a gmmap station, its view in the browser (the station section).",
)
@click.option(
    "--secure",
    is_flag=True,
    help="Fresh fleet credentials in OUT/fleet: mutual TLS, access control, signed submaps.",
)
@click.option(
    "--explore",
    is_flag=True,
    help="The robots explore the world instead of following routes (gmmap explore without "
    "its baselines: a process each, perfect odometry).",
)
@config_option
@as_json_option
def command(
    max_frames: int | None,
    out: Path | None,
    plots: Path | None,
    station: bool,
    secure: bool,
    explore: bool,
    config: Config,
    as_json: bool,
) -> None:
    """Simulated robots as separate processes share GMM submaps over Zenoh and merge maps.

    The pose graph's odometry noise follows the simulated drift (sim.drift, with a floor)
    unless the configuration sets the backend's odometry fields."""
    if explore:
        from gmmap.cli.explore import explore_and_report

        explore_and_report(config, baselines=False, out=out, as_json=as_json)
        return
    config = backend_follows_drift(config)
    r = run_demo(config, max_frames, out, log, secure=secure, station=station)
    if plots:
        from gmmap.eval.fleetplots import write_plots

        r["plots"] = write_plots(Path(r["out"]), list(r["received"]), plots)
    click.echo(json.dumps(r) if as_json else format_report(r))


def backend_follows_drift(config: Config) -> Config:
    b, default = config.backend, Config().backend
    if any(getattr(b, k) != getattr(default, k) for k in drift_overrides(0.0)):
        return config  # the configuration chose its odometry noise
    drift = drift_overrides(max(config.sim.drift, 0.001))
    return replace(config, backend=replace(config.backend, **drift))
