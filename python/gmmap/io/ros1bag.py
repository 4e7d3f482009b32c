"""ROS 1 bags written from gmmap's frames (rosbags; no ROS install), for ``rosbag play`` into a
live node: the tests and benchmarks of ``gmmap robot --ros1``, and anyone who wants to replay a
recording through ROS. Two layouts, the two a robot publishes:

- `write_cloud_bag`: sensor_msgs/PointCloud2 (x y z float32) on ``<prefix>/camera/depth/points``
  and nav_msgs/Odometry of the sensor on ``<prefix>/odom``;
- `write_depth_bag`: sensor_msgs/Image (16UC1, millimetres) with its CameraInfo on
  ``/camera/depth/image`` and ``/camera/depth/camera_info``, the base on /tf (odom →
  base_link) and the camera's mounting on /tf_static (base_link → camera).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from gmmap.io.datasets.tum import Intrinsics
from gmmap.mapping.frame import Frame
from gmmap.math.geometry import matrix_to_quaternion

TF = "tf2_msgs/msg/TFMessage"
TS = get_typestore(Stores.ROS1_NOETIC)
# rosbags' Noetic store lacks tf2_msgs; its definition is one line
TS.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
T = TS.types


def header(stamp: float, frame: str):
    sec = int(stamp)
    return T["std_msgs/msg/Header"](
        0, T["builtin_interfaces/msg/Time"](sec, round((stamp - sec) * 1e9)), frame
    )


def cloud(stamp: float, points: np.ndarray, frame: str = "camera"):
    pts = np.ascontiguousarray(points, dtype="<f4")
    fields = [T["sensor_msgs/msg/PointField"](a, 4 * i, 7, 1) for i, a in enumerate("xyz")]
    data = np.frombuffer(pts.tobytes(), np.uint8)
    return T["sensor_msgs/msg/PointCloud2"](
        header(stamp, frame), 1, len(pts), fields, False, 12, 12 * len(pts), data, True
    )


def _quaternion(pose: np.ndarray):
    return T["geometry_msgs/msg/Quaternion"](*matrix_to_quaternion(pose[None, :3, :3])[0])


def odometry(stamp: float, pose: np.ndarray, child: str = "camera"):
    p = T["geometry_msgs/msg/Pose"](T["geometry_msgs/msg/Point"](*pose[:3, 3]), _quaternion(pose))
    vec = T["geometry_msgs/msg/Vector3"](0.0, 0.0, 0.0)
    twist = T["geometry_msgs/msg/TwistWithCovariance"](
        T["geometry_msgs/msg/Twist"](vec, vec), np.zeros(36)
    )
    covariance = T["geometry_msgs/msg/PoseWithCovariance"](p, np.zeros(36))
    return T["nav_msgs/msg/Odometry"](header(stamp, "odom"), child, covariance, twist)


def transform(stamp: float, parent: str, child: str, pose: np.ndarray):
    vec = T["geometry_msgs/msg/Vector3"](*pose[:3, 3])
    r = T["geometry_msgs/msg/Transform"](vec, _quaternion(pose))
    return T[TF]([T["geometry_msgs/msg/TransformStamped"](header(stamp, parent), child, r)])


def camera_info(stamp: float, k: Intrinsics, width: int, height: int, frame: str = "camera"):
    roi = T["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
    K = np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], float)
    P = np.array([k.fx, 0, k.cx, 0, 0, k.fy, k.cy, 0, 0, 0, 1, 0], float)
    R = np.eye(3).ravel()
    info = T["sensor_msgs/msg/CameraInfo"]
    return info(header(stamp, frame), height, width, "plumb_bob", np.zeros(5), K, R, P, 0, 0, roi)


def depth_image(stamp: float, millimetres: np.ndarray, frame: str = "camera"):
    mm = np.ascontiguousarray(millimetres, dtype="<u2")
    h, w = mm.shape
    data = np.frombuffer(mm.tobytes(), np.uint8)
    return T["sensor_msgs/msg/Image"](header(stamp, frame), h, w, "16UC1", 0, 2 * w, data)


class _Bag:
    def __init__(self, bag: Writer) -> None:
        self.bag, self.conns = bag, {}

    def put(self, topic: str, at: float, msg) -> None:
        kind = msg.__msgtype__
        if topic not in self.conns:
            self.conns[topic] = self.bag.add_connection(topic, kind, typestore=TS)
        self.bag.write(self.conns[topic], round(at * 1e9), TS.serialize_ros1(msg, kind))


def write_cloud_bag(path: str | Path, robots: dict[str, Sequence[Frame]]) -> Path:
    """Each robot's frames as clouds and odometry under ``<prefix>`` ("": no prefix), the
    odometry 1 µs ahead of its cloud."""
    with Writer(path) as bag:
        out = _Bag(bag)
        for prefix, frames in robots.items():
            for f in frames:
                out.put(f"{prefix}/odom", f.stamp - 1e-6, odometry(f.stamp, f.pose))
                out.put(f"{prefix}/camera/depth/points", f.stamp, cloud(f.stamp, f.points))
    return Path(path)


def write_depth_bag(
    path: str | Path,
    frames: Iterable[tuple[float, np.ndarray, np.ndarray]],
    intrinsics: Intrinsics,
    mount: np.ndarray,
) -> Path:
    """(stamp, camera pose 4×4, depth in millimetres (H, W)) frames as depth images with their
    CameraInfo, the base pose (camera pose × mount⁻¹) on /tf and ``mount`` on /tf_static."""
    inverse = np.linalg.inv(mount)
    with Writer(path) as bag:
        out = _Bag(bag)
        for k, (stamp, pose, mm) in enumerate(frames):
            if k == 0:
                out.put("/tf_static", stamp - 1e-3, transform(0.0, "base_link", "camera", mount))
            out.put("/tf", stamp - 2e-6, transform(stamp, "odom", "base_link", pose @ inverse))
            h, w = mm.shape
            out.put("/camera/depth/camera_info", stamp - 1e-6, camera_info(stamp, intrinsics, w, h))
            out.put("/camera/depth/image", stamp, depth_image(stamp, mm))
    return Path(path)
