import json

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gmmap import FileFormatError, InvalidInputError
from gmmap.errors import TopicNotFoundError
from gmmap.io.datasets import RosBag, detect_format
from gmmap.io.datasets import open as open_dataset
from gmmap.io.datasets.rosbag import decode_pointcloud2
from gmmap.math.geometry import make_poses

T0 = 1_700_000_000.0
CLOUD_STAMPS = T0 + 0.1 * np.arange(6)  # 0.0 … 0.5 s
POSE_STAMPS = T0 + 0.04 + 0.07 * np.arange(7)  # 0.04 … 0.46 s: clouds 0 and 5 fall outside
LIDAR_IN_BASE = make_poses(
    np.array([[0.1, 0.0, 0.3]]), np.array([[0, 0, np.sin(0.4), np.cos(0.4)]])
)[0]


def motion(t):
    """Base pose at stamp t: x = 2 m/s, yaw = 0.5 rad/s (exact under lerp + slerp)."""
    dt = np.asarray(t) - T0
    trans = np.stack([2.0 * dt, 0.1 + 0 * dt, 0 * dt], axis=1)
    quat = np.stack([0 * dt, 0 * dt, np.sin(0.25 * dt), np.cos(0.25 * dt)], axis=1)
    return trans, quat


def points(k: int) -> np.ndarray:
    return np.random.default_rng(k).uniform(-20, 20, (100 + k, 3)).astype(np.float32)


class Msgs:
    """Message builders for one typestore (ROS 1 headers have a seq field, ROS 2 ones none)."""

    def __init__(self, ts, ros1: bool):
        self.ts, self.ros1, self.T = ts, ros1, ts.types

    def header(self, t, frame):
        stamp = self.T["builtin_interfaces/msg/Time"](sec=int(t), nanosec=round((t - int(t)) * 1e9))
        extra = {"seq": 0} if self.ros1 else {}
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame, **extra)

    def cloud(self, t, pts):
        # x y z float32 at 0, 4, 8, an intensity at 12, padded to a 20-byte point.
        F = self.T["sensor_msgs/msg/PointField"]
        fields = [F(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyzi")]
        rows = np.zeros((len(pts), 5), np.float32)
        rows[:, :3] = pts
        data = np.frombuffer(rows.tobytes(), np.uint8)
        return self.T["sensor_msgs/msg/PointCloud2"](
            header=self.header(t, "/lidar" if self.ros1 else "lidar"),
            height=1,
            width=len(pts),
            fields=fields,
            is_bigendian=False,
            point_step=20,
            row_step=20 * len(pts),
            data=data,
            is_dense=True,
        )

    def pose(self, trans, quat):
        T = self.T
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=trans[0], y=trans[1], z=trans[2]),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=quat[0], y=quat[1], z=quat[2], w=quat[3]
            ),
        )

    def odometry(self, t, trans, quat):
        T = self.T
        cov = np.zeros(36)
        twist = T["geometry_msgs/msg/Twist"](
            linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
            angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
        )
        return T["nav_msgs/msg/Odometry"](
            header=self.header(t, "odom"),
            child_frame_id="lidar",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=self.pose(trans, quat), covariance=cov
            ),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov),
        )

    def tf(self, t, parent, child, trans, quat):
        T = self.T
        tr = T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](x=trans[0], y=trans[1], z=trans[2]),
            rotation=T["geometry_msgs/msg/Quaternion"](x=quat[0], y=quat[1], z=quat[2], w=quat[3]),
        )
        stamped = T["geometry_msgs/msg/TransformStamped"](
            header=self.header(t, parent), child_frame_id=child, transform=tr
        )
        return T["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def messages(m: Msgs):
    """(topic, type, log time ns, message) of a small drive, in log-time order."""
    out = []
    for k, t in enumerate(CLOUD_STAMPS):
        out.append(("/points", "sensor_msgs/msg/PointCloud2", t, m.cloud(t, points(k))))
    trans, quat = motion(POSE_STAMPS)
    for t, p, q in zip(POSE_STAMPS, trans, quat, strict=True):
        out.append(("/odom", "nav_msgs/msg/Odometry", t, m.odometry(t, p, q)))
        out.append(("/tf", "tf2_msgs/msg/TFMessage", t, m.tf(t, "odom", "base_link", p, q)))
    static_q = [0, 0, np.sin(0.4), np.cos(0.4)]
    static = m.tf(0.0, "base_link", "lidar", [0.1, 0.0, 0.3], static_q)
    out.append(("/tf_static", "tf2_msgs/msg/TFMessage", T0, static))
    return sorted(out, key=lambda r: r[2])


def write_bag(path, ros1: bool, storage=StoragePlugin.SQLITE3):
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # rosbags' Noetic store lacks tf2_msgs; its definition is one line
        tf = "geometry_msgs/TransformStamped[] transforms"
        ts.register(get_types_from_msg(tf, "tf2_msgs/msg/TFMessage"))
    m = Msgs(ts, ros1)
    writer = Writer1(path) if ros1 else Writer2(path, version=9, storage_plugin=storage)
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    with writer:
        conns = {}
        for topic, typ, t, msg in messages(m):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=ts)
            writer.write(conns[topic], round(t * 1e9), serialize(msg, typ))
    return path


BAGS = {
    "ros1": lambda d: write_bag(d / "drive.bag", ros1=True),
    "ros2-sqlite": lambda d: write_bag(d / "drive", ros1=False),
    "ros2-mcap": lambda d: write_bag(d / "drive", ros1=False, storage=StoragePlugin.MCAP),
}


@pytest.fixture(params=list(BAGS))
def bag(request, tmp_path):
    return BAGS[request.param](tmp_path)


def expected_poses(stamps, extrinsic=None):
    trans, quat = motion(stamps)
    return make_poses(trans, quat) @ (np.eye(4) if extrinsic is None else extrinsic)


def test_clouds_and_interpolated_odometry(bag):
    assert detect_format(bag) == "rosbag"
    with RosBag(bag) as seq:  # one cloud topic, one odometry topic: both found
        assert seq.format == "rosbag" and seq.topic == "/points" and seq.pose_source == "/odom"
        # Clouds at 0.0 and 0.5 s lie outside the odometry's 0.04 … 0.46 s: dropped.
        assert len(seq) == 4
        np.testing.assert_allclose(seq.stamps, CLOUD_STAMPS[1:5], rtol=0, atol=1e-6)
        # Stamps 0.1 … 0.4 fall between odometry samples (0.07 s apart); the motion is linear
        # in x and constant-rate in yaw, so lerp + slerp reproduce it exactly.
        np.testing.assert_allclose(seq.poses, expected_poses(seq.stamps), atol=1e-9)
        frames = list(seq)
        for k, f in enumerate(frames, 1):
            np.testing.assert_array_equal(f.points, points(k))
            assert f.gt_pose is None
        np.testing.assert_array_equal(seq[-1].points, points(4))
        assert [f.stamp for f in seq[1:3]] == [frames[1].stamp, frames[2].stamp]


def test_poses_from_the_tf_tree(bag):
    with RosBag(bag, tf_parent="odom") as seq:  # child: the clouds' frame_id, "lidar"
        assert seq.pose_source == "tf odom -> lidar" and len(seq) == 4
        np.testing.assert_allclose(seq.poses, expected_poses(seq.stamps, LIDAR_IN_BASE), atol=1e-9)
    with RosBag(bag, tf_parent="odom", tf_child="base_link", extrinsic=LIDAR_IN_BASE) as seq:
        np.testing.assert_allclose(seq.poses, expected_poses(seq.stamps, LIDAR_IN_BASE), atol=1e-9)
    with pytest.raises(InvalidInputError, match=r"no tf chain from 'map'.*odom->base_link"):
        RosBag(bag, tf_parent="map")


def test_wrong_topics_list_the_available_ones(bag):
    with pytest.raises(
        TopicNotFoundError,
        match=r"'/velodyne_points' is absent.*/points \(sensor_msgs/msg/PointCloud2\)",
    ) as err:
        RosBag(bag, topic="/velodyne_points")
    assert err.value.available["/odom"] == "nav_msgs/msg/Odometry"
    with pytest.raises(TopicNotFoundError, match=r"'/odom' is a nav_msgs/msg/Odometry"):
        RosBag(bag, topic="/odom")
    with pytest.raises(TopicNotFoundError, match="odom_topic='/points'"):
        RosBag(bag, odom_topic="/points")
    with open_dataset(bag, topic="/points", odom_topic="/odom", voxel=100.0) as seq:
        assert len(seq[0].points) < 20  # a 40 m cube of points in 100 m voxels


def test_pointcloud2_decoding_layouts():
    ts = get_typestore(Stores.ROS2_HUMBLE)
    F = ts.types["sensor_msgs/msg/PointField"]
    pts = points(0).astype(np.float64)
    pts[3] = np.nan  # not dense: NaN points are dropped
    # Big-endian float64 z before y, 2 bytes padding per point, 2 rows each padded by 8 bytes.
    dtype = np.dtype(
        {"names": ["x", "z", "y"], "formats": [">f8"] * 3, "offsets": [2, 10, 18], "itemsize": 28}
    )
    rows = np.zeros(len(pts), dtype)
    rows["x"], rows["y"], rows["z"] = pts.T
    half = len(pts) // 2
    body = rows.tobytes()
    data = body[: half * 28] + b"\0" * 8 + body[half * 28 :] + b"\0" * 8
    msg = ts.types["sensor_msgs/msg/PointCloud2"](
        header=None,
        height=2,
        width=half,
        is_bigendian=True,
        point_step=28,
        row_step=half * 28 + 8,
        fields=[
            F(name="x", offset=2, datatype=8, count=1),
            F(name="y", offset=18, datatype=8, count=1),
            F(name="z", offset=10, datatype=8, count=1),
        ],
        data=np.frombuffer(data, np.uint8),
        is_dense=False,
    )
    expected = np.delete(pts, 3, axis=0).astype(np.float32)
    np.testing.assert_array_equal(decode_pointcloud2(msg), expected)
    msg.data = msg.data[:-30]
    with pytest.raises(FileFormatError, match="truncated PointCloud2"):
        decode_pointcloud2(msg)


def test_missing_and_corrupt_bags(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nothing\.bag"):
        RosBag(tmp_path / "nothing.bag")
    (tmp_path / "junk.bag").write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 50)
    with pytest.raises(FileFormatError, match=r"junk\.bag: unreadable bag"):
        RosBag(tmp_path / "junk.bag")


def test_the_cli_takes_a_bags_topics_and_frames_from_flags_or_the_config(tmp_path):
    from click.testing import CliRunner

    from gmmap.cli import main

    bag = write_bag(tmp_path / "drive.bag", ros1=True)
    run = CliRunner().invoke
    r = run(main, ["info", str(bag), "--tf-parent", "odom", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["frames"] == 4
    r = run(main, ["info", str(bag), "--tf-parent", "map"])
    assert r.exit_code != 0 and "no tf chain from 'map'" in r.output
    config = tmp_path / "ros.yaml"
    config.write_text("ros:\n  tf_parent: map\n")
    for args in (["info", str(bag)], ["build", str(bag), "--out", str(tmp_path / "s")]):
        r = run(main, [*args, "--config", str(config)])
        assert r.exit_code != 0 and "no tf chain from 'map'" in r.output, args
    r = run(main, ["build", str(bag), "--out", str(tmp_path / "s"), "--cloud-topic", "/x"])
    assert r.exit_code != 0 and "/points" in r.output  # the topics the bag has
