"""What the emulated links carried (`gmmap.eval.links.Relay` counts), per robot and per link."""

from __future__ import annotations


def wire_report(relays: dict, names: list[str], deliveries: int) -> dict:
    """What the relays carried: per robot the packets it put on its links and their bytes,
    headers included (``bytes``), the payload under them (``payload_bytes``: Zenoh's framing,
    keep-alives and queries, what the relay read), the bytes it took off them; per link each
    direction, with the datagrams a datagram link dropped; and the bytes per submap delivered
    to a peer (``deliveries`` in all)."""
    keys = ("bytes", "packets", "payload_bytes", "received_bytes", "chunks")
    wire = {n: dict.fromkeys(keys, 0) for n in names}
    links = []
    for (i, j), relay in sorted(relays.items()):
        c = relay.counts()
        a, b = names[i], names[j] if j < len(names) else "router"
        for sender, receiver, d in ((a, b, c["forward"]), (b, a, c["backward"])):
            if sender in wire:  # the router is not among the robots
                w = wire[sender]
                w["bytes"] += d.wire_bytes
                w["packets"] += d.packets
                w["payload_bytes"] += d.bytes
                w["chunks"] += d.chunks
            if receiver in wire:
                wire[receiver]["received_bytes"] += d.wire_bytes
        links.append({
            "robots": [a, b],
            "bytes": [c["forward"].wire_bytes, c["backward"].wire_bytes],
            "packets": [c["forward"].packets, c["backward"].packets],
            "dropped": [c["forward"].dropped, c["backward"].dropped],
        })  # fmt: skip
    total = sum(sum(link["bytes"]) for link in links)
    return {
        "wire": wire,
        "links": links,
        "wire_bytes_per_delivered_submap": total / deliveries if deliveries else None,
    }


def delivered(reports: dict[str, dict]) -> int:
    """The submaps robots ended holding from others: what a restarted robot received before
    it was killed counts, and its report's ``submaps_received`` (this process only) misses."""
    return sum(n for name, r in reports.items() for robot, n in r["held"].items() if robot != name)
