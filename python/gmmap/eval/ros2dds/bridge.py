"""zenoh-bridge-ros2dds for tests: ``make ros2`` builds `BINARY` (zenoh-plugin-ros2dds in a
small host, ``tools/ros2dds-bridge``); `RosDdsBridge` runs it on loopback between one DDS
domain and one Zenoh endpoint, as a robot's bridge would run beside its ROS 2 nodes."""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

from gmmap.errors import TransportError

# CycloneDDS on loopback only (no multicast, localhost the one peer): the bridge and the
# stand-in nodes both, so tests never reach past the machine.
LOCALHOST = (
    '<CycloneDDS><Domain id="any"><General>'
    '<Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
    '<Peers><Peer address="localhost"/></Peers></Discovery></Domain></CycloneDDS>'
)
PLUGIN_VERSION = "1.10.2"  # tools/ros2dds-bridge/Cargo.toml; the cache is keyed by it
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "gmmap"
BINARY = Path(
    os.environ.get(
        "GMMAP_ROS2DDS_BRIDGE",
        CACHE / f"ros2dds-bridge-{PLUGIN_VERSION}" / "release" / "gmmap-ros2dds-bridge",
    )
)


def missing() -> str | None:
    """Why the bridge cannot run here (None when it can): for tests to skip with."""
    if not BINARY.is_file():
        return f"{BINARY} not built: run `make ros2`"
    try:
        import cyclonedds  # noqa: F401
    except ImportError:
        return "the cyclonedds package is not installed: run `make ros2`"
    return None


class RosDdsBridge:
    """The bridge process: DDS ``domain`` on loopback ↔ Zenoh, listening on ``listen``
    (``tcp/127.0.0.1:<port>``); ``namespace`` prefixes every key as the bridge's setting
    does. A context manager; `close` stops it."""

    def __init__(self, domain: int, listen: str, namespace: str = "/", folder: Path = CACHE):
        config = {
            "mode": "peer",
            "listen": {"endpoints": [listen]},
            "scouting": {"multicast": {"enabled": False}},
            "plugins": {
                "ros2dds": {
                    "domain": domain,
                    "namespace": namespace,
                    "ros_automatic_discovery_range": "LOCALHOST",
                }
            },
        }
        folder.mkdir(parents=True, exist_ok=True)
        name = f"ros2dds-bridge-{os.getpid()}-{domain}"
        self.config, self.log = folder / f"{name}.json5", folder / f"{name}.log"
        self.config.write_text(json.dumps(config))
        env = {
            **os.environ,
            "CYCLONEDDS_URI": LOCALHOST,
            "RUST_LOG": os.environ.get("RUST_LOG", "warn"),
        }
        # Its output goes to a file, not a pipe: a pipe nobody reads would stop the bridge
        # once its logs filled it.
        with open(self.log, "wb") as out:
            self.process = subprocess.Popen(
                [str(BINARY), str(self.config)], stdout=out, stderr=subprocess.STDOUT, env=env
            )
        self._ready(timeout=60.0)

    def _ready(self, timeout: float) -> None:
        """Waits for the host's "ready" line (it prints it once the runtime has started)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            lines = self.log.read_text(errors="replace").splitlines()
            if "ready" in (line.strip() for line in lines):
                return
            if self.process.poll() is not None:
                raise TransportError(f"the ROS 2 DDS bridge exited: {' | '.join(lines[-20:])}")
            time.sleep(0.1)
        self.close()
        raise TransportError(f"the ROS 2 DDS bridge did not start within {timeout:.0f} s")

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self.config.unlink(missing_ok=True)
        self.log.unlink(missing_ok=True)

    def __enter__(self) -> RosDdsBridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
