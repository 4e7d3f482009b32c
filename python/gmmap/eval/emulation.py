"""The demo's robot processes and emulated links (`gmmap.cli.demo`, and `gmmap explore`'s
robots): each robot's configuration and endpoints, launching it with its output relayed,
robots paced on rendezvous links, who is in reach of whom, and a counting relay for every
linked pair (`gmmap.eval.links`)."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from dataclasses import replace
from pathlib import Path

from gmmap.config import Config

RENDEZVOUS_PACE = 2.0  # the robots' pace on rendezvous links: twice as fast as they drive
STARTUP_S = 3.0  # from launching the robot processes to their first frame, on rendezvous links


def paced(config: Config, secure: bool = False) -> Config:
    """With rendezvous links the robots move in step (`SimOptions.pace`, `RENDEZVOUS_PACE`
    unless set), from a common start a moment from now, once the processes are up, send
    each submap at once (`RobotOptions.bundle` 1 unless set): a contact may last a second,
    and talk over UDP (`TransportOptions.protocol`, unless set or ``secure``: TLS needs TCP):
    a link that comes and goes costs no handshakes, ACKs or retransmissions."""
    sim = config.sim
    if not config.link.rendezvous:
        return config
    pace = sim.pace or RENDEZVOUS_PACE
    robot = replace(config.robot, bundle=config.robot.bundle or 1)
    protocol = config.transport.protocol or ("tcp" if secure else "udp")
    transport = replace(config.transport, protocol=protocol)
    sim = replace(sim, pace=pace, start=time.time() + STARTUP_S)
    return replace(config, sim=sim, robot=robot, transport=transport)


def rendezvous(config: Config, max_frames: int | None = None):
    """With rendezvous links, who is in reach of whom (`gmmap.eval.links.Rendezvous`), from
    the simulated robots' true positions on the paced robots' clock; else None."""
    from gmmap.eval.links import Rendezvous
    from gmmap.io.sim import simulate_options

    link, sim = config.link, config.sim
    if not link.rendezvous:
        return None
    run = simulate_options(sim, max_frames)
    sight = run[0].world.in_sight if link.line_of_sight else None
    tracks = [r.gt_poses[:, :3, 3] for r in run]
    return Rendezvous(tracks, link.range_m, sight, sim.start, sim.rate * sim.pace)


def start_relays(config: Config, ports: list[int], reach=None) -> dict:
    """With emulated links, one relay per linked pair (i < j, `LinkOptions.pairs`) in front
    of j's endpoint (``ports``: the robots', then the router's): i reaches j only through it,
    and with rendezvous links (``reach``) only while they are in reach of each other."""
    from gmmap.eval.links.datagrams import relay_for

    if not config.link.shaped:
        return {}
    pairs = config.link.pairs(config.sim.robots)
    relay = relay_for(config.transport.link_protocol)
    return {
        (i, j): relay(
            ("127.0.0.1", ports[j]), config.link, gate=reach.gate(i, j) if reach else None
        ).start()
        for i, j in pairs
    }


def robot_config(
    config: Config,
    i: int,
    names: list[str],
    ports: list[int],
    fleet: str,
    out: Path,
    relays: dict | None = None,
    reach=None,
) -> Config:
    """Robot ``i``'s tree: the demo's, with its name, store, peers and endpoints (through
    the ``relays`` where links are emulated). It waits at the start for the robots linked
    to it, on rendezvous links (``reach``) only for those in reach there."""
    from gmmap.eval.links import ZENOH_NO_GOSSIP

    name = names[i]
    if relays and config.link.topology != "router":
        linked = sorted({j for pair in relays if i in pair for j in pair} - {i})
    else:  # every robot in reach, directly or through the router
        linked = [j for j in range(len(names)) if j != i]
    waits = [j for j in linked if reach is None or reach.up(min(i, j), max(i, j), frame=0)]
    robot = replace(
        config.robot,
        name=name,
        fleet=fleet,
        store=str(out / f"{name}.sqlite"),
        wait_for=tuple(names[j] for j in waits),
    )
    options = config.transport
    if options.broadcast is not None and options.protocol is None:
        # One shared channel: UDP links need no TCP handshakes, ACKs or retransmissions, which
        # took a third of a 500 B/s channel (docs/benchmarks.md, "channel").
        options = replace(options, protocol="udp")
    zenoh = dict(options.zenoh_options)
    mode, listen = options.mode, options.listen
    if config.link.topology == "router":  # a client of the router: it listens nowhere
        mode, listen, peers = "client", (), (relays[(i, len(names))].endpoint,)
    elif relays:
        # Gossip off: peers would tell each other their own endpoints and meet around a relay.
        peers = tuple(relays[(i, j)].endpoint for j in linked if j > i)
        zenoh.update(ZENOH_NO_GOSSIP)
    else:  # on a shared channel dialled only to fetch what a robot missed
        peers = tuple(f"{options.link_protocol}/127.0.0.1:{ports[j]}" for j in linked)
    transport = replace(
        options, mode=mode, listen=listen, port=ports[i], connect=peers,
        zenoh_options=zenoh,
    )  # fmt: skip
    return replace(config, robot=robot, transport=transport)


def launch(cmd: list[str], log, readers: list[threading.Thread]) -> subprocess.Popen:
    """A robot process, its output relayed to ``log`` by a thread added to ``readers``."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    readers.append(threading.Thread(target=_relay, args=(proc, log), daemon=True))
    readers[-1].start()
    return proc


def _relay(proc: subprocess.Popen, log) -> None:
    """Child's status lines and messages → our progress log, as they come."""

    def pump(stream, fmt):
        for line in stream:
            line = line.rstrip()
            if line:
                log(fmt(line))

    def status(line: str) -> str:
        try:
            s = json.loads(line)
        except ValueError:
            return line
        return (
            f"  {s['robot']}: submap {s['seq']} sent ({s['bytes']} B); {s['received']} received, "
            f"{s['matches']} matches, groups {s['groups']}"
        )

    err = threading.Thread(target=pump, args=(proc.stderr, lambda x: f"  {x}"), daemon=True)
    err.start()
    pump(proc.stdout, status)
    err.join(timeout=5)
