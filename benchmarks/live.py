"""A robot node on live input: the rate it keeps up with on one core, what it skips, latency.

Prints one JSON object. Per sensor, simulated frames are pushed into a `LiveInput`
(`gmmap.mapping.live`) at the sensor's rate by a driver thread, poses just ahead of them,
while the node maps (no peers): a 640×480 depth camera at 30 Hz and a 16-beam LiDAR at
10 Hz, the process pinned to one core. Per sensor: the frames mapped and skipped (the oldest
waiting frame goes when ``max_pending`` wait), the rate mapped, the latency from a submap's
last frame being pushed to the submap being built and sent (median, max), and CPU seconds per
mapped frame. Baseline: the same frames as a recording (`RobotNode.start_frames` on a list:
nothing skipped), its frames per second (``times_real_time``: against the sensor's rate) and
CPU per frame, in the same run; ``cpu_vs_recorded`` is live CPU per frame against it.

    .venv/bin/python benchmarks/live.py [--seconds 10] [--cores 1]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from gmmap.config import Config
from gmmap.fleet.node.robot import RobotNode
from gmmap.io.sim import simulate_options
from gmmap.mapping.live import LiveInput

SENSORS = {"depth_640x480_30hz": ("depth", 640, 30.0), "lidar_16_10hz": ("lidar", 320, 10.0)}


def frames_of(sensor: str, width: int, n: int) -> list:
    base = Config()
    sim = replace(base.sim, sensor=sensor, width=width, robots=1)
    run = simulate_options(sim)[0]
    return [run[i] for i in range(min(n, len(run)))]


def cpu_seconds() -> float:
    """This process's CPU time so far (user + system, every thread)."""
    t = os.times()
    return t.user + t.system


def node(tmp: Path, name: str) -> RobotNode:
    config = Config()
    config = replace(config, robot=replace(config.robot, name=name, store=str(tmp / f"{name}.db")))
    return RobotNode(config)


def live_run(tmp: Path, frames: list, hz: float) -> dict:
    n = node(tmp, "live")
    live = LiveInput(max_pending=8)
    pushed: dict[float, float] = {}
    latencies: list[float] = []

    def built(b) -> None:  # from the push of the submap's last frame
        latencies.append(time.monotonic() - pushed.get(float(b.submap.stamps[-1]), np.nan))

    n.on_built = built
    n.start()
    builder = n.start_frames(live)

    def driver() -> None:
        start = time.monotonic()
        for k, f in enumerate(frames):
            time.sleep(max(0.0, start + k / hz - time.monotonic()))
            live.push_pose(f.stamp + 1e-3, f.pose)  # odometry a hair ahead of the frame
            live.push_pose(f.stamp - 1e-3, f.pose)
            pushed[float(f.stamp)] = time.monotonic()
            live.push_frame(f.stamp, f.points)
        live.close()

    cpu, wall = cpu_seconds(), time.monotonic()
    feeder = threading.Thread(target=driver)
    feeder.start()
    feeder.join()
    builder.join()
    wall, cpu = time.monotonic() - wall, cpu_seconds() - cpu
    n.stop()
    c = live.counts
    return {
        "frames": c.frames,
        "mapped": c.mapped,
        "skipped": c.skipped,
        "no_pose": c.no_pose,
        "mapped_per_s": c.mapped / wall,
        "sensor_hz": hz,
        "submaps": len(latencies),
        "latency_median_s": float(np.median(latencies)) if latencies else None,
        "latency_max_s": float(np.max(latencies)) if latencies else None,
        "cpu_s_per_mapped_frame": cpu / max(1, c.mapped),
    }


def recorded_run(tmp: Path, frames: list) -> dict:
    n = node(tmp, "recorded")
    n.start()
    cpu, wall = cpu_seconds(), time.monotonic()
    n.start_frames(frames).join()
    wall, cpu = time.monotonic() - wall, cpu_seconds() - cpu
    built = n.counts["built"]
    n.stop()
    return {"frames": len(frames), "frames_per_s": len(frames) / wall,
            "cpu_s_per_frame": cpu / len(frames), "submaps": built}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="Sensor time per run.")
    parser.add_argument("--cores", type=int, default=1, help="Cores the process may use.")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: args.cores]))
    out: dict = {
        "cores": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    }
    for name, (sensor, width, hz) in SENSORS.items():
        print(f"{name}: rendering", file=sys.stderr, flush=True)
        frames = frames_of(sensor, width, int(args.seconds * hz))
        with tempfile.TemporaryDirectory() as tmp:
            print(f"{name}: live", file=sys.stderr, flush=True)
            live = live_run(Path(tmp), frames, hz)
            print(f"{name}: recorded", file=sys.stderr, flush=True)
            recorded = recorded_run(Path(tmp), frames)
        live["keeps_up"] = live["skipped"] == 0 and live["no_pose"] == 0
        live["cpu_vs_recorded"] = live["cpu_s_per_mapped_frame"] / recorded["cpu_s_per_frame"]
        recorded["times_real_time"] = recorded["frames_per_s"] / hz
        out[name] = {"live": live, "recorded": recorded}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
