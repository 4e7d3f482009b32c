"""The demo's emulated links (`gmmap.cli.demo`): robots paced on rendezvous links, who is in
reach of whom, and a counting relay for every linked pair (`gmmap.eval.links`)."""

from __future__ import annotations

import time
from dataclasses import replace

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
