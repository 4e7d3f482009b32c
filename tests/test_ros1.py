"""The ROS 1 node (`gmmap robot --ros1`, `gmmap.io.ros1bridge`) against the real thing: Debian's
roscore, ``rosbag play`` of a bag written from the bundled TUM recording, and a rospy
subscriber receiving the node's map, TF and status. Skipped where ROS 1 is not installed
(``make ros1``)."""

import json
import os
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from conftest import wait
from gmmap.fleet.transport import free_port
from gmmap.io import ros1bridge
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.math.geometry import matrix_to_quaternion

pytestmark = pytest.mark.skipif(
    not (ros1bridge.available() and shutil.which("roscore") and shutil.which("rosbag")),
    reason=f"ROS 1 is not installed: {ros1bridge.SETUP}",
)
TS = get_typestore(Stores.ROS1_NOETIC)
T = TS.types


def header(stamp: float, frame: str):
    sec = int(stamp)
    return T["std_msgs/msg/Header"](
        0, T["builtin_interfaces/msg/Time"](sec, int((stamp - sec) * 1e9)), frame
    )


def cloud(f):
    pts = np.ascontiguousarray(f.points, dtype="<f4")
    fields = [T["sensor_msgs/msg/PointField"](a, 4 * i, 7, 1) for i, a in enumerate("xyz")]
    data = np.frombuffer(pts.tobytes(), np.uint8)
    return T["sensor_msgs/msg/PointCloud2"](
        header(f.stamp, "camera"), 1, len(pts), fields, False, 12, 12 * len(pts), data, True
    )


def odometry(f):
    q = T["geometry_msgs/msg/Quaternion"](*matrix_to_quaternion(f.pose[None, :3, :3])[0])
    pose = T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](*f.pose[:3, 3]), q)
    vec = T["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        T["geometry_msgs/msg/Twist"](vec, vec), np.zeros(36)
    )
    return T["nav_msgs/msg/Odometry"](header(f.stamp, "odom"), "camera",
                                      T["geometry_msgs/msg/PoseWithCovariance"](pose, np.zeros(36)),
                                      twist)  # fmt: skip


def write_bag(path, frames):
    with Writer(path) as bag:
        c = bag.add_connection("/camera/depth/points", "sensor_msgs/msg/PointCloud2", typestore=TS)
        o = bag.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=TS)
        for f in frames:
            t = round(f.stamp * 1e9)
            bag.write(o, t - 1000, TS.serialize_ros1(odometry(f), "nav_msgs/msg/Odometry"))
            bag.write(c, t, TS.serialize_ros1(cloud(f), "sensor_msgs/msg/PointCloud2"))
    return path


@pytest.fixture
def roscore(tmp_path):
    port = free_port()
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}", "ROS_HOME": str(tmp_path)}
    proc = subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)  # fmt: skip
    rosgraph = pytest.importorskip("rosgraph")
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_HOME=str(tmp_path))
    master = rosgraph.Master("/gmmap_test")

    def up() -> bool:
        try:
            master.getPid()
        except Exception:
            return False
        return True

    assert wait(up, 20), "roscore did not start"
    yield env
    os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=20)


def test_the_ros1_node_maps_a_played_bag_and_publishes_map_tf_and_status(tmp_path, roscore):
    rospy = ros1bridge.rospy()
    from std_msgs.msg import String
    from visualization_msgs.msg import MarkerArray

    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:8]
    bag = write_bag(tmp_path / "tum.bag", frames)
    config = tmp_path / "robot.yaml"
    config.write_text(
        "ros: {cloud_topic: /camera/depth/points, odom_topic: /odom, publish_every_s: 0.5}\n"
        "build: {frames_per_submap: 2, n_components: 60, covariance: full}\n"
    )
    report = tmp_path / "a.json"
    node = subprocess.Popen(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "robot", "--id", "a",
         "--fleet", "f", "--ros1", "--config", str(config), "--linger", "0.5",
         "--report", str(report)],
        env=roscore, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    heard: dict = {}
    rospy.init_node("gmmap_test_listener", anonymous=True, disable_signals=True)
    rospy.Subscriber("/gmmap/status", String, lambda m: heard.__setitem__("status", m.data))
    rospy.Subscriber("/gmmap/map", MarkerArray, lambda m: heard.__setitem__("map", m))
    try:
        master = __import__("rosgraph").Master("/gmmap_test")
        subscribed = lambda: any(  # noqa: E731
            t == "/camera/depth/points" for t, _ in master.getSystemState()[1]
        )
        assert wait(subscribed, 30), "the gmmap node did not subscribe"
        subprocess.run(["rosbag", "play", "-q", str(bag)], env=roscore, check=True, timeout=60)
        mapped = lambda: "status" in heard and json.loads(heard["status"])["live"]["mapped"] == 8  # noqa: E731
        assert wait(mapped, 60), heard.get("status")
        assert wait(lambda: "map" in heard and len(heard["map"].markers) > 0, 30)
        assert {m.ns for m in heard["map"].markers} == {"a"}
    finally:
        rospy.signal_shutdown("the test is done")
        node.send_signal(signal.SIGINT)
        _, err = node.communicate(timeout=60)
    assert node.returncode == 0, err[-2000:]
    r = json.loads(report.read_text())
    assert r["submaps_built"] == 4 and r["interrupted"]
