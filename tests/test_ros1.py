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
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import assert_two_robots_joined, stop_robots, wait
from gmmap.fleet.net.keys import listen_port
from gmmap.io import ros1bridge
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.io.datasets.tum import read_depth
from gmmap.io.ros1bag import write_cloud_bag, write_depth_bag
from gmmap.math.geometry import make_poses

pytestmark = pytest.mark.skipif(
    not (ros1bridge.available() and shutil.which("roscore") and shutil.which("rosbag")),
    reason=f"ROS 1 is not installed: {ros1bridge.SETUP}",
)


@pytest.fixture(scope="module")
def roscore(tmp_path_factory):
    """One master for the module: rospy lets a process be one node, once."""
    tmp_path = tmp_path_factory.mktemp("ros")
    port = listen_port()
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
    ros1bridge.rospy().init_node("gmmap_test_listener", anonymous=True, disable_signals=True)
    yield env
    ros1bridge.rospy().signal_shutdown("the tests are done")
    os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=20)


def robot(name: str, config, report, roscore, *extra) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", "from gmmap.cli import main; main()", "robot", "--id", name,
         "--fleet", "f", "--ros1", "--config", str(config), "--linger", "0.5",
         "--report", str(report), *extra],
        env=roscore, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def play(bag: Path, env: dict, wait: bool = False) -> None:
    """``rosbag play``, a second after advertising for the node's subscribers to connect to
    every topic; with ``wait``, only once every topic has a subscriber connected: an image
    that came before its CameraInfo connection was up is dropped (a second was not always
    enough on a loaded CI machine)."""
    args = ["rosbag", "play", "-q", "-d", "1", *(["--wait-for-subscribers"] if wait else [])]
    subprocess.run([*args, str(bag)], env=env, check=True, timeout=60)


def subscribed(topics) -> bool:
    """Whether the ROS master has a subscriber to each of ``topics``."""
    state = __import__("rosgraph").Master("/gmmap_test").getSystemState()[1]
    return set(topics) <= {t for t, _ in state}


def test_the_ros1_node_maps_a_played_bag_and_publishes_map_tf_and_status(tmp_path, roscore):
    rospy = ros1bridge.rospy()
    from std_msgs.msg import String
    from visualization_msgs.msg import MarkerArray

    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:8]
    bag = write_cloud_bag(tmp_path / "tum.bag", {"": frames})
    config = tmp_path / "robot.yaml"
    config.write_text(
        "ros: {cloud_topic: /camera/depth/points, odom_topic: /odom, publish_every_s: 0.5}\n"
        "build: {frames_per_submap: 2, n_components: 60, covariance: full}\n"
    )
    report = tmp_path / "a.json"
    node = robot("a", config, report, roscore)
    heard: dict = {}
    subs = [
        rospy.Subscriber("/gmmap/status", String, lambda m: heard.__setitem__("status", m.data)),
        rospy.Subscriber("/gmmap/map", MarkerArray, lambda m: heard.__setitem__("map", m)),
    ]
    try:
        assert wait(lambda: subscribed(["/camera/depth/points"]), 30), "the node did not subscribe"
        play(bag, roscore)
        mapped = lambda: "status" in heard and json.loads(heard["status"])["live"]["mapped"] == 8  # noqa: E731
        assert wait(mapped, 60), heard.get("status")
        assert wait(lambda: "map" in heard and len(heard["map"].markers) > 0, 30)
        assert {m.ns for m in heard["map"].markers} == {"a"}
    finally:
        for sub in subs:
            sub.unregister()
        node.send_signal(signal.SIGINT)
        _, err = node.communicate(timeout=60)
    assert node.returncode == 0, err[-2000:]
    r = json.loads(report.read_text())
    assert r["submaps_built"] == 4 and r["interrupted"]


def test_two_ros1_nodes_of_one_fleet_share_submaps_and_publish_one_tf_tree(tmp_path, roscore):
    """The bundled frames split in two robots (0-3 and 4-7: one desk, one mocap frame), each
    a ROS 1 node on its own topics; their fleet link is Zenoh."""
    rospy = ros1bridge.rospy()
    from tf2_msgs.msg import TFMessage

    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:8]
    bag = write_cloud_bag(tmp_path / "two.bag", {"/a": frames[0:4], "/b": frames[4:8]})
    ports = {"a": listen_port(), "b": listen_port()}
    nodes = []
    for name, other in (("a", "b"), ("b", "a")):
        config = tmp_path / f"{name}.yaml"
        config.write_text(
            f"ros: {{cloud_topic: /{name}/camera/depth/points, odom_topic: /{name}/odom,"
            f" map_topic: /{name}/gmmap/map, points_topic: /{name}/gmmap/map_points,"
            f" status_topic: /{name}/gmmap/status, publish_every_s: 0.5}}\n"
            "build: {frames_per_submap: 2, n_components: 60, covariance: full}\n"
            "backend: {min_matches: 1}\n"
            # Each submap at once: both robots stop as soon as the first tree is published.
            "robot: {bundle: 1}\n"
        )
        peer = ("--peer", f"tcp/127.0.0.1:{ports[other]}", "--port", str(ports[name]))
        nodes.append(robot(name, config, tmp_path / f"{name}.json", roscore, *peer))
    edges: dict = {}

    def on_tf(msg) -> None:
        for t in msg.transforms:
            edges[(t.header.frame_id, t.child_frame_id)] = t.transform.translation

    sub = rospy.Subscriber("/tf", TFMessage, on_tf)
    try:
        topics = ["/a/camera/depth/points", "/b/camera/depth/points"]
        assert wait(lambda: subscribed(topics), 30), "the nodes did not subscribe"
        play(bag, roscore)
        assert wait(lambda: ("a/map", "b/map") in edges, 60), edges
        time.sleep(1.5)  # both nodes have published their tree by now
        assert set(edges) == {("a/map", "b/map")}  # one tree: the reference's map above b's
        t = edges[("a/map", "b/map")]
        assert np.linalg.norm([t.x, t.y, t.z]) < 0.05  # one mocap frame: the identity
    finally:
        sub.unregister()
        outs = stop_robots(nodes)
    assert_two_robots_joined(nodes, outs, tmp_path)


def test_the_ros1_node_maps_depth_images_posed_by_a_tf_chain(tmp_path, roscore):
    """Depth images with their CameraInfo; poses from /tf odom → base_link composed with the
    camera's mounting on /tf_static (the chain's lower end: the images' frame)."""
    rospy = ros1bridge.rospy()
    from std_msgs.msg import String

    data = TumRgbd(BUNDLED_TUM_SLICE)
    mount = make_poses(np.array([[0.1, 0.0, 0.3]]), np.array([[0.0, 0.0, 0.7071068, 0.7071068]]))[0]
    mm = [(read_depth(f).astype(np.float64) / 5).astype(np.uint16) for f in data.files[:8]]  # TUM
    bag = write_depth_bag(
        tmp_path / "depth.bag",
        zip(data.stamps[:8], data.poses[:8], mm, strict=True),
        data.intrinsics,
        mount,
    )
    config = tmp_path / "robot.yaml"
    config.write_text(
        "ros: {depth_topic: /camera/depth/image, depth_stride: 2, tf_parent: odom,"
        " publish_every_s: 0.5}\n"
        "build: {frames_per_submap: 2, n_components: 60, covariance: full}\n"
    )
    report = tmp_path / "d.json"
    node = robot("d", config, report, roscore)
    heard: dict = {}
    sub = rospy.Subscriber("/gmmap/status", String, lambda m: heard.__setitem__("s", m.data))
    try:
        assert wait(lambda: subscribed(["/camera/depth/image", "/tf_static"]), 30)
        play(bag, roscore, wait=True)
        mapped = lambda: "s" in heard and json.loads(heard["s"])["live"]["mapped"] == 8  # noqa: E731
        assert wait(mapped, 60), heard.get("s")
    finally:
        sub.unregister()
        node.send_signal(signal.SIGINT)
        _, err = node.communicate(timeout=60)
    assert node.returncode == 0, err[-2000:]
    status = json.loads(heard["s"])
    assert status["live"]["no_pose"] == 0 and status["ros"]["bad"] == 0
    r = json.loads(report.read_text())
    assert r["submaps_built"] == 4
    # Each submap's anchor sits at its first frame's camera: the chain's, mount included.
    for key, pose in r["poses"].items():
        first = data.poses[2 * int(key.split("/")[1])]
        assert np.linalg.norm(first[:3, 3] - np.asarray(pose)[:3, 3]) < 1e-4, key
