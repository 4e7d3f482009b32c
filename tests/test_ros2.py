"""ROS 2 wire formats (gmmap.io.ros2): rmw_zenoh and zenoh-bridge-ros2dds keys, the rmw_zenoh
attachment, and CDR messages checked against rosbags' own (de)serialisation."""

import contextlib
import dataclasses
import json
import math

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from gmmap.errors import FileFormatError, InvalidInputError, RosMessageError
from gmmap.io import ros2
from gmmap.io.datasets.rosbag import decode_pointcloud2 as bag_decode_pointcloud2
from gmmap.io.ros2msgs import PALETTE
from gmmap.math.geometry import make_poses, quaternion_to_matrix
from gmmap.math.gmm import Gmm

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
STAMP = 1_700_000_000.25
GID = bytes(range(16))


def cdr(msg, typename, little_endian=True):
    return bytes(TS.serialize_cdr(msg, typename, little_endian=little_endian))


def header(t=STAMP, frame="lidar"):
    sec = int(t)
    stamp = T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9))
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


# --- keys ------------------------------------------------------------------------------------


def test_rmw_zenoh_keys_match_the_design_doc_examples():
    string = "std_msgs/msg/String"
    assert ros2.rmw_zenoh_key("/chatter", string) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert ros2.rmw_zenoh_key("/robot1/chatter", string, distro="kilted") == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert ros2.rmw_zenoh_key("chatter/", string, domain=2, distro="humble") == (
        "2/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported"
    )


TYPES = [
    "sensor_msgs/msg/PointCloud2",
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CameraInfo",
    "nav_msgs/msg/Odometry",
    "tf2_msgs/msg/TFMessage",
    "visualization_msgs/msg/MarkerArray",
    "std_msgs/msg/String",
]


@pytest.mark.parametrize(
    "distro,store", [("jazzy", Stores.ROS2_JAZZY), ("kilted", Stores.ROS2_KILTED)]
)
@pytest.mark.parametrize("typename", TYPES)
def test_type_hash_is_rosbags_rihs01(distro, store, typename):
    expected = get_typestore(store).hash_rihs01(typename)
    assert ros2.type_hash(typename, distro) == expected
    assert expected.startswith("RIHS01_") and len(expected) == 7 + 64
    assert ros2.type_hash(typename, "humble") == "TypeHashNotSupported"


def test_type_names():
    assert (
        ros2.dds_type_name("sensor_msgs/msg/PointCloud2") == "sensor_msgs::msg::dds_::PointCloud2_"
    )
    for name in ("example_interfaces/srv/AddTwoInts", "pkg/action/Fib_FeedbackMessage"):
        assert ros2.ros_type_name(ros2.dds_type_name(name)) == name
    for bad in ("String", "std_msgs/String", "std_msgs/msg/", "std_msgs/foo/String", 3):
        with pytest.raises(RosMessageError):
            ros2.dds_type_name(bad)


def test_bridge_keys():
    assert ros2.bridge_key("/scan") == "scan"
    assert ros2.bridge_key("/scan", "/") == "scan"
    assert ros2.bridge_key("/tf", "/bot1") == "bot1/tf"
    assert ros2.bridge_key("/camera/depth/image_raw", "/fleet/bot1") == (
        "fleet/bot1/camera/depth/image_raw"
    )


TOPICS = ["/chatter", "/robot1/chatter", "/bot_2/camera/depth/image_rect_raw", "/_hidden/x"]


@pytest.mark.parametrize("topic", TOPICS)
@pytest.mark.parametrize("distro", ["humble", "jazzy", "kilted"])
def test_keys_parse_back(topic, distro):
    typename = "sensor_msgs/msg/PointCloud2"
    key = ros2.rmw_zenoh_key(topic, typename, domain=7, distro=distro)
    assert ros2.parse_key(key) == (topic, typename, ros2.type_hash(typename, distro))
    assert ros2.parse_key(ros2.bridge_key(topic)) == (topic, None, None)
    assert ros2.parse_key(ros2.bridge_key(topic, "/bot1"), "/bot1") == (topic, None, None)
    assert ros2.parse_key(ros2.bridge_key(topic, "/bot1")) == ("/bot1" + topic, None, None)


def test_bridge_namespace_is_removed_by_whole_chunks():
    assert ros2.parse_key("bot10/scan", "/bot1").topic == "/bot10/scan"
    assert ros2.parse_key("bot1/scan", "bot1/").topic == "/scan"


def test_keys_are_valid_zenoh_key_expressions():
    zenoh = pytest.importorskip("zenoh")
    typename = "nav_msgs/msg/Odometry"
    sub = zenoh.KeyExpr(ros2.rmw_zenoh_subscription_key("/bot1/odom", typename, 3))
    for distro in ros2.DISTROS:
        key = zenoh.KeyExpr(ros2.rmw_zenoh_key("/bot1/odom", typename, 3, distro))
        assert sub.includes(key)
    assert not sub.includes(zenoh.KeyExpr(ros2.rmw_zenoh_key("/bot1/odom", typename, 4)))
    zenoh.KeyExpr(ros2.bridge_key("/bot1/odom", "/fleet"))


@pytest.mark.parametrize(
    "topic", ["", "/", "//a", "/a//b", "/1abc", "/a/2b", "/a*b", "/~/x", "/{node}/x", "a b", None]
)
def test_bad_topics_are_refused(topic):
    with pytest.raises(RosMessageError):
        ros2.rmw_zenoh_key(topic, "std_msgs/msg/String")
    with pytest.raises(RosMessageError):
        ros2.bridge_key(topic)


def test_bad_key_arguments_are_refused():
    for domain in (-1, True, "0", 1.0):
        with pytest.raises(RosMessageError):
            ros2.rmw_zenoh_key("/a", "std_msgs/msg/String", domain=domain)
    with pytest.raises(RosMessageError, match="distro"):
        ros2.rmw_zenoh_key("/a", "std_msgs/msg/String", distro="rolling")
    with pytest.raises(RosMessageError, match="not a jazzy message type"):
        ros2.type_hash("foo_msgs/msg/Bar")
    with pytest.raises(RosMessageError):
        ros2.bridge_key("/a", namespace="bad ns")


@pytest.mark.parametrize(
    "key",
    [
        "",
        "0/chatter/std_msgs::msg::dds_::String_/nothash",
        "0/chatter/String/" + STRING_HASH,
        "0/std_msgs::msg::dds_::String_/" + STRING_HASH,  # no topic
        "0/1x/std_msgs::msg::dds_::String_/" + STRING_HASH,
        "a::b",
        "scan/",
        "a//b",
        None,
    ],
)
def test_bad_keys_do_not_parse(key):
    with pytest.raises(RosMessageError):
        ros2.parse_key(key)


# --- attachment ------------------------------------------------------------------------------

# sequence 1, timestamp 1_700_000_000_123_456_789 ns, GID 00 01 … 0f, by hand: two little-endian
# int64, the LEB128 length 16, the GID.
ATTACHMENT_HEX = "010000000000000015cd853dfe9c971710000102030405060708090a0b0c0d0e0f"
KNOWN = ros2.Attachment(1, 1_700_000_000_123_456_789, GID)


def test_attachment_matches_hand_built_bytes():
    data = ros2.encode_attachment(KNOWN)
    assert data == bytes.fromhex(ATTACHMENT_HEX) and len(data) == 33
    assert ros2.parse_attachment(data) == KNOWN
    negative = ros2.Attachment(-5, 0, b"\xff" * 16)
    assert ros2.encode_attachment(negative)[:8] == bytes.fromhex("fbffffffffffffff")


def test_attachment_round_trips():
    rng = np.random.default_rng(1)
    for _ in range(50):
        seq, stamp = (int(v) for v in rng.integers(-(2**63), 2**63 - 1, 2, dtype=np.int64))
        a = ros2.Attachment(seq, stamp, rng.bytes(16))
        assert ros2.parse_attachment(ros2.encode_attachment(a)) == a
    extreme = ros2.Attachment(2**63 - 1, -(2**63), bytearray(16))
    assert ros2.parse_attachment(memoryview(ros2.encode_attachment(extreme))) == extreme


def test_attachment_is_what_zenoh_ext_serializes():
    ext = pytest.importorskip("zenoh.ext")
    seq, stamp = KNOWN.sequence_number, KNOWN.source_timestamp
    z = ext.z_serialize((ext.Int64(seq), ext.Int64(stamp), GID)).to_bytes()
    assert z == ros2.encode_attachment(KNOWN)
    zbytes = pytest.importorskip("zenoh").ZBytes(ros2.encode_attachment(KNOWN))
    back = ext.z_deserialize(tuple[ext.Int64, ext.Int64, bytes], zbytes)
    assert tuple(back) == (seq, stamp, GID)


def test_legacy_keyed_attachment_parses():
    seq, stamp = KNOWN.sequence_number, KNOWN.source_timestamp
    legacy = (
        b"\x0fsequence_number" + bytes.fromhex("0100000000000000")
        + b"\x10source_timestamp" + bytes.fromhex("15cd853dfe9c9717")
        + b"\x0asource_gid" + b"\x10" + GID
    )  # fmt: skip
    assert ros2.parse_attachment(legacy) == KNOWN
    ext = pytest.importorskip("zenoh.ext")
    parts = ("sequence_number", ext.Int64(seq), "source_timestamp", ext.Int64(stamp))
    assert ext.z_serialize((*parts, "source_gid", GID)).to_bytes() == legacy
    with pytest.raises(RosMessageError, match="source_timestamp"):
        ros2.parse_attachment(legacy.replace(b"source_timestamp", b"source_timestamq"))


def test_bad_attachments_raise_the_typed_error():
    good = bytes.fromhex(ATTACHMENT_HEX)
    for n in range(len(good)):
        with pytest.raises(RosMessageError):
            ros2.parse_attachment(good[:n])
    bad = [good + b"\x00", good[:16] + b"\x11" + good[17:], good[:16] + b"\xff" * 17]
    rng = np.random.default_rng(2)
    bad += [rng.bytes(int(rng.integers(0, 80))) for _ in range(300)]
    for data in bad:  # random bytes may happen to be an attachment; nothing else may escape
        with contextlib.suppress(RosMessageError):
            ros2.parse_attachment(data)
    for data in bad[:3]:
        with pytest.raises(RosMessageError):
            ros2.parse_attachment(data)


def test_attachment_fields_are_checked():
    for seq in (2**63, -(2**63) - 1, True, 1.0):
        with pytest.raises(RosMessageError):
            ros2.Attachment(seq, 0, GID)
    for gid in (b"", bytes(15), bytes(17), "x" * 16, None):
        with pytest.raises(RosMessageError):
            ros2.Attachment(1, 0, gid)


# --- PointCloud2 in --------------------------------------------------------------------------


def cloud_msg(pts, *, dtype="<f4", padding=4, row_padding=0, height=1, bigendian=False):
    """x y z of ``dtype`` at 0, s, 2s, then ``padding`` bytes; rows padded by ``row_padding``."""
    pts = np.asarray(pts)
    size = np.dtype(dtype).itemsize
    point_step = 3 * size + padding
    width = len(pts) // height
    row_step = width * point_step + row_padding
    buf = np.full((height, row_step), 0xAB, np.uint8)
    for r in range(height):
        for c in range(width):
            raw = pts[r * width + c].astype(dtype).tobytes()
            buf[r, c * point_step : c * point_step + 3 * size] = np.frombuffer(raw, np.uint8)
    datatype = {4: 7, 8: 8}[size]
    F = T["sensor_msgs/msg/PointField"]
    fields = [F(name=a, offset=i * size, datatype=datatype, count=1) for i, a in enumerate("xyz")]
    fields.append(F(name="intensity", offset=3 * size, datatype=7, count=1))
    return T["sensor_msgs/msg/PointCloud2"](
        header=header(),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=bigendian,
        point_step=point_step,
        row_step=row_step,
        data=buf.ravel(),
        is_dense=False,
    )


def sample_points(n=12, seed=0):
    pts = np.random.default_rng(seed).uniform(-30, 30, (n, 3)).astype(np.float32)
    pts[3, 1] = np.nan
    pts[7, 2] = np.inf
    return pts


def finite(pts):
    return pts[np.isfinite(pts).all(axis=1)]


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"padding": 8, "row_padding": 6, "height": 3},
        {"dtype": "<f8", "padding": 0},
        {"dtype": ">f4", "bigendian": True, "height": 2, "row_padding": 3},
        {"dtype": ">f8", "bigendian": True},
    ],
)
@pytest.mark.parametrize("cdr_little_endian", [True, False])
def test_pointcloud2_decodes(options, cdr_little_endian):
    pts = sample_points()
    data = cdr(cloud_msg(pts, **options), ros2.POINTCLOUD2, cdr_little_endian)
    stamp, frame, out = ros2.decode_pointcloud2(data)
    assert stamp == pytest.approx(STAMP, abs=1e-6) and frame == "lidar"
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, finite(pts))


def test_pointcloud2_with_shuffled_field_offsets():
    # z first, then x, then y, in a 16-byte point with float64 z.
    pts = sample_points(8)
    rows = np.zeros(8, dtype=[("z", "<f8"), ("x", "<f4"), ("y", "<f4")])
    rows["x"], rows["y"], rows["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    F = T["sensor_msgs/msg/PointField"]
    fields = [F("z", 0, 8, 1), F("x", 8, 7, 1), F("y", 12, 7, 1)]
    msg = T["sensor_msgs/msg/PointCloud2"](
        header(), 1, 8, fields, False, 16, 128, np.frombuffer(rows.tobytes(), np.uint8), False
    )
    np.testing.assert_array_equal(
        ros2.decode_pointcloud2(cdr(msg, ros2.POINTCLOUD2)).points, finite(pts)
    )


def test_bad_pointclouds_raise_the_typed_error():
    F = T["sensor_msgs/msg/PointField"]
    good = cloud_msg(sample_points())
    variants = {
        "no z field": {"fields": good.fields[:2]},
        "unknown datatype": {"fields": [F("x", 0, 9, 1), F("y", 4, 7, 1), F("z", 8, 7, 1)]},
        "field past point_step": {"point_step": 10, "row_step": 10 * good.width},
        "row_step too small": {"row_step": good.width * good.point_step - 1},
        "truncated data": {"data": good.data[:-1]},
    }
    for what, change in variants.items():
        msg = dataclasses.replace(good, **change)
        with pytest.raises(RosMessageError):
            ros2.decode_pointcloud2(cdr(msg, ros2.POINTCLOUD2))
        with pytest.raises(FileFormatError):  # the bag reader shares the decoding
            bag_decode_pointcloud2(msg)
        assert what


# --- depth images in -------------------------------------------------------------------------

CAMERA = ros2.Camera(fx=500.0, fy=400.0, cx=1.5, cy=1.0, width=4, height=3)
DEPTH_MM = np.array([[1000, 0, 2000, 1500], [500, 750, 0, 3000], [1234, 65535, 1, 2500]])


def image_msg(depth, encoding, *, bigendian=False, row_padding=0):
    dtype = {"16UC1": "u2", "32FC1": "f4"}[encoding]
    dtype = np.dtype(dtype).newbyteorder(">" if bigendian else "<")
    h, w = depth.shape
    rows = np.zeros((h, w * dtype.itemsize + row_padding), np.uint8)
    rows[:, : w * dtype.itemsize] = np.frombuffer(depth.astype(dtype).tobytes(), np.uint8).reshape(
        h, -1
    )
    return T["sensor_msgs/msg/Image"](
        header=header(frame="camera_depth_optical_frame"),
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=bigendian,
        step=rows.shape[1],
        data=rows.ravel(),
    )


def pinhole(depth_m, cam, stride=1):
    """The back-projection, pixel by pixel: x = (u − cx) z / fx, y = (v − cy) z / fy."""
    out = []
    for v in range(0, depth_m.shape[0], stride):
        for u in range(0, depth_m.shape[1], stride):
            z = float(depth_m[v, u])
            if math.isfinite(z) and z > 0:
                out.append(((u - cam.cx) * z / cam.fx, (v - cam.cy) * z / cam.fy, z))
    return np.array(out, dtype=np.float32).reshape(-1, 3)


@pytest.mark.parametrize("options", [{}, {"bigendian": True}, {"row_padding": 6}])
def test_depth_16uc1_millimetres(options):
    data = cdr(image_msg(DEPTH_MM, "16UC1", **options), ros2.IMAGE)
    stamp, frame, pts = ros2.decode_depth_image(data, CAMERA)
    assert frame == "camera_depth_optical_frame" and stamp == pytest.approx(STAMP, abs=1e-6)
    np.testing.assert_allclose(pts, pinhole(DEPTH_MM / 1000.0, CAMERA), rtol=1e-6)
    assert len(pts) == 10  # two zero pixels
    # u = 0, v = 0 at 1 m: x = −1.5 / 500, y = −1 / 400.
    np.testing.assert_allclose(pts[0], [-0.003, -0.0025, 1.0], rtol=1e-6)


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_depth_32fc1_metres(stride):
    depth = DEPTH_MM / 1000.0
    depth[0, 3], depth[1, 0], depth[2, 2] = np.nan, np.inf, -1.0
    data = cdr(image_msg(depth, "32FC1", row_padding=4), ros2.IMAGE)
    pts = ros2.decode_depth_image(data, CAMERA, stride=stride).points
    np.testing.assert_allclose(pts, pinhole(depth, CAMERA, stride), rtol=1e-6)
    assert np.isfinite(pts).all() and (pts[:, 2] > 0).all()


def camera_info_msg(k=(500.0, 0, 1.5, 0, 400.0, 1.0, 0, 0, 1), **change):
    roi = T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
    fields = dict(
        header=header(frame="camera_depth_optical_frame"),
        height=3,
        width=4,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=np.array(k, dtype=np.float64),
        r=np.eye(3).ravel(),
        p=np.zeros(12),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )
    return T["sensor_msgs/msg/CameraInfo"](**{**fields, **change})


def test_camera_info_decodes_to_intrinsics():
    cam = ros2.decode_camera_info(cdr(camera_info_msg(), ros2.CAMERA_INFO))
    assert cam == ros2.Camera(500.0, 400.0, 1.5, 1.0, 4, 3, "camera_depth_optical_frame")
    full = T["sensor_msgs/msg/RegionOfInterest"](0, 0, 3, 4, False)
    assert ros2.decode_camera_info(cdr(camera_info_msg(roi=full), ros2.CAMERA_INFO)) == cam


@pytest.mark.parametrize(
    "change",
    [
        {"k": np.zeros(9)},  # uncalibrated
        {"k": np.array([500.0, 2.0, 1.5, 0, 400.0, 1.0, 0, 0, 1])},  # skew
        {"k": np.array([np.nan, 0, 1.5, 0, 400.0, 1.0, 0, 0, 1])},
        {"binning_x": 2},
        {"roi": T["sensor_msgs/msg/RegionOfInterest"](1, 0, 2, 3, False)},
    ],
)
def test_unusable_camera_info_raises(change):
    with pytest.raises(RosMessageError):
        ros2.decode_camera_info(cdr(camera_info_msg(**change), ros2.CAMERA_INFO))


def test_bad_depth_images_raise():
    for encoding in ("rgb8", "mono16", "16SC1", ""):
        msg = image_msg(DEPTH_MM, "16UC1")
        msg.encoding = encoding
        with pytest.raises(RosMessageError, match="encoding"):
            ros2.decode_depth_image(cdr(msg, ros2.IMAGE), CAMERA)
    short = image_msg(DEPTH_MM, "16UC1")
    short.data = short.data[:-1]
    narrow = image_msg(DEPTH_MM, "16UC1")
    narrow.step = 7
    for msg in (short, narrow, image_msg(DEPTH_MM[:2], "16UC1")):  # the last: 4x2 ≠ camera
        with pytest.raises(RosMessageError):
            ros2.decode_depth_image(cdr(msg, ros2.IMAGE), CAMERA)
    for stride in (0, -1, 1.5, True):
        with pytest.raises(InvalidInputError):
            ros2.decode_depth_image(cdr(image_msg(DEPTH_MM, "16UC1"), ros2.IMAGE), CAMERA, stride)


def test_any_size_camera_accepts_any_image():
    cam = ros2.Camera(500.0, 400.0, 1.5, 1.0)
    pts = ros2.decode_depth_image(cdr(image_msg(DEPTH_MM[:2], "16UC1"), ros2.IMAGE), cam).points
    assert len(pts) == 6  # two of the eight pixels have no depth
    with pytest.raises(InvalidInputError):
        ros2.Camera(0.0, 400.0, 1.5, 1.0)


# --- odometry and tf in ----------------------------------------------------------------------


def quat_z(angle):
    return [0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)]


def rot_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def pose_msg(t, q):
    return T["geometry_msgs/msg/Pose"](
        T["geometry_msgs/msg/Point"](*t), T["geometry_msgs/msg/Quaternion"](*q)
    )


def odometry_msg(t, q):
    cov = T["geometry_msgs/msg/PoseWithCovariance"](pose_msg(t, q), np.zeros(36))
    vec = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        T["geometry_msgs/msg/Twist"](vec(1, 0, 0), vec(0, 0, 0.1)), np.zeros(36)
    )
    return T["nav_msgs/msg/Odometry"](header(frame="odom"), "base_link", cov, twist)


def test_odometry_decodes_to_the_quaternion_pose():
    data = cdr(odometry_msg([1.0, -2.0, 0.5], quat_z(math.pi / 2)), ros2.ODOMETRY)
    stamp, parent, child, pose = ros2.decode_odometry(data)
    assert (parent, child) == ("odom", "base_link") and stamp == pytest.approx(STAMP, abs=1e-6)
    expected = np.eye(4)
    expected[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90° about z, by hand
    expected[:3, 3] = [1.0, -2.0, 0.5]
    np.testing.assert_allclose(pose, expected, atol=1e-12)
    # A quaternion off unit length is normalised; a zero one is refused.
    scaled = cdr(odometry_msg([0, 0, 0], [2 * v for v in quat_z(0.3)]), ros2.ODOMETRY)
    np.testing.assert_allclose(ros2.decode_odometry(scaled).pose[:3, :3], rot_z(0.3), atol=1e-12)
    with pytest.raises(RosMessageError):
        ros2.decode_odometry(cdr(odometry_msg([0, 0, 0], [0, 0, 0, 0]), ros2.ODOMETRY))
    with pytest.raises(RosMessageError):
        ros2.decode_odometry(cdr(odometry_msg([np.nan, 0, 0], quat_z(0)), ros2.ODOMETRY))


def transform_msg(parent, child, t, q, stamp):
    tf = T["geometry_msgs/msg/Transform"](
        T["geometry_msgs/msg/Vector3"](*t), T["geometry_msgs/msg/Quaternion"](*q)
    )
    return T["geometry_msgs/msg/TransformStamped"](header(stamp, parent), child, tf)


def test_tf_decodes_every_transform():
    q = np.array([0.1, -0.2, 0.3, 0.9])
    msg = T["tf2_msgs/msg/TFMessage"](
        [
            transform_msg("map", "odom", [0, 0, 0], quat_z(0.5), STAMP),
            transform_msg("odom", "base_link", [3.0, 4.0, 0.0], q.tolist(), STAMP + 1.5),
        ]
    )
    first, second = ros2.decode_tf(cdr(msg, ros2.TF_MESSAGE))
    assert first[1:3] == ("map", "odom") and second[1:3] == ("odom", "base_link")
    assert second.stamp == pytest.approx(STAMP + 1.5, abs=1e-6)
    np.testing.assert_allclose(first.pose[:3, :3], rot_z(0.5), atol=1e-12)
    np.testing.assert_allclose(second.pose, make_poses(np.array([[3.0, 4, 0]]), q[None])[0])
    R = quaternion_to_matrix(q[None])[0]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(second.pose[:3, :3], R)
    assert ros2.decode_tf(cdr(T["tf2_msgs/msg/TFMessage"]([]), ros2.TF_MESSAGE)) == []


# --- garbage in ------------------------------------------------------------------------------


def valid_messages():
    return {
        "cloud": (cdr(cloud_msg(sample_points()), ros2.POINTCLOUD2), ros2.decode_pointcloud2),
        "depth": (
            cdr(image_msg(DEPTH_MM, "16UC1"), ros2.IMAGE),
            lambda d, distro="jazzy": ros2.decode_depth_image(d, CAMERA, distro=distro),
        ),
        "info": (cdr(camera_info_msg(), ros2.CAMERA_INFO), ros2.decode_camera_info),
        "odom": (cdr(odometry_msg([1, 2, 3], quat_z(1)), ros2.ODOMETRY), ros2.decode_odometry),
        "tf": (
            cdr(
                T["tf2_msgs/msg/TFMessage"]([transform_msg("a", "b", [0, 0, 0], quat_z(0), STAMP)]),
                ros2.TF_MESSAGE,
            ),
            ros2.decode_tf,
        ),
        "status": (ros2.encode_status({"ok": True}), ros2.decode_status),
    }


@pytest.mark.parametrize("name", list(valid_messages()))
def test_garbage_raises_the_typed_error(name):
    data, decode = valid_messages()[name]
    decode(data)  # the valid message decodes
    for distro in ros2.DISTROS:
        decode(data, distro=distro)
    rng = np.random.default_rng(3)
    garbage = [b"", b"\x00", b"\x00\x01\x00", b"\x01\x00\x00\x00" + data[4:], data[:4]]
    garbage += [data[: len(data) * k // 10] for k in range(1, 10)]
    garbage += [b"\x00\x01\x00\x00" + rng.bytes(int(rng.integers(0, 300))) for _ in range(200)]
    flipped = bytearray(data)
    for i in rng.choice(len(data), min(60, len(data)), replace=False):
        flipped[i] ^= 0xFF
        garbage.append(bytes(flipped))
    for other, (other_data, _) in valid_messages().items():
        if other != name:
            garbage.append(other_data)  # another type's valid bytes
    failures = 0
    for g in garbage:
        try:
            decode(g)
        except RosMessageError:
            failures += 1
    assert failures >= 15  # every empty, short and truncated one at least
    for g in garbage[:14]:
        with pytest.raises(RosMessageError):
            decode(g)
    with pytest.raises(RosMessageError, match="distro"):
        decode(data, distro="iron")


# --- outputs ---------------------------------------------------------------------------------


def test_encoded_pointcloud2_is_xyz_float32():
    pts = np.random.default_rng(4).normal(size=(50, 3))
    data = ros2.encode_pointcloud2(pts, "map", STAMP)
    msg = TS.deserialize_cdr(data, ros2.POINTCLOUD2)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, 7, 1),
        ("y", 4, 7, 1),
        ("z", 8, 7, 1),
    ]
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 50, 12, 600)
    assert not msg.is_bigendian and msg.is_dense and msg.header.frame_id == "map"
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    np.testing.assert_array_equal(
        np.frombuffer(msg.data.tobytes(), "<f4").reshape(-1, 3), pts.astype(np.float32)
    )
    np.testing.assert_array_equal(ros2.decode_pointcloud2(data).points, pts.astype(np.float32))
    assert (
        len(ros2.decode_pointcloud2(ros2.encode_pointcloud2(np.zeros((0, 3)), "map")).points) == 0
    )
    with pytest.raises(InvalidInputError):
        ros2.encode_pointcloud2([[0, 0, np.nan]], "map")
    for stamp in (-1.0, np.nan, 2.0**31, "now"):
        with pytest.raises(InvalidInputError):
            ros2.encode_pointcloud2(pts, "map", stamp)


def test_stamps_round_to_nanoseconds_with_carry():
    msg = TS.deserialize_cdr(
        ros2.encode_pointcloud2(np.zeros((1, 3)), "m", 41.9999999999), ros2.POINTCLOUD2
    )
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (42, 0)


def test_encoded_tf_decodes_back():
    R = quaternion_to_matrix(np.array([[0.2, 0.4, -0.1, 0.8]]))[0]
    A = np.eye(4)
    A[:3, :3], A[:3, 3] = R, [1.0, 2.0, 3.0]
    B = np.eye(4)
    B[:3, 3] = [0.0, 0.0, -0.5]
    data = ros2.encode_tf([("world", "bot1/map", A, STAMP), ("bot1/map", "bot1/odom", B, 5.0)])
    msg = TS.deserialize_cdr(data, ros2.TF_MESSAGE)
    assert [(t.header.frame_id, t.child_frame_id) for t in msg.transforms] == [
        ("world", "bot1/map"),
        ("bot1/map", "bot1/odom"),
    ]
    assert (msg.transforms[1].header.stamp.sec, msg.transforms[1].header.stamp.nanosec) == (5, 0)
    r = msg.transforms[0].transform.rotation
    np.testing.assert_allclose(
        quaternion_to_matrix(np.array([[r.x, r.y, r.z, r.w]]))[0], R, atol=1e-12
    )
    decoded = ros2.decode_tf(data)
    np.testing.assert_allclose(decoded[0].pose, A, atol=1e-12)
    np.testing.assert_allclose(decoded[1].pose, B, atol=1e-12)
    assert decoded[0].stamp == pytest.approx(STAMP, abs=1e-6)
    for bad in ([("a", "b", np.diag([2.0, 1, 1, 1]), 0.0)], [("a", "b", np.eye(4))], ["x"]):
        with pytest.raises(InvalidInputError):
            ros2.encode_tf(bad)


def random_gmm(k=6, seed=5):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(k, 3, 3))
    covs = A @ np.swapaxes(A, 1, 2) * 0.05 + 1e-4 * np.eye(3)
    covs[0] = np.diag([0.04, 0.01, 1e-12])  # a flat one: its thin axis is clamped
    return Gmm(np.full(k, 1 / k), rng.uniform(-10, 10, (k, 3)), covs)


def test_markers_draw_each_component_ellipsoid():
    gmm = random_gmm()
    msg = TS.deserialize_cdr(ros2.encode_markers(gmm, "bot1", "bot1/map", STAMP), ros2.MARKER_ARRAY)
    assert len(msg.markers) == len(gmm)
    color = ros2.robot_color("bot1")
    for i, m in enumerate(msg.markers):
        assert (m.ns, m.id, m.type, m.action, m.header.frame_id) == ("bot1", i, 2, 0, "bot1/map")
        assert (m.color.r, m.color.g, m.color.b) == pytest.approx(color) and 0 < m.color.a <= 1
        p, o, s = m.pose.position, m.pose.orientation, m.scale
        np.testing.assert_allclose([p.x, p.y, p.z], gmm.means[i])
        assert math.isclose(np.linalg.norm([o.x, o.y, o.z, o.w]), 1.0, rel_tol=1e-9)
        R = quaternion_to_matrix(np.array([[o.x, o.y, o.z, o.w]]))[0]
        assert np.linalg.det(R) == pytest.approx(1.0)
        semi = np.array([s.x, s.y, s.z]) / 2 / 2.0  # diameters of the 2-sigma ellipsoid → σ
        if i == 0:
            assert min(s.x, s.y, s.z) == pytest.approx(1e-3)
            np.testing.assert_allclose(sorted([s.x, s.y, s.z])[1:], [0.4, 0.8], rtol=1e-9)
            continue
        np.testing.assert_allclose(
            R @ np.diag(semi**2) @ R.T, gmm.covariances[i], rtol=1e-7, atol=1e-12
        )


def test_marker_options():
    gmm = random_gmm(3)
    msg = TS.deserialize_cdr(
        ros2.encode_markers(gmm, "bot2", "map", sigma=1.0, previous=5, color=(1.0, 0.0, 0.5)),
        ros2.MARKER_ARRAY,
    )
    assert [m.action for m in msg.markers] == [0, 0, 0, 2, 2]
    assert [m.id for m in msg.markers] == [0, 1, 2, 3, 4]
    assert (msg.markers[0].color.r, msg.markers[0].color.b) == (1.0, 0.5)
    s = msg.markers[1].scale
    values = np.linalg.eigvalsh(gmm.covariances[1])
    np.testing.assert_allclose(sorted([s.x, s.y, s.z]), 2 * np.sqrt(values), rtol=1e-9)
    with pytest.raises(InvalidInputError):
        ros2.encode_markers(gmm, "", "map")
    with pytest.raises(InvalidInputError):
        ros2.encode_markers(gmm, "bot", "map", sigma=0)


def test_robot_colours_are_a_deterministic_palette():
    assert ros2.robot_color("bot1") == ros2.robot_color("bot1")
    assert ros2.robot_color("bot1") in PALETTE
    assert len({ros2.robot_color(f"bot{i}") for i in range(20)}) > 3
    assert ros2.robot_color("alpha") == (0.17, 0.63, 0.17)  # crc32("alpha") % 8 == 2: stable


def test_status_is_json_in_a_string():
    status = {"robot": "bot1", "submaps": 12, "pose": [1.0, 2.0, 0.5], "ok": True}
    data = ros2.encode_status(status, distro="humble")
    text = TS.deserialize_cdr(data, ros2.STRING).data
    assert json.loads(text) == status and text == json.dumps(
        status, sort_keys=True, separators=(",", ":")
    )
    assert ros2.decode_status(data) == status
    for bad in ({"x": math.nan}, {"x": object()}):
        with pytest.raises(InvalidInputError):
            ros2.encode_status(bad)
    with pytest.raises(RosMessageError):
        ros2.decode_status(cdr(T["std_msgs/msg/String"]("not json"), ros2.STRING))


# rmw_zenoh's design.md examples, verbatim.
LISTENER = "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
TALKER = (
    "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    "std_msgs::msg::dds_::String_/"
    "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,"
)


def test_liveliness_tokens_are_rmw_zenohs_own():
    zids = ("aac3178e146ba6f1fc6e6a4085e77f21", "8b20917502ee955ac4476e0266340d5c")
    assert ros2.liveliness_token(zids[0], 0, 0, "NN", "listener") == LISTENER
    talker = ros2.liveliness_token(zids[1], 0, 10, "MP", "talker", "/chatter", ros2.STRING, 7)
    assert talker == TALKER
    t = ros2.parse_liveliness_token(TALKER)
    assert (t.kind, t.node, t.namespace, t.topic, t.typename) == (
        "MP", "talker", "/", "/chatter", ros2.STRING
    )  # fmt: skip
    assert (t.entity_id, t.qos) == (10, "::,7:,:,:,,")
    assert ros2.parse_liveliness_token(LISTENER).topic is None


def test_liveliness_tokens_round_trip_mangled_names_default_depth_and_humble():
    key = ros2.liveliness_token("ab12", 3, 4, "MS", "gmmap_a", "/robot1/scan", ros2.POINTCLOUD2,
                                domain=7, distro="humble")  # fmt: skip
    assert "/%robot1%scan/" in key and key.endswith(f"/{ros2.HUMBLE_TYPE_HASH}/::,:,:,:,,")
    t = ros2.parse_liveliness_token(key)
    assert (t.domain, t.node_id, t.entity_id, t.topic) == (7, 3, 4, "/robot1/scan")


@pytest.mark.parametrize(
    "key",
    [
        "", "@ros2_lv/0", LISTENER.replace("@ros2_lv", "@ros2"), LISTENER.replace("/NN/", "/XX/"),
        LISTENER.replace("/0/0/", "/0/x/"), LISTENER + "/%chatter", TALKER.rsplit("/", 1)[0],
        TALKER.replace("RIHS01_df", "RIHS02_df"), TALKER.replace("/MP/", "/NN/"),
        LISTENER.replace("/aac3", "/AAC3"), LISTENER.replace("/%/%/", "/%/%/1"),
        LISTENER.replace("/%/%/", "//%/"), LISTENER.replace("/%/%/", "/%/robot1/"),
        LISTENER.replace("/%/%/", "/%/%a b/"), TALKER.replace("%chatter", "chatter"),
        TALKER.replace("%chatter", "%"), TALKER.replace("::,7:,:,:,,", "::,x:,:,:,,"),
        TALKER.replace("::,7:,:,:,,", "::,7:,:,:"),
        TALKER.replace("::,7:,:,:,,", "::,\u0667:,:,:,,"),  # an Arabic-Indic 7
    ],
)  # fmt: skip
def test_malformed_liveliness_tokens_are_refused(key):
    with pytest.raises(RosMessageError):
        ros2.parse_liveliness_token(key)


def test_a_token_needs_a_hex_zid_a_known_kind_a_ros_node_name_and_a_topic():
    for args in (("zz", 0, 0, "NN", "n"), ("ab", 0, 0, "QQ", "n"), ("ab", 0, 0, "NN", "1n"),
                 ("ab", 0, 0, "MP", "n"), ("ab", 0, 0, "NN", "a/b"), ("ab", -1, 0, "NN", "n"),
                 ("ab", 0, 0, "MS", "n", "/s", ros2.STRING, -1)):  # fmt: skip
        with pytest.raises(RosMessageError):
            ros2.liveliness_token(*args)
    with pytest.raises(RosMessageError):
        ros2.liveliness_token("ab", 0, 0, "NN", "n", namespace="robot1")  # not absolute
    key = ros2.liveliness_token("ab", 0, 0, "NN", "n", namespace="/robot1")
    assert key.endswith("/%/%robot1/n") and ros2.parse_liveliness_token(key).namespace == "/robot1"


def test_the_bridge_hosts_version_is_the_one_tests_look_for():
    """``make ros2`` keys its cache by the host's version; `RosDdsBridge` looks there."""
    import re
    from pathlib import Path

    from gmmap.eval.ros2dds import bridge

    cargo = (Path(__file__).parents[1] / "tools" / "ros2dds-bridge" / "Cargo.toml").read_text()
    assert re.search(r'^version = "(.*)"', cargo, re.M)[1] == bridge.PLUGIN_VERSION
    assert f'zenoh-plugin-ros2dds = {{ version = "={bridge.PLUGIN_VERSION}"' in cargo
