"""A robot node on ROS 2 through the real DDS bridge: frames mapped, latency, CPU and bytes.

Prints one JSON object. The bridge is zenoh-plugin-ros2dds in its host (``make ros2``); a
stand-in ROS 2 node on CycloneDDS (`gmmap.eval.ros2dds`, in a child process, so that its
serialising is not counted) publishes at the sensor's rate; the robot node (this process)
maps in the bridge key format; a DDS subscriber (here) takes its MarkerArrays. Per input:

- ``depth_image_30hz``: the shared TUM fr1_xyz depth images (640×480 16UC1 at 30 Hz) with
  their CameraInfo, posed by /tf odom → base_link and a /tf_static mounting;
- ``pointcloud2_lidar_10hz``: simulated 16-beam LiDAR scans (10 Hz) with nav_msgs/Odometry.

``ros2``: frames published, handed on by the bridge, mapped, skipped (back-pressure) and
without a pose; rejected messages; the latency from a submap's last frame leaving the
publisher to the first MarkerArray at the DDS subscriber that shows the submap (median, max);
CPU seconds per mapped frame; bytes per frame on the topics; bytes per submap built (as
sent to the fleet) and per MarkerArray (as the bridge carries it to DDS). ``recorded``: the
same frames as a recording, its CPU per frame; ``cpu_vs_recorded`` their ratio.

    .venv/bin/python benchmarks/ros2.py [--seconds 10]   (needs make ros2)
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from live import cpu_seconds, node  # benchmarks/live.py: this script's folder is on the path
from ros1 import MOUNT, STRIDE, TUM, _image, lidar_frames, recorded_run, submap_bytes

from gmmap.eval.ros2dds.bridge import missing
from gmmap.fleet.net.transport import free_port
from gmmap.io.datasets import TumRgbd
from gmmap.io.datasets.tum import read_depth
from gmmap.io.ros2msgs import Camera, depth_points
from gmmap.mapping.frame import Frame
from gmmap.mapping.live import LiveInput
from gmmap.options import RosOptions

PUBLISH_EVERY_S = 0.2  # the node's outputs: often, so the latency is the pipeline's


def depth_frames(n: int) -> tuple[list, list, RosOptions]:
    """(stamp, pose, millimetre image) per frame, the recorded frames and the ROS settings."""
    data = TumRgbd(TUM)
    i = data.intrinsics
    camera = Camera(i.fx, i.fy, i.cx, i.cy)
    k = min(n, len(data))
    mm = [(read_depth(f).astype(np.float64) / 5).astype(np.uint16) for f in data.files[:k]]
    frames = [Frame(data.stamps[j], depth_points(_image(m), camera, STRIDE), data.poses[j])
              for j, m in enumerate(mm)]  # fmt: skip
    options = RosOptions(depth_topic="/camera/depth/image", depth_stride=STRIDE, tf_parent="odom")
    return list(zip(data.stamps[:k], data.poses[:k], mm, strict=True)), frames, options


def lidar_input(n: int) -> tuple[list, list, RosOptions]:
    frames = lidar_frames(n)
    return frames, frames, RosOptions(cloud_topic="/points", odom_topic="/odom")


INPUTS = {"depth_image_30hz": (depth_frames, 30.0), "pointcloud2_lidar_10hz": (lidar_input, 10.0)}


def publish(name: str, n: int, domain: int, go, sent) -> None:
    """The stand-in ROS 2 driver (a child process): waits for ``go``, then publishes input
    ``name`` at its rate; ``sent`` gets (stamp, monotonic time, bytes) per frame."""
    from gmmap.eval.ros2dds import graph
    from gmmap.eval.ros2dds import messages as m

    make, hz = INPUTS[name]
    source, _, _ = make(n)
    with graph.StandInNode("driver", domain) as driver:
        if name.startswith("depth"):
            info = TumRgbd(TUM).intrinsics
            k = [info.fx, 0.0, info.cx, 0.0, info.fy, info.cy, 0.0, 0.0, 1.0]
            static = driver.publisher("/tf_static", m.TFMessage, graph.TF_STATIC)
            static.write(graph.transforms([("base_link", "camera", MOUNT)], 0.0))
            images = driver.publisher("/camera/depth/image", m.Image, graph.SENSOR_DATA)
            infos = driver.publisher("/camera/depth/camera_info", m.CameraInfo, graph.SENSOR_DATA)
            tf = driver.publisher("/tf", m.TFMessage)
            writers = (images, infos, tf)
        else:
            clouds = driver.publisher("/points", m.PointCloud2, graph.SENSOR_DATA)
            odom = driver.publisher("/odom", m.Odometry)
            writers = (clouds, odom)
        if not all(graph.matched(w, 30) for w in writers):
            raise RuntimeError("the bridge made no route")
        go.wait()
        start = time.monotonic()
        for i, item in enumerate(source):
            time.sleep(max(0.0, start + i / hz - time.monotonic()))
            if name.startswith("depth"):
                stamp, pose, mm = item
                header = m.Header(graph.stamp(stamp), "camera")
                h, w = mm.shape
                image = m.Image(header, h, w, "16UC1", 0, 2 * w, mm.astype("<u2").tobytes())
                camera = m.CameraInfo(header, h, w, "plumb_bob", [0.0] * 5, k)
                tf.write(
                    graph.transforms([("odom", "base_link", pose @ np.linalg.inv(MOUNT))], stamp)
                )
                infos.write(camera)
                images.write(image)
                size = len(image.serialize()) + len(camera.serialize())
            else:
                stamp = item.stamp
                odom.write(graph.odometry(item.pose, stamp))
                cloud = graph.point_cloud(item.points, "lidar", stamp)
                clouds.write(cloud)
                size = len(cloud.serialize())
            sent.put((float(stamp), time.monotonic(), size))
        # The last pose a little after the last frame, for its interpolation.
        if name.startswith("depth"):
            tf.write(
                graph.transforms([("odom", "base_link", pose @ np.linalg.inv(MOUNT))], stamp + 0.02)
            )
        else:
            odom.write(graph.odometry(item.pose, stamp + 0.05))
        sent.put(None)
        time.sleep(1.0)


def ros2_run(tmp: Path, name: str, n: int, options: RosOptions) -> dict:
    from gmmap.eval.ros2dds import graph
    from gmmap.eval.ros2dds import messages as m
    from gmmap.eval.ros2dds.bridge import RosDdsBridge
    from gmmap.io.ros2bridge import Ros2Bridge

    domain, port = 150 + os.getpid() % 80, free_port()
    ctx = multiprocessing.get_context("spawn")
    go, sent = ctx.Event(), ctx.Queue()
    maps: list[tuple[float, int, int]] = []  # (arrival, markers shown, bytes)
    built: list[tuple[float, float]] = []  # (last frame's stamp, built at)
    with RosDdsBridge(domain, f"tcp/127.0.0.1:{port}"), graph.StandInNode("rviz", domain) as rviz:

        def on_map(msg) -> None:
            shown = sum(k.action == 0 for k in msg.markers)
            maps.append((time.monotonic(), shown, len(msg.serialize())))

        rviz.subscription("/gmmap/map", m.MarkerArray, callback=on_map)
        options = replace(options, key_format="bridge", connect=(f"tcp/127.0.0.1:{port}",),
                          publish_every_s=PUBLISH_EVERY_S)  # fmt: skip
        robot = node(tmp, "ros2")
        live = LiveInput(max_pending=8)
        bridge = Ros2Bridge("ros2", options, live)
        robot.on_built = lambda b: built.append((float(b.submap.stamps[-1]), time.monotonic()))
        robot.start()
        builder = robot.start_frames(live)
        bridge.attach(robot)
        driver = ctx.Process(target=publish, args=(name, n, domain, go, sent))
        driver.start()
        time.sleep(2.0)  # the driver's routes reach the node's session
        cpu, wall = cpu_seconds(), time.monotonic()
        go.set()
        frames = []
        while (item := sent.get(timeout=600)) is not None:
            frames.append(item)
        driver.join(timeout=60)
        time.sleep(1.5)  # the last frames' poses and fitting
        live.close()
        builder.join()
        wall, cpu = time.monotonic() - wall, cpu_seconds() - cpu
        time.sleep(3 * PUBLISH_EVERY_S)
        bridge.close()
    out = counts(live, bridge, robot, cpu, wall)
    robot.stop()
    out.update(latencies(frames, built, maps, robot))
    out["published"] = len(frames)
    out["input_bytes_per_frame"] = float(np.mean([s for _, _, s in frames])) if frames else None
    out["markerarray_bytes"] = maps[-1][2] if maps else None
    return out


def counts(live, bridge, robot, cpu: float, wall: float) -> dict:
    c = live.counts
    return {
        "frames": c.frames, "mapped": c.mapped, "skipped": c.skipped, "no_pose": c.no_pose,
        "bad_messages": bridge.counts["bad"], "submaps": robot.counts["built"],
        "cpu_s_per_mapped_frame": cpu / max(1, c.mapped), "wall_s": wall,
        "bytes_per_submap": submap_bytes(robot) / max(1, robot.counts["built"]),
    }  # fmt: skip


def latencies(frames: list, built: list, maps: list, robot) -> dict:
    """Per submap the live input closed: its last frame's send time → the first MarkerArray
    after its build. The one the end of input closed is not timed."""
    sent_at = {round(s, 6): t for s, t, _ in frames}
    out = []
    for stamp, at in built[:-1]:
        shown = next((t for t, _, _ in maps if t >= at), None)
        if shown is not None and round(stamp, 6) in sent_at:
            out.append(shown - sent_at[round(stamp, 6)])
    return {
        "timed_submaps": len(out),
        "latency_median_s": float(np.median(out)) if out else None,
        "latency_max_s": float(np.max(out)) if out else None,
    }


def one(name: str, seconds: float) -> dict:
    make, hz = INPUTS[name]
    n = int(seconds * hz)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _, frames, options = make(n)
        print(f"{name}: recorded", file=sys.stderr, flush=True)
        recorded = recorded_run(tmp, frames)
        print(f"{name}: ROS 2 through the bridge", file=sys.stderr, flush=True)
        ros = ros2_run(tmp, name, n, options)
    ros["sensor_hz"] = hz
    ros["keeps_up"] = ros["mapped"] == ros["published"] and ros["skipped"] == 0
    ros["cpu_vs_recorded"] = ros["cpu_s_per_mapped_frame"] / recorded["cpu_s_per_frame"]
    return {"ros2": ros, "recorded": recorded}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="Sensor time per input.")
    args = parser.parse_args()
    if missing() is not None:  # make bench runs everywhere; this one says why it did not
        print(json.dumps({"skipped": missing()}))
        return
    out: dict = {"seconds": args.seconds}
    for name in INPUTS:
        out[name] = one(name, args.seconds)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
