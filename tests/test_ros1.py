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

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from conftest import wait
from gmmap.fleet.transport import free_port
from gmmap.io import ros1bridge
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.io.datasets.tum import read_depth
from gmmap.math.geometry import make_poses, matrix_to_quaternion

pytestmark = pytest.mark.skipif(
    not (ros1bridge.available() and shutil.which("roscore") and shutil.which("rosbag")),
    reason=f"ROS 1 is not installed: {ros1bridge.SETUP}",
)
TS = get_typestore(Stores.ROS1_NOETIC)
# rosbags' Noetic store lacks tf2_msgs; its definition is one line
TS.register(
    get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
)
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


def write_bag(path, robots: dict[str, list]):
    """A ROS 1 bag of each robot's clouds and odometry, under ``/<robot>`` ("": no prefix)."""
    with Writer(path) as bag:
        for prefix, frames in robots.items():
            c = bag.add_connection(f"{prefix}/camera/depth/points", "sensor_msgs/msg/PointCloud2",
                                   typestore=TS)  # fmt: skip
            o = bag.add_connection(f"{prefix}/odom", "nav_msgs/msg/Odometry", typestore=TS)
            for f in frames:
                t = round(f.stamp * 1e9)
                bag.write(o, t - 1000, TS.serialize_ros1(odometry(f), "nav_msgs/msg/Odometry"))
                bag.write(c, t, TS.serialize_ros1(cloud(f), "sensor_msgs/msg/PointCloud2"))
    return path


def transform(stamp: float, parent: str, child: str, pose: np.ndarray):
    q = T["geometry_msgs/msg/Quaternion"](*matrix_to_quaternion(pose[None, :3, :3])[0])
    r = T["geometry_msgs/msg/Transform"](T["geometry_msgs/msg/Vector3"](*pose[:3, 3]), q)
    stamped = T["geometry_msgs/msg/TransformStamped"](header(stamp, parent), child, r)
    return T["tf2_msgs/msg/TFMessage"]([stamped])


def write_depth_bag(path, data: TumRgbd, frames: range, mount: np.ndarray):
    """A ROS 1 bag of depth images (16UC1 mm) with their CameraInfo, odom → base_link on /tf
    and the camera's mounting base_link → camera on /tf_static."""
    k = data.intrinsics
    roi = T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
    K = np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], float)
    P = np.array([k.fx, 0, k.cx, 0, 0, k.fy, k.cy, 0, 0, 0, 1, 0], float)
    with Writer(path) as bag:
        add = lambda topic, kind: bag.add_connection(topic, kind, typestore=TS)  # noqa: E731
        depth, info = (
            add("/camera/depth/image", "sensor_msgs/msg/Image"),
            add("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo"),
        )
        tf, static = (
            add("/tf", "tf2_msgs/msg/TFMessage"),
            add("/tf_static", "tf2_msgs/msg/TFMessage"),
        )
        put = lambda c, t, m: bag.write(c, t, TS.serialize_ros1(m, m.__msgtype__))  # noqa: E731
        t0 = round(data.stamps[frames[0]] * 1e9)
        put(static, t0 - 10**6, transform(0.0, "base_link", "camera", mount))
        for i in frames:
            stamp, t = data.stamps[i], round(data.stamps[i] * 1e9)
            base = data.poses[i] @ np.linalg.inv(mount)
            put(tf, t - 2000, transform(stamp, "odom", "base_link", base))
            mm = (read_depth(data.files[i]).astype(np.float64) / 5).astype("<u2")  # TUM: 5000/m
            h, w = mm.shape
            put(info, t - 1000, T["sensor_msgs/msg/CameraInfo"](header(stamp, "camera"), h, w,
                "plumb_bob", np.zeros(5), K, np.eye(3).ravel(), P, 0, 0, roi))  # fmt: skip
            image = np.frombuffer(mm.tobytes(), np.uint8)
            put(depth, t, T["sensor_msgs/msg/Image"](header(stamp, "camera"), h, w, "16UC1",
                                                     0, 2 * w, image))  # fmt: skip
    return path


@pytest.fixture(scope="module")
def roscore(tmp_path_factory):
    """One master for the module: rospy lets a process be one node, once."""
    tmp_path = tmp_path_factory.mktemp("ros")
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


def subscribed(topics) -> bool:
    """Whether the ROS master has a subscriber to each of ``topics``."""
    state = __import__("rosgraph").Master("/gmmap_test").getSystemState()[1]
    return set(topics) <= {t for t, _ in state}


def test_the_ros1_node_maps_a_played_bag_and_publishes_map_tf_and_status(tmp_path, roscore):
    rospy = ros1bridge.rospy()
    from std_msgs.msg import String
    from visualization_msgs.msg import MarkerArray

    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:8]
    bag = write_bag(tmp_path / "tum.bag", {"": frames})
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
        subprocess.run(["rosbag", "play", "-q", str(bag)], env=roscore, check=True, timeout=60)
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
    bag = write_bag(tmp_path / "two.bag", {"/a": frames[0:4], "/b": frames[4:8]})
    ports = {"a": free_port(), "b": free_port()}
    nodes = []
    for name, other in (("a", "b"), ("b", "a")):
        config = tmp_path / f"{name}.yaml"
        config.write_text(
            f"ros: {{cloud_topic: /{name}/camera/depth/points, odom_topic: /{name}/odom,"
            f" map_topic: /{name}/gmmap/map, points_topic: /{name}/gmmap/map_points,"
            f" status_topic: /{name}/gmmap/status, publish_every_s: 0.5}}\n"
            "build: {frames_per_submap: 2, n_components: 60, covariance: full}\n"
            "backend: {min_matches: 1}\n"
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
        subprocess.run(["rosbag", "play", "-q", str(bag)], env=roscore, check=True, timeout=60)
        assert wait(lambda: ("a/map", "b/map") in edges, 60), edges
        time.sleep(1.5)  # both nodes have published their tree by now
        assert set(edges) == {("a/map", "b/map")}  # one tree: the reference's map above b's
        t = edges[("a/map", "b/map")]
        assert np.linalg.norm([t.x, t.y, t.z]) < 0.05  # one mocap frame: the identity
    finally:
        sub.unregister()
        for node in nodes:
            node.send_signal(signal.SIGINT)
        outs = [node.communicate(timeout=60) for node in nodes]
    assert [n.returncode for n in nodes] == [0, 0], [err[-1500:] for _, err in outs]
    for name in ("a", "b"):
        r = json.loads((tmp_path / f"{name}.json").read_text())
        assert r["held"] == {"a": 2, "b": 2} and r["groups"] == [["a", "b"]]


def test_the_ros1_node_maps_depth_images_posed_by_a_tf_chain(tmp_path, roscore):
    """Depth images with their CameraInfo; poses from /tf odom → base_link composed with the
    camera's mounting on /tf_static (the chain's lower end: the images' frame)."""
    rospy = ros1bridge.rospy()
    from std_msgs.msg import String

    data = TumRgbd(BUNDLED_TUM_SLICE)
    mount = make_poses(np.array([[0.1, 0.0, 0.3]]), np.array([[0.0, 0.0, 0.7071068, 0.7071068]]))[0]
    bag = write_depth_bag(tmp_path / "depth.bag", data, range(8), mount)
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
        subprocess.run(["rosbag", "play", "-q", str(bag)], env=roscore, check=True, timeout=60)
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
