"""``gmmap robot --ros2`` against real DDS software: ROS 2 topics published by a stand-in node on
CycloneDDS (`gmmap.eval.ros2dds`), routed by zenoh-plugin-ros2dds (the bridge host that
``make ros2`` builds), mapped by a robot node in the bridge key format; its outputs routed back
and decoded with cyclonedds's IDL types, not rosbags. Skips, naming ``make ros2``, where the
bridge or the cyclonedds package is missing."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import assert_two_robots_joined, stop_robots, wait
from gmmap.config import Config
from gmmap.eval.ros2dds.bridge import missing
from gmmap.fleet.net.keys import listen_port
from gmmap.fleet.node.robot import RobotNode
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.io.ros2bridge import MAP_POINTS, Ros2Bridge
from gmmap.options import BuildOptions, RobotOptions, RosOptions

pytestmark = pytest.mark.skipif(missing() is not None, reason=str(missing()))

if missing() is None:
    from gmmap.eval.ros2dds import graph
    from gmmap.eval.ros2dds import messages as m
    from gmmap.eval.ros2dds.bridge import RosDdsBridge


def domain() -> int:
    """A DDS domain of this test run's own (ids 0-232 are valid)."""
    return 100 + os.getpid() % 100


def play(clouds, odom, frames) -> None:
    """``frames`` as a 10 Hz camera driver publishes them: each frame's odometry and cloud,
    then one more pose just after the last frame (its pose is interpolated)."""
    for f in frames:
        odom.write(graph.odometry(f.pose, f.stamp))
        clouds.write(graph.point_cloud(f.points, "camera", f.stamp))
        time.sleep(0.1)
    odom.write(graph.odometry(frames[-1].pose, frames[-1].stamp + 0.05))


def test_dds_topics_through_the_bridge_are_mapped_and_the_map_comes_back(tmp_path):
    port, dds = listen_port(), domain()
    heard: dict[str, list] = {"map": [], "status": [], "points": []}
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:4]
    with (
        RosDdsBridge(dds, f"tcp/127.0.0.1:{port}"),
        graph.StandInNode("camera_driver", dds) as sensor,
        graph.StandInNode("rviz", dds) as viewer,
    ):
        config = Config(
            robot=RobotOptions(name="a", fleet="f", store=str(tmp_path / "a.db")),
            build=BuildOptions(frames_per_submap=2, covariance="full", n_components=60),
        )
        options = RosOptions(
            key_format="bridge", connect=(f"tcp/127.0.0.1:{port}",), publish_every_s=0.3
        )
        node = RobotNode(config)
        bridge = Ros2Bridge("a", options)
        try:
            node.start()
            builder = node.start_frames(bridge.live)
            bridge.attach(node)
            viewer.subscription("/gmmap/map", m.MarkerArray, callback=heard["map"].append)
            viewer.subscription("/gmmap/status", m.String, callback=heard["status"].append)
            viewer.subscription("/gmmap/map_points", m.PointCloud2, callback=heard["points"].append)
            clouds = sensor.publisher("/points", m.PointCloud2, graph.SENSOR_DATA)
            odom = sensor.publisher("/odom", m.Odometry)
            assert graph.matched(clouds) and graph.matched(odom), "the bridge made no route"
            time.sleep(1.0)  # the route's Zenoh side reaches the node's session
            play(clouds, odom, frames)
            assert wait(lambda: node.store.seqs("a") == [0, 1], 30), bridge.counts

            def status() -> dict:
                return json.loads(heard["status"][-1].data) if heard["status"] else {"live": {}}

            assert wait(lambda: status()["live"].get("mapped") == len(frames), 15), status()
            assert bridge.counts["bad"] == 0

            def shown() -> list:  # the ellipsoids the last MarkerArray adds
                return (
                    [k for k in heard["map"][-1].markers if k.action == 0] if heard["map"] else []
                )

            def agrees() -> bool:  # one snapshot of each: the map changes while the node maps
                markers, built = shown(), node.global_map()
                if built is None:  # not optimised yet
                    return False
                gmm = built.gmm
                means = np.array([[k.pose.position.x, k.pose.position.y, k.pose.position.z]
                                  for k in markers]).reshape(-1, 3)  # fmt: skip
                return len(markers) == len(gmm) > 0 and np.allclose(
                    np.sort(means, axis=0), np.sort(gmm.means, axis=0), atol=1e-4
                )

            assert wait(agrees, 15)
            assert {k.ns for k in shown()} == {"a"}
            assert all(k.type == 2 and k.scale.x > 0 for k in shown())  # SPHERE, scaled
            cloud = heard["points"][-1]  # the merged map sampled, in the reference's frame
            assert cloud.width == MAP_POINTS and cloud.header.frame_id == "a/map"
            assert [f.name for f in cloud.fields][:3] == ["x", "y", "z"]
        finally:
            bridge.close()
            builder.join(timeout=10)
            node.stop()


def test_a_mounting_sent_before_the_node_started_reaches_it_from_the_bridges_cache():
    """/tf_static is transient local (rmw_cyclonedds's QoS for it): the publisher's DDS writer
    keeps its samples for a route the bridge opens later, and the bridge's publication cache
    for a subscriber that comes after that; so clouds in the camera frame are posed with a
    mounting published before the node started."""
    port, dds = listen_port(), domain()
    mount = np.eye(4)
    mount[:3, 3] = [0.1, 0.0, 0.5]
    moved = np.eye(4)
    moved[0, 3] = 1.0
    with (
        RosDdsBridge(dds, f"tcp/127.0.0.1:{port}"),
        graph.StandInNode("robot_state_publisher", dds) as tf_node,
    ):
        static = tf_node.publisher("/tf_static", m.TFMessage, graph.TF_STATIC)
        static.write(graph.transforms([("base_link", "camera", mount)], 0.0))
        time.sleep(1.0)  # published, and no one subscribed
        options = RosOptions(key_format="bridge", connect=(f"tcp/127.0.0.1:{port}",),
                             tf_parent="odom")  # fmt: skip
        bridge = Ros2Bridge("a", options)
        try:
            assert graph.matched(static), "the bridge opened no route for /tf_static"
            tf = tf_node.publisher("/tf", m.TFMessage)
            clouds = tf_node.publisher("/points", m.PointCloud2, graph.SENSOR_DATA)
            assert graph.matched(tf) and graph.matched(clouds)
            time.sleep(1.0)
            tf.write(graph.transforms([("odom", "base_link", np.eye(4))], 1.0))
            clouds.write(graph.point_cloud(np.ones((5, 3)), "camera", 1.5))
            tf.write(graph.transforms([("odom", "base_link", moved)], 2.0))
            assert wait(lambda: bridge.counts["clouds"] == 1 and bridge.counts["poses"] >= 2, 10)
            bridge.live.close()
            (frame,) = list(bridge.live)
            halfway = np.eye(4)
            halfway[0, 3] = 0.5
            assert np.allclose(frame.pose, halfway @ mount, atol=1e-6), frame.pose
        finally:
            bridge.close()


def test_malformed_dds_samples_are_counted_and_mapping_goes_on():
    """A cloud whose data is shorter than its header says and one without x, y, z are
    rejected and counted; the good clouds around them become frames. (A String published on
    the clouds' topic never reaches the node: the bridge routes one type per topic.)"""
    port, dds = listen_port(), domain()
    with (
        RosDdsBridge(dds, f"tcp/127.0.0.1:{port}"),
        graph.StandInNode("driver", dds) as driver,
        graph.StandInNode("intruder", dds) as intruder,
    ):
        options = RosOptions(key_format="bridge", connect=(f"tcp/127.0.0.1:{port}",))
        bridge = Ros2Bridge("a", options)
        try:
            clouds = driver.publisher("/points", m.PointCloud2, graph.SENSOR_DATA)
            odom = driver.publisher("/odom", m.Odometry)
            assert graph.matched(clouds) and graph.matched(odom)
            wrong = intruder.publisher("/points", m.String, graph.SENSOR_DATA)
            time.sleep(1.0)
            odom.write(graph.odometry(np.eye(4), 0.0))
            clouds.write(graph.point_cloud(np.ones((5, 3)), "camera", 0.5))
            short = graph.point_cloud(np.ones((5, 3)), "camera", 0.6)
            short.data = short.data[:20]  # 5 points announced, 1.7 sent
            clouds.write(short)
            nameless = graph.point_cloud(np.ones((5, 3)), "camera", 0.65)
            nameless.fields = [m.PointField("intensity", 0, graph.FLOAT32, 1)]
            clouds.write(nameless)
            wrong.write(m.String("not a cloud"))
            clouds.write(graph.point_cloud(np.ones((5, 3)), "camera", 0.7))
            odom.write(graph.odometry(np.eye(4), 1.0))
            done = {"clouds": 2, "poses": 2, "bad": 2}
            assert wait(lambda: all(bridge.counts[k] == n for k, n in done.items()), 10), (
                bridge.counts
            )
            bridge.live.close()
            assert len(list(bridge.live)) == 2
        finally:
            bridge.close()


def test_two_robots_on_two_bridges_join_and_publish_one_tf_tree(tmp_path):
    """The bundled frames split in two robots (0-3 and 4-7: one desk, one mocap frame), each a
    ``gmmap robot --ros2`` process behind its own bridge and DDS domain; their fleet link is
    Zenoh. A DDS subscriber in robot a's domain sees one TF edge, a/map → b/map."""
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:8]
    fleet = {"a": listen_port(), "b": listen_port()}
    ros = {"a": listen_port(), "b": listen_port()}
    domains = {"a": domain(), "b": domain() + 1}
    edges: dict = {}

    def on_tf(msg) -> None:
        for t in msg.transforms:
            edges[(t.header.frame_id, t.child_frame_id)] = t.transform.translation

    with (
        RosDdsBridge(domains["a"], f"tcp/127.0.0.1:{ros['a']}"),
        RosDdsBridge(domains["b"], f"tcp/127.0.0.1:{ros['b']}"),
        graph.StandInNode("driver_a", domains["a"]) as driver_a,
        graph.StandInNode("driver_b", domains["b"]) as driver_b,
        graph.StandInNode("rviz", domains["a"]) as viewer,
    ):
        viewer.subscription("/tf", m.TFMessage, callback=on_tf)
        nodes = []
        for name, other in (("a", "b"), ("b", "a")):
            config = tmp_path / f"{name}.yaml"
            config.write_text(
                f"ros: {{key_format: bridge, connect: ['tcp/127.0.0.1:{ros[name]}'],"
                " publish_every_s: 0.5}\n"
                "build: {frames_per_submap: 2, n_components: 60, covariance: full}\n"
                "backend: {min_matches: 1}\n"
                "robot: {bundle: 1}\n"
            )
            nodes.append(subprocess.Popen(
                [sys.executable, "-c", "from gmmap.cli import main; main()", "robot", "--id", name,
                 "--fleet", "f", "--ros2", "--config", str(config), "--linger", "0.5",
                 "--report", str(tmp_path / f"{name}.json"), "--port", str(fleet[name]),
                 "--peer", f"tcp/127.0.0.1:{fleet[other]}"],
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            ))  # fmt: skip
        try:
            writers = []
            for driver, part in ((driver_a, frames[0:4]), (driver_b, frames[4:8])):
                clouds = driver.publisher("/points", m.PointCloud2, graph.SENSOR_DATA)
                odom = driver.publisher("/odom", m.Odometry)
                assert graph.matched(clouds, 30) and graph.matched(odom, 30)
                writers.append((clouds, odom, part))
            time.sleep(2.0)  # the bridges' routes reach the nodes' sessions
            for clouds, odom, part in writers:
                play(clouds, odom, part)
            assert wait(lambda: ("a/map", "b/map") in edges, 60), edges
            time.sleep(1.5)  # both nodes have published their tree by now
            assert set(edges) == {("a/map", "b/map")}  # one tree, seen through robot a's bridge
            t = edges[("a/map", "b/map")]
            assert np.linalg.norm([t.x, t.y, t.z]) < 0.05  # one mocap frame: the identity
        finally:
            outs = stop_robots(nodes)
    assert_two_robots_joined(nodes, outs, tmp_path)


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_a_bag_recorded_through_the_bridge_is_read_by_gmmap_build(tmp_path, storage):
    """What a DDS driver publishes, recorded from the bridge's Zenoh side into a rosbag2 (the
    CDR as it crossed), opens as a recording with one frame per cloud."""
    import zenoh
    from rosbags.rosbag2 import StoragePlugin, Writer

    from gmmap.io import datasets, ros2

    port, dds = listen_port(), domain()
    frames = TumRgbd(BUNDLED_TUM_SLICE, stride=2)[0:4]
    got: list[tuple[str, int, bytes]] = []
    cfg = zenoh.Config()
    cfg.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    with (
        RosDdsBridge(dds, f"tcp/127.0.0.1:{port}"),
        graph.StandInNode("driver", dds) as driver,
        zenoh.open(cfg) as session,
    ):
        for key in ("points", "odom"):
            session.declare_subscriber(
                key,
                lambda s: got.append((str(s.key_expr), time.time_ns(), s.payload.to_bytes())),
            )
        clouds = driver.publisher("/points", m.PointCloud2, graph.SENSOR_DATA)
        odom = driver.publisher("/odom", m.Odometry)
        assert graph.matched(clouds) and graph.matched(odom)
        time.sleep(1.0)
        play(clouds, odom, frames)
        assert wait(lambda: len(got) == 2 * len(frames) + 1, 10), len(got)
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    types = {"points": ros2.POINTCLOUD2, "odom": ros2.ODOMETRY}
    with Writer(tmp_path / "bag", version=9, storage_plugin=plugin) as writer:
        conns = {k: writer.add_connection("/" + k, t, typestore=ros2.typestore("jazzy"))
                 for k, t in types.items()}  # fmt: skip
        for key, t, payload in got:
            writer.write(conns[key], t, payload)
    recording = datasets.open(tmp_path / "bag")
    assert len(recording) == len(frames)
    assert np.allclose(recording[1].points, frames[1].points, atol=1e-6)
