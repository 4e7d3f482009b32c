"""The demo on one radio channel shared by the whole fleet: broadcast against the unicast mesh.

Prints one JSON object. Each case runs `gmmap demo` (robots as separate processes, the office)
inside one network namespace whose loopback carries every robot's traffic, capped for all of
them together by `tc tbf` (`gmmap.eval.links.channel`): the kernel enforces the budget and the
bytes on the air are the interface's own count. Per robot count (3 and 5), channel rate
(10 kB/s, 2 kB/s, 500 B/s, 250 B/s) and sharing (``broadcast``: submaps and adverts on a UDP
multicast group, fetches unicast, each robot within its share of the channel's rate:
`TransportOptions.broadcast`, ``channel_rate``; ``unicast``: every message to every peer over
its own Zenoh link, the default):

- ``lost``: submaps built but never delivered to a peer (goal 0 at 500 B/s), ``delivered``:
  submaps the robots received from their peers, fetched ones included;
- ``all_held_after_s``: when every robot held every robot's submaps (None if never),
  ``first_heard_after_s``: when the last robot to receive a peer's submap received its first
  (set-up cost: connected and receiving), both from the fleet's first submap, and ``wall_s``
  of the whole demo;
- ``air_bytes``, ``air_bytes_per_submap`` (built) and its ratio to one submap's wire size
  (goal ≤ 1.2, however many robots hear it), with ``payload_bytes_per_submap``;
- ``groups``: the demo's map groups at the end.

Needs root, iproute2 and tc; skipped otherwise. 16 demos: 30-60 minutes on two cores.

    .venv/bin/python benchmarks/channel.py [--robots 3,5] [--rates 10000,2000,500,250]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from gmmap.eval.fleetplots import completeness
from gmmap.eval.links.channel import ChannelUnavailable, SharedChannel
from gmmap.fleet.storage.store import Store

GROUP = "udp/224.0.0.224:7447"
SHARING = ("unicast", "broadcast")
DEADLINE_S = 300.0  # five robots need ~240 s at 500 B/s


def case(robots: int, rate: float, sharing: str) -> dict:
    gmmap = str(Path(sys.executable).parent / "gmmap")
    with SharedChannel(rate=rate) as air, tempfile.TemporaryDirectory() as out:
        argv = [
            gmmap, "demo", "--json", "--robots", str(robots), "--out", out, "--linger", "2",
            "--deadline", str(DEADLINE_S),
        ]  # fmt: skip
        if sharing == "broadcast":  # the channel's rate is what the fleet is configured with
            argv += ["--broadcast", GROUP, "--channel-rate", str(rate)]
        before = air.bytes_sent()
        done = subprocess.run(air.command(argv), capture_output=True, text=True)
        on_air = air.bytes_sent() - before
        if done.returncode != 0:
            return {"error": done.stderr[-2000:]}
        r = json.loads(done.stdout)
        stores = {n: Path(out) / f"{n}.sqlite" for n in r["received"]}
        curves = completeness(stores)
        first = first_heard(list(stores.values()))
    lost = sum(r["lost"].values())
    wire = r["bytes_per_submap"]["wire"]
    return {
        "lost": lost,
        "delivered": sum(r["received"].values()),
        "all_held_after_s": (
            round(max(t[-1] for t, _ in curves.values()), 1) if not lost else None
        ),
        "first_heard_after_s": first,
        "wall_s": round(r["wall_s"], 1),
        "air_bytes": on_air,
        "submaps": r["submaps"],
        "air_bytes_per_submap": on_air / r["submaps"],
        "air_per_submap_over_wire_size": on_air / r["submaps"] / wire,
        "payload_bytes_per_submap": wire,
        "groups": len(r["groups"]),
    }


def first_heard(stores: list[Path]) -> float | None:
    """Seconds from the fleet's first submap until the last robot to hear a peer's submap
    heard its first: how soon every robot is connected and receiving (None if one never is)."""
    own, heard = [], []
    for path in stores:
        with Store(path, durable=False) as store:
            records = store.submaps()
        own += [r.received for r in records if r.own]
        peers = [r.received for r in records if not r.own]
        heard.append(min(peers) if peers else None)
    if not own or None in heard:
        return None
    return round(max(heard) - min(own), 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="3,5")
    parser.add_argument("--rates", default="10000,2000,500,250")
    parser.add_argument("--sharing", default=",".join(SHARING))
    args = parser.parse_args()
    out: dict = {}
    try:
        for robots in (int(n) for n in args.robots.split(",")):
            for rate in (float(x) for x in args.rates.split(",")):
                for sharing in args.sharing.split(","):
                    name = f"{robots}_robots_{rate:g}_Bps_{sharing}"
                    print(name, file=sys.stderr, flush=True)
                    out[name] = case(robots, rate, sharing)
    except ChannelUnavailable as err:
        out = {"skipped": str(err)}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
