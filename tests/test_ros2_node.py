"""A robot node fed by ROS 2 topics over Zenoh (`gmmap.io.ros2bridge`), in both key formats:
messages serialised by rosbags in, the node's outputs decoded back by rosbags. Tested against
the wire formats on this machine, not against a running ROS 2 graph."""

import json
import time
from types import SimpleNamespace

import numpy as np
import pytest
import zenoh

from conftest import wait
from gmmap.config import Config
from gmmap.fleet.net.keys import listen_port
from gmmap.fleet.node.robot import RobotNode
from gmmap.io import ros2
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.io.ros2bridge import Ros2Bridge, tf_tree
from gmmap.math.geometry import matrix_to_quaternion
from gmmap.options import BuildOptions, RobotOptions, RosOptions

T = ros2.typestore("jazzy").types
BLOCK = zenoh.CongestionControl.BLOCK  # a test's burst must not be dropped at the sender


def odometry(stamp: float, pose: np.ndarray) -> bytes:
    """A nav_msgs/Odometry, serialised by rosbags."""
    sec = int(stamp)
    header = T["std_msgs/msg/Header"](
        T["builtin_interfaces/msg/Time"](sec, int((stamp - sec) * 1e9)), "odom"
    )
    q = T["geometry_msgs/msg/Quaternion"](*matrix_to_quaternion(pose[None, :3, :3])[0])
    p = T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](*pose[:3, 3]), q)
    vec = T["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        T["geometry_msgs/msg/Twist"](vec, vec), np.zeros(36)
    )
    msg = T["nav_msgs/msg/Odometry"](
        header, "base_link", T["geometry_msgs/msg/PoseWithCovariance"](p, np.zeros(36)), twist
    )
    return bytes(ros2.typestore("jazzy").serialize_cdr(msg, ros2.ODOMETRY))


def graph(port: int) -> zenoh.Session:
    """The ROS 2 side: a session listening where rmw_zenoh's router would."""
    config = zenoh.Config()
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def subscribed(ros: zenoh.Session, *keys: str) -> None:
    """Waits until the bridge's subscriptions to ``keys`` have reached the graph's session:
    a put before that would go nowhere."""
    probes = [ros.declare_publisher(k) for k in keys]
    assert wait(lambda: all(p.matching_status.matching for p in probes), 10)
    for p in probes:
        p.undeclare()


def key(fmt: str, topic: str, typename: str) -> str:
    if fmt == "bridge":
        return ros2.bridge_key(topic)
    return ros2.rmw_zenoh_key(topic, typename)


@pytest.mark.parametrize("fmt", ["rmw_zenoh", "bridge"])
def test_a_node_maps_ros2_topics_and_publishes_its_map_and_status(tmp_path, fmt):
    port = listen_port()
    outputs: dict[str, bytes] = {}
    attachments: dict[str, bytes | None] = {}

    def heard(s: zenoh.Sample) -> None:
        outputs[str(s.key_expr)] = s.payload.to_bytes()
        attachments[str(s.key_expr)] = None if s.attachment is None else s.attachment.to_bytes()

    with graph(port) as ros:
        ros.declare_subscriber("**", heard)
        config = Config(
            robot=RobotOptions(name="a", fleet="f", store=str(tmp_path / "a.db")),
            build=BuildOptions(frames_per_submap=2, covariance="full", n_components=60),
        )
        options = RosOptions(key_format=fmt, connect=(f"tcp/127.0.0.1:{port}",),
                             publish_every_s=0.3)  # fmt: skip
        node = RobotNode(config)
        bridge = Ros2Bridge("a", options)
        try:
            node.start()
            builder = node.start_frames(bridge.live)
            bridge.attach(node)
            subscribed(ros, key(fmt, "/points", ros2.POINTCLOUD2), key(fmt, "/odom", ros2.ODOMETRY))
            for f in TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:4]:
                cloud = ros2.encode_pointcloud2(f.points, "camera", f.stamp)
                ros.put(key(fmt, "/points", ros2.POINTCLOUD2), cloud, congestion_control=BLOCK)
                ros.put(
                    key(fmt, "/odom", ros2.ODOMETRY),
                    odometry(f.stamp, f.pose),
                    congestion_control=BLOCK,
                )
            ros.put(key(fmt, "/points", ros2.POINTCLOUD2), b"not cdr", congestion_control=BLOCK)
            assert wait(lambda: node.store.seqs("a") == [0, 1], 30)
            assert bridge.counts["clouds"] == 4 and bridge.counts["bad"] == 1
            map_key = key(fmt, "/gmmap/map", ros2.MARKER_ARRAY)

            def shown() -> list:  # the ellipsoids the last MarkerArray adds
                if map_key not in outputs:
                    return []
                sent = ros2.typestore("jazzy").deserialize_cdr(outputs[map_key], ros2.MARKER_ARRAY)
                return [m for m in sent.markers if m.action == 0]

            def drawn() -> bool:  # the map is built once the node has optimised its graph
                built = node.global_map()
                return built is not None and len(shown()) == len(built.gmm) > 0

            assert wait(drawn, 15)
            assert {m.ns for m in shown()} == {"a"}
            status_key = key(fmt, "/gmmap/status", ros2.STRING)

            def status() -> dict:  # the latest one heard
                if status_key not in outputs:
                    return {"live": {}}
                data = ros2.typestore("jazzy").deserialize_cdr(outputs[status_key], ros2.STRING)
                return json.loads(data.data)

            assert wait(lambda: status()["live"].get("mapped") == 4, 10)
            assert status()["robot"] == "a"
            if fmt == "rmw_zenoh":  # the type hash in the key, rmw_zenoh's attachment beside
                assert map_key.endswith(ros2.type_hash(ros2.MARKER_ARRAY, "jazzy"))
                assert ros2.parse_attachment(attachments[status_key]).sequence_number > 0
            else:
                assert attachments[status_key] is None
        finally:
            bridge.close()
            builder.join(timeout=10)
            node.stop()


def test_thetf_tree_hangs_every_robots_map_under_its_groups_reference():
    T_ab = np.eye(4)
    T_ab[0, 3] = 2.0
    frames = SimpleNamespace(
        robots=["a", "b", "c"],
        reference=lambda r: "a" if r in "ab" else "c",
        to_reference=lambda r: T_ab if r == "b" else np.eye(4),
    )
    node = SimpleNamespace(mapper=SimpleNamespace(result=object(), frames=frames))
    tree = tf_tree(node, 5.0)
    assert [(p, c) for p, c, _, _ in tree] == [("a/map", "b/map")]  # c is alone: no edge
    decoded = ros2.decode_tf(ros2.encode_tf(tree))
    assert decoded[0].parent == "a/map" and np.allclose(decoded[0].pose, T_ab)


def test_depth_images_with_their_camera_info_become_frames():
    port = listen_port()
    ts = ros2.typestore("jazzy")
    header = T["std_msgs/msg/Header"](T["builtin_interfaces/msg/Time"](10, 0), "camera")
    depth = np.full((6, 8), 2000, np.uint16)  # a wall 2 m ahead, in millimetres
    image = T["sensor_msgs/msg/Image"](header, 6, 8, "16UC1", False, 16,
                                       np.frombuffer(depth.tobytes(), np.uint8))  # fmt: skip
    roi = T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
    k = np.array([4.0, 0, 4.0, 0, 4.0, 3.0, 0, 0, 1])
    info = T["sensor_msgs/msg/CameraInfo"](header, 6, 8, "plumb_bob", np.zeros(5), k,
                                           np.eye(3).ravel(), np.zeros(12), 0, 0, roi)  # fmt: skip
    options = RosOptions(connect=(f"tcp/127.0.0.1:{port}",), depth_topic="/camera/depth",
                         depth_stride=2)  # fmt: skip
    with graph(port) as ros:
        bridge = Ros2Bridge("a", options)
        try:
            image_key = ros2.rmw_zenoh_key("/camera/depth", ros2.IMAGE)
            info_key = ros2.rmw_zenoh_key("/camera/camera_info", ros2.CAMERA_INFO)
            subscribed(ros, image_key, info_key, ros2.rmw_zenoh_key("/odom", ros2.ODOMETRY))
            first = bytes(ts.serialize_cdr(image, ros2.IMAGE))
            ros.put(image_key, first, congestion_control=BLOCK)  # no intrinsics yet
            # Zenoh orders samples per key, not across keys: let it be refused before the info.
            assert wait(lambda: bridge.counts["bad"] == 1, 10)
            ros.put(
                info_key, bytes(ts.serialize_cdr(info, ros2.CAMERA_INFO)), congestion_control=BLOCK
            )
            assert wait(lambda: bridge._camera is not None, 10)  # callbacks run on many threads
            ros.put(image_key, bytes(ts.serialize_cdr(image, ros2.IMAGE)), congestion_control=BLOCK)
            ros.put(
                ros2.rmw_zenoh_key("/odom", ros2.ODOMETRY),
                odometry(9.0, np.eye(4)),
                congestion_control=BLOCK,
            )
            ros.put(
                ros2.rmw_zenoh_key("/odom", ros2.ODOMETRY),
                odometry(11.0, np.eye(4)),
                congestion_control=BLOCK,
            )
            assert wait(lambda: bridge.live.counts.frames == 1 and bridge.counts["poses"] == 2, 10)
            assert bridge.counts["bad"] == 1  # the image before its CameraInfo
            bridge.live.close()
            (frame,) = list(bridge.live)
            assert len(frame.points) == 12 and np.allclose(frame.points[:, 2], 2.0)
        finally:
            bridge.close()


def test_poses_from_one_tf_edge_down_to_the_clouds_frame():
    port = listen_port()
    options = RosOptions(connect=(f"tcp/127.0.0.1:{port}",), tf_parent="odom", key_format="bridge")
    moved = np.eye(4)
    moved[0, 3] = 1.0
    with graph(port) as ros:
        bridge = Ros2Bridge("a", options)
        try:
            subscribed(ros, ros2.bridge_key("/points"), ros2.bridge_key("/tf"))
            points = np.ones((5, 3), np.float32)
            ros.put(
                ros2.bridge_key("/points"),
                ros2.encode_pointcloud2(points, "camera", 1.5),
                congestion_control=BLOCK,
            )
            assert wait(lambda: bridge.counts["clouds"] == 1, 5)
            other = ros2.encode_tf([("odom", "base_link", moved, 1.0)])  # not the clouds' frame
            ros.put(ros2.bridge_key("/tf"), other, congestion_control=BLOCK)
            for stamp, pose in ((1.0, np.eye(4)), (2.0, moved)):
                ros.put(
                    ros2.bridge_key("/tf"),
                    ros2.encode_tf([("odom", "camera", pose, stamp)]),
                    congestion_control=BLOCK,
                )
            assert wait(lambda: bridge.counts["poses"] == 2, 5)
            bridge.live.close()
            frames = list(bridge.live)
            assert len(frames) == 1, (bridge.live.counts, bridge.live._stamps, bridge.counts)
            assert np.isclose(frames[0].pose[0, 3], 0.5)  # halfway between the two
        finally:
            bridge.close()


def test_rmw_zenoh_tools_see_the_node_its_subscriptions_and_publishers():
    """The node's liveliness tokens, as ``ros2 node list`` / ``ros2 topic list`` read them
    (rmw_zenoh's graph); none in the bridge format, and none once the bridge closes."""
    port = listen_port()
    with graph(port) as ros:
        options = RosOptions(connect=(f"tcp/127.0.0.1:{port}",), tf_parent="odom")
        bridge = Ros2Bridge("robot-1.a", options)

        def tokens() -> list:
            replies = ros.liveliness().get(f"{ros2.LIVELINESS_PREFIX}/0/**", timeout=2)
            return [ros2.parse_liveliness_token(str(r.ok.key_expr)) for r in replies if r.ok]

        try:
            assert wait(lambda: len(tokens()) == 8, 10), tokens()
            seen = tokens()
        finally:
            bridge.close()
        assert {t.node for t in seen} == {"gmmap_robot_1_a"}
        assert {t.zid for t in seen} == {str(bridge.session.info.zid())}
        assert sorted(t.entity_id for t in seen) == list(range(8))  # one counter, from 0
        node = [t for t in seen if t.kind == "NN"]
        assert [(t.node_id, t.entity_id) for t in node] == [(0, 0)]  # .../0/0/NN/...
        assert {t.node_id for t in seen} == {0} and {t.namespace for t in seen} == {"/"}
        assert not seen[0].zid.startswith("0")  # Zenoh's spelling: no leading zeros
        by_kind = {k: {(t.topic, t.typename) for t in seen if t.kind == k} for k in ("MS", "MP")}
        assert by_kind["MS"] == {("/points", ros2.POINTCLOUD2), ("/tf", ros2.TF_MESSAGE),
                                 ("/tf_static", ros2.TF_MESSAGE)}  # fmt: skip
        assert by_kind["MP"] == {("/gmmap/map", ros2.MARKER_ARRAY), ("/tf", ros2.TF_MESSAGE),
                                 ("/gmmap/map_points", ros2.POINTCLOUD2),
                                 ("/gmmap/status", ros2.STRING)}  # fmt: skip
        assert all(t.type_hash == ros2.type_hash(t.typename) for t in seen if t.topic)
        assert wait(lambda: tokens() == [], 10)
        plain = Ros2Bridge("b", RosOptions(connect=options.connect, key_format="bridge"))
        try:
            time.sleep(0.5)
            assert tokens() == []
        finally:
            plain.close()
