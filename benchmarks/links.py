"""The demo over emulated links: submaps lost, time and bytes, against perfect links.

Prints one JSON object. Each case runs the whole demo (`gmmap.cli.demo.run_demo`, robots as
separate processes) with one counting relay between every two linked robots
(`gmmap.eval.links`): perfect links, per-link caps of 10 kB/s, 2 kB/s and 500 B/s, 30 % loss
(a 0.2 s TCP stall per lost chunk), two partitions of 30 s, a chain (robot i linked to
i + 1 only: the others' submaps go through the robots in between) and a router (every robot
a Zenoh client of one router, linked to it alone), rendezvous links (up only while two
robots are within 8 m, or in line of sight, the robots moving in step at twice their speed;
`gmmap.eval.links.Rendezvous`; Zenoh over UDP there, as the demo runs them, and the 8 m case
once more over TCP) and perfect links with robot 1 killed with SIGKILL after its
third submap and restarted on its store, and perfect links over the first 100 frames (the
difference to the whole run is what one more delivered submap costs on the wire, the
sessions' set-up and the ending apart). Per case: submaps lost
(built but never delivered to a peer in reach; goal 0), and on rendezvous links those
built after their robot left every peer's reach for good (``out_of_reach``: no protocol can
deliver them; `gmmap.eval.delivery`) and of the lost those that contacts of at least 2 s
could have carried, each robot in between holding them for 2 s of one (``lost_lasting``;
the others met their peers only for less, or reached a robot in between too late), whether
every robot ended complete, the wall
time, the time until every robot held every submap, the bytes on the wire per delivered
submap (headers, ACKs, Zenoh's framing, adverts and fetches included; goal <= 1,000 B) and
whether the robots end holding the same submaps, groups and pose-graph matches as on
perfect links, and how far apart their optimised anchors end (m). Also the
bytes and packets an idle link between two robots carries per minute, over TCP and over UDP,
and the bytes on the
wire per 750 B submap sent alone or in bundles of 2 to 6 (`RobotOptions.bundle`). With
``--plots DIR``, each robot count's map completeness over time, one curve per case
(``completeness_<n>_robots.png``). On rendezvous links a robot that ends out of everyone's
reach keeps its last submaps (they would go at the next meeting) and the others wait for it
until the deadline (30 s): those submaps are out of reach, and the robots end incomplete.

    .venv/bin/python benchmarks/links.py [--robots 3,5] [--cases perfect,10k,...] [--plots DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from gmmap.cli.demo import backend_follows_drift, run_demo
from gmmap.config import Config
from gmmap.eval.fleetplots import completeness, plot_completeness
from gmmap.eval.wire import delivered
from gmmap.options import LinkOptions, RobotOptions, SimOptions, TransportOptions

CASES = {
    "perfect": LinkOptions(emulate=True),
    "10k": LinkOptions(rate=10_000),
    "2k": LinkOptions(rate=2_000),
    "500": LinkOptions(rate=500),
    "loss_30": LinkOptions(loss=0.3),
    "partitions_2x30s": LinkOptions(outages=((5.0, 35.0), (45.0, 75.0))),
    "chain": LinkOptions(topology="chain"),
    "router": LinkOptions(topology="router"),
    "rendezvous_8m": LinkOptions(range_m=8.0),
    "rendezvous_sight": LinkOptions(line_of_sight=True),
    "rendezvous_8m_tcp": LinkOptions(range_m=8.0),
    "kill_9": LinkOptions(emulate=True),
    "perfect_100_frames": LinkOptions(emulate=True),
}
PROTOCOL = {"rendezvous_8m_tcp": "tcp"}  # else the demo's: UDP on rendezvous links, TCP on others
CRASH = {"kill_9": (1, 3)}  # robot 1 killed after its third submap, restarted on its store
# The same perfect links over the first 100 frames only: what the rest of the run adds per
# submap is the cost of one more submap, once the sessions are set up.
FRAMES = {"perfect_100_frames": 100}
# Robots that drove apart wait for each other until the deadline: on rendezvous links, the
# deadline is the end of the run.
RENDEZVOUS_DEADLINE_S = 30.0


def case(robots: int, name: str) -> dict:
    link = CASES[name]
    deadline = RENDEZVOUS_DEADLINE_S if link.rendezvous else 180.0
    base = Config(
        sim=SimOptions(robots=robots),
        robot=RobotOptions(linger=2.0, deadline=deadline),
        transport=TransportOptions(protocol=PROTOCOL.get(name)),
    )
    config = backend_follows_drift(replace(base, link=link))
    with tempfile.TemporaryDirectory() as out:
        said: list[str] = []
        try:
            r = run_demo(config, FRAMES.get(name), Path(out), said.append, CRASH.get(name))
        except RuntimeError:
            print("\n".join(said[-40:]), file=sys.stderr)  # the robots' last words
            raise
        reports = {n: json.loads((Path(out) / f"{n}.json").read_text()) for n in r["received"]}
        curves = completeness({n: Path(out) / f"{n}.sqlite" for n in reports})
    lost = sum(r["lost"].values())
    # On links that stay every contact lasts.
    lost_lasting = sum(r["lost_lasting"].values()) if "lost_lasting" in r else lost
    unreachable = sum(r.get("out_of_reach", {}).values())
    held_all = not lost and not unreachable
    return {
        # None while some submap never reached some robot
        "all_held_after_s": round(max(t[-1] for t, _ in curves.values()), 1) if held_all else None,
        "curve": fleet_curve(curves),
        "lost": lost,
        "lost_lasting": lost_lasting,
        "out_of_reach": unreachable,
        "complete": all(rep["complete"] for rep in reports.values()),
        "wall_s": round(r["wall_s"], 1),
        "wire_bytes_per_delivered_submap": r["wire_bytes_per_delivered_submap"],
        "wire_bytes": sum(sum(link["bytes"]) for link in r["links"]),
        "delivered": delivered(reports),
        "payload_bytes_per_submap": r["bytes_per_submap"]["wire"],
        "groups": r["groups"],
        "held": {n: rep["held"] for n, rep in reports.items()},
        "kept": {n: sorted(_kept(rep)) for n, rep in reports.items()},
        "poses": {n: rep["poses"] for n, rep in reports.items()},
        **({"restarted_reloaded": reports[f"robot_{CRASH[name][0]}"]["reloaded"]}
           if name in CRASH else {}),
    }  # fmt: skip


def _kept(report: dict) -> list[tuple]:
    """The robot's pose-graph match edges and what the backend made of them."""
    return [(*e["target"], *e["source"], str(e["backend"])) for e in report["edges"]]


def pose_difference(row: dict, perfect: dict) -> float | None:
    """The largest distance (m) between a robot's optimised anchor here and on perfect links;
    None when they hold different anchors."""
    worst = 0.0
    for name, poses in row["poses"].items():
        other = perfect["poses"].get(name, {})
        if poses.keys() != other.keys():
            return None
        for key, pose in poses.items():
            moved = np.asarray(pose)[:3, 3] - np.asarray(other[key])[:3, 3]
            worst = max(worst, float(np.linalg.norm(moved)))
    return worst


def fleet_curve(curves: dict) -> tuple[list[float], list[float]]:
    """The robots' completeness curves as one: the mean share held over time."""
    t = np.unique(np.concatenate([t for t, _ in curves.values()]))
    held = [np.interp(t, ct, share, left=0.0) for ct, share in curves.values()]
    return t.round(2).tolist(), np.mean(held, axis=0).round(4).tolist()


@contextlib.contextmanager
def _pair(tmp: str, protocol: str = "tcp"):
    """Two robots' transports, b reaching a through a counting relay, both serving a store
    and subscribed: (relay, a, b, messages b received)."""
    from gmmap.eval.links import relayed_pair
    from gmmap.fleet.storage.store import Store

    got: list[int] = []
    pair = relayed_pair("idle", protocol=protocol)
    with Store(Path(tmp) / "a.db") as store, pair as (relay, a, b):
        for t in (a, b):
            t.serve(store.fetch_provider, store.robots)
        a.subscribe(lambda *_: None)
        b.subscribe(lambda robot, kind, seq, payload: got.append(seq))
        time.sleep(2.0)  # declarations settle
        yield relay, a, b, got


def _wire(relay, before) -> dict[str, int]:
    """The wire bytes and packets the relay counted since ``before``, both directions."""
    after = relay.counts()
    return {
        k: sum(getattr(after[d], k) - getattr(before[d], k) for d in after)
        for k in ("wire_bytes", "packets")
    }


def idle(seconds: float, protocol: str = "tcp") -> dict:
    """What two robots' transports (presence, subscription, fetch service) put on the link
    between them while neither has anything to send, per minute, in both directions."""
    with tempfile.TemporaryDirectory() as tmp, _pair(tmp, protocol) as (relay, *_):
        before = relay.counts()
        time.sleep(seconds)
        wire = _wire(relay, before)
    return {k: round(v * 60.0 / seconds) for k, v in wire.items()}


def bundles(sizes=(1, 2, 3, 4, 6), repeats: int = 10, payload: int = 750) -> dict:
    """Bytes on the wire per ``payload``-byte submap (both directions: headers, ACKs and
    Zenoh's framing included) when submaps leave alone or ``size`` back to back, as the
    outbox's bundles do (`RobotOptions.bundle`), on the relay's 1,448-byte segments."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp, _pair(tmp) as (relay, a, _, got):
        seq = 0
        for size in sizes:
            before = relay.counts()
            for _ in range(repeats):
                for _ in range(size):
                    a.publish("submap", seq, bytes(payload))
                    seq += 1
                time.sleep(0.3)  # the ACKs, and the next bundle apart
            out[str(size)] = round(_wire(relay, before)["wire_bytes"] / (size * repeats), 1)
        if len(got) != seq:
            raise RuntimeError(f"{seq - len(got)} of {seq} messages did not arrive")
    return out


def marginal(rows: dict) -> float | None:
    """The bytes on the wire one more delivered submap costs: between the run over the first
    100 frames and the whole run, on perfect links."""
    full, short = rows.get("perfect"), rows.get("perfect_100_frames")
    if not full or not short or full["delivered"] <= short["delivered"]:
        return None
    return (full["wire_bytes"] - short["wire_bytes"]) / (full["delivered"] - short["delivered"])


def ended(row: dict) -> tuple:
    """What the robots ended with: the submaps each held, the groups and the kept matches."""
    return row["held"], row["groups"], row["kept"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", default="3,5")
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--plots", type=Path, help="Write completeness PNGs here.")
    parser.add_argument("--idle-s", type=float, default=60.0, help="Idle link measured (s).")
    args = parser.parse_args()
    out: dict = {"idle_link_per_minute": idle(args.idle_s)}
    out["idle_link_per_minute_udp"] = idle(args.idle_s, "udp")
    print(f"idle link: {out['idle_link_per_minute']}, over UDP {out['idle_link_per_minute_udp']}",
          file=sys.stderr, flush=True)  # fmt: skip
    out["wire_bytes_per_submap_by_bundle"] = bundles()
    print(f"bundles: {out['wire_bytes_per_submap_by_bundle']}", file=sys.stderr, flush=True)
    for robots in (int(n) for n in args.robots.split(",")):
        rows = {}
        for name in args.cases.split(","):
            print(f"{robots} robots, {name}", file=sys.stderr, flush=True)
            rows[name] = case(robots, name)
            print(json.dumps(rows[name]), file=sys.stderr, flush=True)
        perfect = rows.get("perfect")
        out[f"{robots}_robots_marginal_wire_bytes_per_submap"] = marginal(rows)
        for row in rows.values():
            row["same_as_perfect"] = perfect is not None and ended(row) == ended(perfect)
            row["pose_difference_m"] = pose_difference(row, perfect) if perfect else None
        if args.plots:
            args.plots.mkdir(parents=True, exist_ok=True)
            curves = {name: tuple(map(np.array, row["curve"])) for name, row in rows.items()}
            title = f"{robots} robots: mean share of all submaps held"
            plot_completeness(curves, args.plots / f"completeness_{robots}_robots.png", title)
        for row in rows.values():
            del row["held"], row["curve"], row["kept"], row["poses"]
        out[f"{robots}_robots"] = rows
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
