"""What securing a fleet costs: bytes per submap and per link, CPU per seal, the demo beside plain.

Prints one JSON object:

- ``seal``: the bytes a seal adds to a submap (measured on one built from the simulator), and
  the time to seal one and to check one (Ed25519, `cryptography`), against decoding the same
  submap, which a check stands in front of (ratio);
- ``link``: what two robots' transports put on the link between them, counted by a relay
  (headers included), to meet and settle (set-up) and then per idle minute: plain TCP against
  mutual TLS with access control;
- ``demo``: the 3-robot demo over emulated perfect links, plain and ``--secure``: bytes on the
  wire per delivered submap, payload per submap, the groups, refusals, wall time, and whether
  the secured robots end holding the same submaps, groups and matches as the plain ones.

    .venv/bin/python benchmarks/security.py [--idle-s 30]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from gmmap.cli.demo import backend_follows_drift, run_demo
from gmmap.config import Config
from gmmap.fleet.security.access import issue_fleet
from gmmap.fleet.security.credentials import load
from gmmap.fleet.security.seal import open_sealed, seal
from gmmap.fleet.wire.codec import decode, encode
from gmmap.io.sim import simulate_options
from gmmap.mapping.submap import SubmapBuilder


def _timed(fn, n: int) -> float:
    start = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - start) / n


def seal_costs(tmp: Path, n: int = 2000) -> dict:
    config = Config()
    frames = simulate_options(config.sim)[0]
    builder = SubmapBuilder("a", config.build, config.select)
    s = next(x for x in map(builder.add, frames) if x is not None)
    payload = encode(s)
    creds = load(issue_fleet(tmp / "fleet", "f", ["a", "b"])["a"])
    sealed = seal(creds.sign, "f", "a", "submap", 0, payload)
    keys = load(tmp / "fleet" / "b").member_key
    check = _timed(lambda: open_sealed(keys, "f", "a", "submap", 0, sealed), n)
    decoding = _timed(lambda: decode(payload), n // 10)
    return {
        "submap_bytes": len(payload),
        "sealed_bytes": len(sealed),
        "added_bytes": len(sealed) - len(payload),
        "sign_us": 1e6 * _timed(lambda: seal(creds.sign, "f", "a", "submap", 0, payload), n),
        "check_us": 1e6 * check,
        "decode_us": 1e6 * decoding,
        "check_vs_decode": check / decoding,
    }


def link_costs(tmp: Path, secure: bool, idle_s: float) -> dict:
    """Set-up and idle bytes between two robots' transports, through a counting relay."""
    from gmmap.eval.links import ZENOH_NO_GOSSIP, Relay
    from gmmap.fleet.net.keys import free_port
    from gmmap.fleet.net.transport import Transport, TransportConfig
    from gmmap.fleet.storage.store import Store
    from gmmap.options import TransportOptions

    members = issue_fleet(tmp / f"link{int(secure)}", "f", ["a", "b"]) if secure else {}
    creds = {n: load(p) for n, p in members.items()}
    scheme = "tls" if secure else "tcp"
    port = free_port()
    with Relay(("127.0.0.1", port)) as relay:
        connect = (relay.endpoint.replace("tcp/", f"{scheme}/"),)
        a_opts = TransportOptions(port=port, zenoh_options=ZENOH_NO_GOSSIP)
        b_opts = TransportOptions(connect=connect, zenoh_options=ZENOH_NO_GOSSIP)
        start = time.monotonic()
        with (
            Store(tmp / f"a{int(secure)}.db") as store,
            Transport(TransportConfig("f", "a", a_opts, creds.get("a"))) as a,
            Transport(TransportConfig("f", "b", b_opts, creds.get("b"))) as b,
        ):
            for t in (a, b):
                t.serve(store.fetch_provider, store.robots)
                t.subscribe(lambda *_: None)
            if not b.wait_for_peers(["a"], 10):
                raise RuntimeError("the two robots did not meet")
            met_s = time.monotonic() - start
            time.sleep(2.0)  # declarations settle
            setup = relay.counts()
            time.sleep(idle_s)
            after = relay.counts()
    total = {k: sum(getattr(c, k) for c in setup.values()) for k in ("wire_bytes", "packets")}
    idle = sum(after[d].wire_bytes - setup[d].wire_bytes for d in after) * 60.0 / idle_s
    return {"setup_wire_bytes": total["wire_bytes"], "setup_packets": total["packets"],
            "met_after_s": met_s, "idle_wire_bytes_per_minute": round(idle)}  # fmt: skip


def demo(secure: bool) -> dict:
    base = Config()
    config = backend_follows_drift(replace(base, link=replace(base.link, emulate=True)))
    with tempfile.TemporaryDirectory() as tmp:
        r = run_demo(config, out=Path(tmp), log=lambda *_: None, secure=secure)
    kept = {n: sorted(tuple(e) for e in m.items()) for n, m in r["matches"].items()}
    return {
        "secure": r["secure"],
        "wire_bytes_per_delivered_submap": r["wire_bytes_per_delivered_submap"],
        "payload_bytes_per_submap": r["bytes_per_submap"]["wire"],
        "received": r["received"],
        "groups": r["groups"],
        "refused": sum(n for by in r["refused"].values() for n in by.values()),
        "lost": sum(r["lost"].values()),
        "wall_s": r["wall_s"],
        "_ended": (r["received"], r["groups"], kept),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--idle-s", type=float, default=30.0, help="Idle link measured (s).")
    args = parser.parse_args()
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        out["seal"] = seal_costs(Path(tmp))
        print(f"seal: {out['seal']}", file=sys.stderr, flush=True)
        out["link"] = {
            name: link_costs(Path(tmp), secure, args.idle_s)
            for name, secure in (("plain", False), ("secure", True))
        }
        print(f"link: {out['link']}", file=sys.stderr, flush=True)
    rows = {name: demo(secure) for name, secure in (("plain", False), ("secure", True))}
    same = rows["plain"].pop("_ended") == rows["secure"].pop("_ended")
    rows["secure"]["same_as_plain"] = same
    out["demo"] = rows
    p, s = out["link"]["plain"], out["link"]["secure"]
    out["tls_setup_bytes_per_link"] = s["setup_wire_bytes"] - p["setup_wire_bytes"]
    out["secure_vs_plain_wire_bytes_per_submap"] = (
        rows["secure"]["wire_bytes_per_delivered_submap"]
        / rows["plain"]["wire_bytes_per_delivered_submap"]
    )
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
