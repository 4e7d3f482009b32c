"""One radio channel shared by a whole fleet, as the kernel enforces it, for tests and benchmarks.

Every robot runs inside one network namespace and talks over its loopback, so whatever any of
them sends, unicast or multicast, crosses one interface; `tc tbf` caps that interface's egress
at ``rate`` bytes/s for all of them together, and the bytes on the air are the interface's own
counters, Zenoh's framing and the IP headers included. The loopback's MTU is set to Ethernet's
1,500 B (a token bucket drops a packet larger than its burst) and multicast is routed on it.
The per-link emulator (`gmmap.eval.links.relay`) stays for what only it shows: rendezvous
links, outages, delay.

Needs root, iproute2 and tc (`ChannelUnavailable` otherwise, which tests turn into a skip)::

    with SharedChannel(rate=500) as air:
        out = subprocess.run(air.command(["gmmap", "demo", "--json"]), capture_output=True)
        print(air.bytes_sent())
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field

from gmmap.errors import GmmapError

BURST = 1_600  # bytes: one full 1,500 B packet and its link header fit in the bucket


class ChannelUnavailable(GmmapError):
    """The shared channel cannot be set up here (not root, or no ip / tc)."""


@dataclass
class SharedChannel:
    """A namespace whose loopback is the fleet's shared channel (see the module docstring).

    ``rate``: bytes/s for all robots together (None: not capped); ``queue_s``: seconds of
    traffic the channel's queue holds before it drops (a radio modem's buffer)."""

    rate: float | None = None
    queue_s: float = 10.0
    name: str = field(default_factory=lambda: f"gmmap-air-{uuid.uuid4().hex[:8]}")
    _open: bool = field(default=False, init=False, repr=False)

    def __enter__(self) -> SharedChannel:
        if os.geteuid() != 0 or not (shutil.which("ip") and shutil.which("tc")):
            raise ChannelUnavailable("a shared channel needs root, iproute2 and tc")
        try:
            self._sh("ip", "netns", "add", self.name, here=True)
            self._open = True
            self._sh("ip", "link", "set", "lo", "mtu", "1500", "multicast", "on", "up")
            self._sh("ip", "route", "add", "224.0.0.0/4", "dev", "lo")
            if self.rate is not None:
                limit = max(2 * BURST, round(self.rate * self.queue_s))
                self._sh(
                    "tc", "qdisc", "add", "dev", "lo", "root", "tbf",
                    "rate", f"{round(self.rate * 8)}bit", "burst", str(BURST),
                    "limit", str(limit),
                )  # fmt: skip
        except (OSError, subprocess.SubprocessError) as err:
            self.close()
            raise ChannelUnavailable(f"cannot set up the shared channel: {err}") from err
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Removes the namespace (its processes should have ended). Idempotent."""
        if self._open:
            subprocess.run(["ip", "netns", "del", self.name], capture_output=True, timeout=10)
            self._open = False

    def command(self, argv: Sequence[str]) -> list[str]:
        """``argv`` run inside the channel's namespace."""
        return ["ip", "netns", "exec", self.name, *argv]

    def bytes_sent(self) -> int:
        """Bytes put on the channel so far, every robot's, as the interface counts them."""
        out = self._sh("cat", "/sys/class/net/lo/statistics/tx_bytes")
        return int(out)

    def _sh(self, *argv: str, here: bool = False) -> str:
        cmd = list(argv) if here else self.command(argv)
        done = subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=10)
        return done.stdout
