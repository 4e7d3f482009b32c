"""A robot node on ROS 1: latency, keep-up rate, bytes and CPU beside the same recorded frames.

The node is `gmmap.io.ros1bridge`'s, fed by rosbag play.

Prints one JSON object. A real roscore; ``rosbag play`` (real time) of a bag written from
the data (`gmmap.io.ros1bag`); the node in this process, pinned to ``--cores`` cores with
the roscore and the player outside that set where the machine has cores to spare. Per input:

- ``depth_image_30hz``: the shared TUM fr1_xyz depth images (640×480 16UC1 at 30 Hz) with
  their CameraInfo, posed by /tf odom → base_link and a /tf_static mounting;
- ``pointcloud2_lidar_10hz``: simulated 16-beam LiDAR scans (10 Hz) as PointCloud2 with
  nav_msgs/Odometry.

Per input, ``ros``: frames the bridge handed on, mapped, skipped (back-pressure) and without
a pose; the latency from a frame's arrival (decoded, handed to the live input) to its
submap's publication (built and sent: median, max); CPU seconds per mapped frame; the ROS
input per frame (bytes on the topic) and the submap bytes built. ``recorded``: the same
frames as a recording (`RobotNode.start_frames` on a list), its CPU per frame, submaps and
bytes. ``cpu_vs_recorded`` is the ROS run's CPU per mapped frame against it (the price of
decoding ROS messages, interpolating poses and the rospy threads).

    .venv/bin/python benchmarks/ros1.py [--seconds 10] [--cores 1]   (needs make ros1)
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from live import cpu_seconds, node  # benchmarks/live.py: this script's folder is on the path

from gmmap.config import Config
from gmmap.fleet.net.transport import free_port
from gmmap.fleet.node.robot import RobotNode
from gmmap.io import ros1bridge
from gmmap.io.datasets import TumRgbd
from gmmap.io.datasets.tum import read_depth
from gmmap.io.ros1bag import write_cloud_bag, write_depth_bag
from gmmap.io.ros2msgs import Camera, depth_points
from gmmap.io.sim import simulate_options
from gmmap.mapping.frame import Frame
from gmmap.mapping.live import LiveInput
from gmmap.math.geometry import make_poses
from gmmap.options import RosOptions

TUM = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "tum_fr1_xyz"
STRIDE = 4  # the depth pixels kept, both ways (RosOptions.depth_stride's default)
MOUNT = make_poses(np.array([[0.1, 0.0, 0.3]]), np.array([[0.0, 0.0, 0.7071068, 0.7071068]]))[0]


def submap_bytes(n: RobotNode) -> int:
    """The bytes of the submaps built, as sent (sealed payloads): the same whether or not the
    outbox has sent them yet."""
    return sum(int(w["wire"]) for w in n.wire.values())


def depth_input(tmp: Path, n: int) -> tuple[Path, list, RosOptions]:
    """The bag, the recorded frames (the same millimetre images, back-projected as the bridge
    does them) and the ROS settings."""
    data = TumRgbd(TUM)
    k, stamps, poses = min(n, len(data)), data.stamps, data.poses
    mm = [(read_depth(f).astype(np.float64) / 5).astype(np.uint16) for f in data.files[:k]]
    bag = write_depth_bag(tmp / "depth.bag", zip(stamps[:k], poses[:k], mm, strict=True),
                          data.intrinsics, MOUNT)  # fmt: skip
    i = data.intrinsics
    camera = Camera(i.fx, i.fy, i.cx, i.cy)
    frames = [Frame(stamps[j], depth_points(_image(m), camera, STRIDE), poses[j]) for j, m in
              enumerate(mm)]  # fmt: skip
    options = RosOptions(depth_topic="/camera/depth/image", depth_stride=STRIDE, tf_parent="odom")
    return bag, frames, options


def _image(mm: np.ndarray) -> SimpleNamespace:
    h, w = mm.shape
    return SimpleNamespace(width=w, height=h, encoding="16UC1", is_bigendian=0, step=2 * w,
                           data=mm.astype("<u2").tobytes())  # fmt: skip


def lidar_frames(n: int) -> list:
    """The first ``n`` scans of a simulated 16-beam LiDAR at 10 Hz."""
    base = Config()
    run = simulate_options(replace(base.sim, sensor="lidar", width=320, robots=1, rate=10.0))[0]
    return [run[i] for i in range(min(n, len(run)))]


def lidar_input(tmp: Path, n: int) -> tuple[Path, list, RosOptions]:
    frames = lidar_frames(n)
    bag = write_cloud_bag(tmp / "lidar.bag", {"": frames})
    return bag, frames, RosOptions(cloud_topic="/camera/depth/points", odom_topic="/odom")


INPUTS = {"depth_image_30hz": (depth_input, 30.0), "pointcloud2_lidar_10hz": (lidar_input, 10.0)}


def ros_run(tmp: Path, bag: Path, options: RosOptions, env: dict, others: set) -> dict:
    """The node on ROS 1 while ``rosbag play`` plays the bag (in a child: rospy is one node
    per process, once)."""
    n = node(tmp, "ros")
    live = LiveInput(max_pending=8)
    bridge = ros1bridge.Ros1Bridge("ros", options, live)
    arrived: dict[float, float] = {}
    latencies: list[float] = []
    push, ending = live.push_frame, threading.Event()

    def timed_push(stamp: float, points: np.ndarray) -> None:
        arrived[round(float(stamp), 6)] = time.monotonic()
        push(stamp, points)

    def built(b) -> None:  # a submap the end of input closed is not timed
        last = round(float(b.submap.stamps[-1]), 6)
        if not ending.is_set():
            latencies.append(time.monotonic() - arrived.get(last, np.nan))

    live.push_frame, n.on_built = timed_push, built
    n.start()
    builder = n.start_frames(live)
    time.sleep(2.0)  # the master connects the bag's publishers to the node's subscribers
    cpu, wall = cpu_seconds(), time.monotonic()
    player = subprocess.Popen(["rosbag", "play", "-q", "-d", "1", str(bag)], env=env,
                              stdout=subprocess.DEVNULL, preexec_fn=_pin(others))  # fmt: skip
    player.wait(timeout=600)
    time.sleep(1.5)  # the last frames' poses and fitting
    ending.set()
    live.close()
    builder.join()
    wall, cpu = time.monotonic() - wall, cpu_seconds() - cpu
    bridge.close()
    c = live.counts
    out = {
        "frames": c.frames, "mapped": c.mapped, "skipped": c.skipped, "no_pose": c.no_pose,
        "bad_messages": bridge.counts["bad"], "submaps": n.counts["built"],
        "timed_submaps": len(latencies),
        "latency_median_s": float(np.nanmedian(latencies)) if latencies else None,
        "latency_max_s": float(np.nanmax(latencies)) if latencies else None,
        "cpu_s_per_mapped_frame": cpu / max(1, c.mapped), "wall_s": wall,
        "submap_bytes": submap_bytes(n),
    }  # fmt: skip
    n.stop()
    return out


def recorded_run(tmp: Path, frames: list) -> dict:
    n = node(tmp, "recorded")
    n.start()
    cpu = cpu_seconds()
    n.start_frames(frames).join()
    cpu = cpu_seconds() - cpu
    out = {"frames": len(frames), "cpu_s_per_frame": cpu / len(frames),
           "submaps": n.counts["built"], "submap_bytes": submap_bytes(n)}  # fmt: skip
    n.stop()
    return out


def _pin(cores: set):
    return (lambda: os.sched_setaffinity(0, cores)) if cores else None


def roscore(tmp: Path, others: set) -> tuple[subprocess.Popen, dict]:
    ros1bridge.rospy()  # puts Debian's ROS 1 packages, rosgraph among them, on the path
    port = free_port()
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}", "ROS_HOME": str(tmp)}
    proc = subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True,
                            preexec_fn=_pin(others))  # fmt: skip
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_HOME=str(tmp))
    master = __import__("rosgraph").Master("/gmmap_bench")
    for _ in range(200):
        try:
            master.getPid()
            return proc, env
        except Exception:
            time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)
    raise RuntimeError("roscore did not start")


def one(name: str, seconds: float, cores: int) -> dict:
    make, hz = INPUTS[name]
    everything = sorted(os.sched_getaffinity(0))
    mine = set(everything[:cores])
    others = set(everything[cores:])
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bag, frames, options = make(tmp, int(seconds * hz))
        os.sched_setaffinity(0, mine)
        print(f"{name}: recorded", file=sys.stderr, flush=True)
        recorded = recorded_run(tmp, frames)
        core, env = roscore(tmp, others)
        try:
            print(f"{name}: ROS 1", file=sys.stderr, flush=True)
            ros = ros_run(tmp, bag, options, env, others)
        finally:
            os.killpg(core.pid, signal.SIGINT)
            core.wait(timeout=30)
        ros["input_bytes_per_frame"] = bag.stat().st_size / max(1, len(frames))
    ros["sensor_hz"] = hz
    ros["keeps_up"] = ros["skipped"] == 0 and ros["no_pose"] == 0
    ros["cpu_vs_recorded"] = ros["cpu_s_per_mapped_frame"] / recorded["cpu_s_per_frame"]
    return {"ros": ros, "recorded": recorded}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="Sensor time per input.")
    parser.add_argument("--cores", type=int, default=1, help="Cores the node may use.")
    parser.add_argument("--only", choices=sorted(INPUTS), help=argparse.SUPPRESS)  # the child
    args = parser.parse_args()
    if args.only:
        print(json.dumps(one(args.only, args.seconds, args.cores)))
        return
    if not ros1bridge.available():  # make bench runs everywhere; this one says why it did not
        print(json.dumps({"skipped": f"ROS 1 is not installed: {ros1bridge.SETUP}"}))
        return
    out: dict = {"cores": args.cores, "seconds": args.seconds}
    for name in INPUTS:
        child = [sys.executable, __file__, "--only", name, "--seconds", str(args.seconds),
                 "--cores", str(args.cores)]  # fmt: skip
        done = subprocess.run(child, check=True, stdout=subprocess.PIPE, text=True)
        out[name] = json.loads(done.stdout)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
