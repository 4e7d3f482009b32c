"""ROS 2 messages in and out of gmmap as CDR bytes (the payload of a Zenoh sample, from either
rmw_zenoh or zenoh-bridge-ros2dds), through rosbags' typestore of the robot's distro.

In: sensor_msgs/PointCloud2 and depth sensor_msgs/Image (+ CameraInfo) as points,
nav_msgs/Odometry and tf2_msgs/TFMessage as 4x4 poses. Out: visualization_msgs/MarkerArray
(one ellipsoid per Gaussian), PointCloud2, TFMessage and a JSON std_msgs/String status.
Every decoder raises `RosMessageError` for bytes it cannot use, never anything else.
Stamps are float seconds (header sec + nanosec); frame ids are returned as sent.
"""

from __future__ import annotations

import json
import math
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from gmmap.errors import FileFormatError, InvalidInputError, RosMessageError
from gmmap.io.datasets.rosbag import decode_pointcloud2 as cloud_points
from gmmap.io.ros2keys import typestore
from gmmap.math.geometry import make_poses, matrix_to_quaternion, rigid_matrix
from gmmap.math.gmm import Gmm
from gmmap.math.points import as_points

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
ODOMETRY = "nav_msgs/msg/Odometry"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
STRING = "std_msgs/msg/String"

# Depth encodings (REP-118): numpy type and the factor to metres.
DEPTH_ENCODINGS = {"16UC1": ("u2", 1e-3), "32FC1": ("f4", 1.0)}
# Robot colours (RGB), picked by a stable hash of the robot name.
PALETTE = (
    (0.12, 0.47, 0.71),
    (1.00, 0.50, 0.05),
    (0.17, 0.63, 0.17),
    (0.84, 0.15, 0.16),
    (0.58, 0.40, 0.74),
    (0.55, 0.34, 0.29),
    (0.89, 0.47, 0.76),
    (0.09, 0.75, 0.81),
)
MARKER_ALPHA = 0.5
MIN_MARKER_SCALE = 1e-3  # metres: RViz draws nothing for a zero-size axis (flat Gaussians)


class Cloud(NamedTuple):
    """Points (N, 3) float32, all finite, in frame ``frame_id`` at ``stamp`` (s)."""

    stamp: float
    frame_id: str
    points: np.ndarray


class StampedPose(NamedTuple):
    """``pose`` (4x4) of frame ``child`` in frame ``parent`` at ``stamp`` (s)."""

    stamp: float
    parent: str
    child: str
    pose: np.ndarray


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics (pixels) of a depth camera; ``width``/``height`` 0 accept any image."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 0
    height: int = 0
    frame_id: str = ""

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy)
        if not all(math.isfinite(v) for v in values) or self.fx <= 0 or self.fy <= 0:
            raise InvalidInputError(f"camera intrinsics must be finite with fx, fy > 0: {values}")


# --- decoding --------------------------------------------------------------------------------


def _deserialize(data: bytes | bytearray | memoryview, typename: str, distro: str) -> Any:
    store = typestore(distro)
    try:
        return store.deserialize_cdr(memoryview(data), typename)
    # rosbags raises SerdeError for most bad bytes, but hostile input must never take the robot
    # node down with something else (IndexError, numpy errors, …), so every failure is typed.
    except Exception as exc:
        raise RosMessageError(f"not a valid {typename} ({distro}): {exc}") from exc


def _stamp(t: Any) -> float:
    return t.sec + t.nanosec * 1e-9


def pose_matrix(position: Any, rotation: Any, what: str) -> np.ndarray:
    """A 4x4 pose from a geometry_msgs Point/Vector3 and Quaternion (normalised here)."""
    t = np.array([[position.x, position.y, position.z]], dtype=np.float64)
    q = np.array([[rotation.x, rotation.y, rotation.z, rotation.w]], dtype=np.float64)
    if not (np.isfinite(t).all() and np.isfinite(q).all()) or np.linalg.norm(q) < 1e-6:
        raise RosMessageError(f"{what}: non-finite position or no valid quaternion {q[0]}")
    return make_poses(t, q)[0]


def decode_pointcloud2(data: bytes | bytearray | memoryview, distro: str = "jazzy") -> Cloud:
    """A PointCloud2 → its finite x y z points (any FLOAT32/FLOAT64/integer field types and
    offsets, point and row padding, big-endian data; the decoding the bag reader uses)."""
    msg = _deserialize(data, POINTCLOUD2, distro)
    try:
        points = cloud_points(msg)
    except (FileFormatError, ValueError) as exc:
        raise RosMessageError(f"PointCloud2: {exc}") from exc
    return Cloud(_stamp(msg.header.stamp), msg.header.frame_id, points)


def decode_camera_info(data: bytes | bytearray | memoryview, distro: str = "jazzy") -> Camera:
    """A CameraInfo → its intrinsics (`camera_of`)."""
    msg = _deserialize(data, CAMERA_INFO, distro)
    return camera_of(msg, msg.k)


def camera_of(msg: Any, K: Any) -> Camera:
    """The intrinsics of a CameraInfo message of ROS 1 or 2 (``K``: its ``K`` or ``k``).
    Distortion is ignored (the back-projection assumes a rectified depth image); binning, a
    partial ROI or a skewed K are refused, not misapplied."""
    K = np.asarray(K, dtype=np.float64)
    roi = msg.roi
    full_roi = roi.width in (0, msg.width) and roi.height in (0, msg.height)
    if msg.binning_x > 1 or msg.binning_y > 1 or roi.x_offset or roi.y_offset or not full_roi:
        raise RosMessageError("CameraInfo with binning or a region of interest is not supported")
    if K.shape != (9,) or K[1] != 0.0:
        raise RosMessageError(f"CameraInfo K must be a pinhole matrix without skew: {K.tolist()}")
    try:
        fx, fy, cx, cy = (float(K[i]) for i in (0, 4, 2, 5))
        return Camera(fx, fy, cx, cy, msg.width, msg.height, msg.header.frame_id)
    except InvalidInputError as exc:  # an all-zero K: the camera is not calibrated
        raise RosMessageError(f"CameraInfo: {exc}") from exc


def decode_depth_image(
    data: bytes | bytearray | memoryview, camera: Camera, stride: int = 1, distro: str = "jazzy"
) -> Cloud:
    """A depth Image → its points (`depth_points`)."""
    msg = _deserialize(data, IMAGE, distro)
    points = depth_points(msg, camera, stride)
    return Cloud(_stamp(msg.header.stamp), msg.header.frame_id, points)


def depth_points(msg: Any, camera: Camera, stride: int = 1) -> np.ndarray:
    """A depth Image message of ROS 1 or 2 (16UC1 millimetres or 32FC1 metres) → float32
    points in the camera optical frame (x right, y down, z forward), one per ``stride``-th
    pixel of every ``stride``-th row; pixels without depth (0, NaN, inf, negative) are
    skipped."""
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
        raise InvalidInputError(f"stride must be an integer >= 1, got {stride!r}")
    if camera.width and (msg.width, msg.height) != (camera.width, camera.height):
        raise RosMessageError(
            f"depth image is {msg.width}x{msg.height}, its CameraInfo {camera.width}x"
            f"{camera.height}"
        )
    z = _depth_metres(msg)[::stride, ::stride]
    v, u = np.mgrid[0 : msg.height : stride, 0 : msg.width : stride]
    ok = np.isfinite(z) & (z > 0)
    z = z[ok]
    x = (u[ok] - camera.cx) * z / camera.fx
    y = (v[ok] - camera.cy) * z / camera.fy
    return np.stack([x, y, z], 1).astype(np.float32)


def _depth_metres(msg: Any) -> np.ndarray:
    """(height, width) float64 depths in metres, after checking the sizes add up."""
    if msg.encoding not in DEPTH_ENCODINGS:
        raise RosMessageError(
            f"depth image encoding {msg.encoding!r} is not supported (16UC1 mm or 32FC1 m)"
        )
    code, scale = DEPTH_ENCODINGS[msg.encoding]
    dtype = np.dtype(code).newbyteorder(">" if msg.is_bigendian else "<")
    row_bytes = msg.width * dtype.itemsize
    raw = msg.data  # rosbags: a uint8 array; rospy: bytes
    data = np.frombuffer(raw, np.uint8) if isinstance(raw, bytes) else np.asarray(raw, np.uint8)
    if msg.step < row_bytes or len(data) < msg.height * msg.step:
        raise RosMessageError(
            f"depth image of {len(data)} bytes for {msg.height} rows of step {msg.step} "
            f"({msg.width} {msg.encoding} pixels)"
        )
    rows = data[: msg.height * msg.step].reshape(msg.height, msg.step)[:, :row_bytes]
    depth = np.ascontiguousarray(rows).view(dtype).reshape(msg.height, msg.width)
    return depth.astype(np.float64) * scale


def decode_odometry(data: bytes | bytearray | memoryview, distro: str = "jazzy") -> StampedPose:
    """An Odometry → the pose of ``child_frame_id`` in ``header.frame_id`` (covariance and
    twist dropped)."""
    msg = _deserialize(data, ODOMETRY, distro)
    pose = msg.pose.pose
    matrix = pose_matrix(pose.position, pose.orientation, "Odometry pose")
    return StampedPose(_stamp(msg.header.stamp), msg.header.frame_id, msg.child_frame_id, matrix)


def decode_tf(data: bytes | bytearray | memoryview, distro: str = "jazzy") -> list[StampedPose]:
    """A TFMessage (/tf or /tf_static) → one StampedPose per transform, in message order."""
    msg = _deserialize(data, TF_MESSAGE, distro)
    out = []
    for tr in msg.transforms:
        parent, child = tr.header.frame_id, tr.child_frame_id
        r = tr.transform
        matrix = pose_matrix(r.translation, r.rotation, f"tf {parent}->{child}")
        out.append(StampedPose(_stamp(tr.header.stamp), parent, child, matrix))
    return out


def decode_status(data: bytes | bytearray | memoryview, distro: str = "jazzy") -> Any:
    """The JSON value of a std_msgs/String status (the inverse of `encode_status`)."""
    text = _deserialize(data, STRING, distro).data
    try:
        return json.loads(text)
    except ValueError as exc:
        raise RosMessageError(f"status String is not JSON: {exc}") from exc


# --- encoding --------------------------------------------------------------------------------


def _serialize(msg: Any, typename: str, distro: str) -> bytes:
    return bytes(typestore(distro).serialize_cdr(msg, typename))


def _time(types: Any, stamp: float) -> Any:
    """builtin_interfaces/Time from float seconds (0 ≤ stamp < 2³¹, int32 seconds)."""
    try:
        stamp = float(stamp)
    except (TypeError, ValueError):
        stamp = math.nan
    if not 0 <= stamp < 2**31:  # also refuses NaN
        raise InvalidInputError(f"stamp must be seconds in [0, 2**31), got {stamp!r}")
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)
    if nanosec >= 1_000_000_000:  # rounding carried into the next second
        sec, nanosec = sec + 1, nanosec - 1_000_000_000
    return types["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec))


def _header(types: Any, frame_id: str, stamp: float) -> Any:
    if not isinstance(frame_id, str):
        raise InvalidInputError(f"frame_id must be a string, got {frame_id!r}")
    return types["std_msgs/msg/Header"](stamp=_time(types, stamp), frame_id=frame_id)


def encode_pointcloud2(
    points: object, frame_id: str, stamp: float = 0.0, distro: str = "jazzy"
) -> bytes:
    """(N, 3) finite points → an unorganised PointCloud2 of x y z FLOAT32, little-endian."""
    pts = as_points(points, allow_empty=True).astype("<f4")
    T = typestore(distro).types
    field = T["sensor_msgs/msg/PointField"]
    fields = [field(name=a, offset=4 * i, datatype=7, count=1) for i, a in enumerate("xyz")]
    msg = T[POINTCLOUD2](
        header=_header(T, frame_id, stamp),
        height=1,
        width=len(pts),
        fields=fields,
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(pts),
        data=np.frombuffer(pts.tobytes(), dtype=np.uint8),
        is_dense=True,  # as_points refused non-finite points
    )
    return _serialize(msg, POINTCLOUD2, distro)


def encode_tf(transforms: Iterable[tuple[str, str, object, float]], distro: str = "jazzy") -> bytes:
    """(parent, child, 4x4 pose of child in parent, stamp) tuples → a TFMessage."""
    T = typestore(distro).types
    out = []
    for item in transforms:
        if not isinstance(item, tuple | list) or len(item) != 4:
            raise InvalidInputError(f"a transform is (parent, child, 4x4, stamp), got {item!r}")
        parent, child, pose, stamp = item
        M = rigid_matrix(pose, f"transform {parent}->{child}")
        q = matrix_to_quaternion(M[None, :3, :3])[0]
        transform = T["geometry_msgs/msg/Transform"](
            translation=T["geometry_msgs/msg/Vector3"](*M[:3, 3].tolist()),
            rotation=T["geometry_msgs/msg/Quaternion"](*q.tolist()),
        )
        out.append(
            T["geometry_msgs/msg/TransformStamped"](
                header=_header(T, parent, stamp), child_frame_id=child, transform=transform
            )
        )
    return _serialize(T[TF_MESSAGE](transforms=out), TF_MESSAGE, distro)


def encode_status(status: object, distro: str = "jazzy") -> bytes:
    """A JSON-serialisable status (keys sorted, strict JSON: no NaN) → a std_msgs/String."""
    try:
        text = json.dumps(status, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"status is not JSON-serialisable: {exc}") from exc
    T = typestore(distro).types
    return _serialize(T[STRING](data=text), STRING, distro)


def robot_color(robot: str) -> tuple[float, float, float]:
    """The palette colour of a robot: crc32 of its name (stable across runs, unlike hash())."""
    return PALETTE[zlib.crc32(robot.encode()) % len(PALETTE)]


def ellipsoids(gmm: Gmm, sigma: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """(K, 4) orientations (qx qy qz qw) and (K, 3) diameters of each component's ``sigma``
    ellipsoid: the covariance's eigenvectors (made a proper rotation) and 2·sigma·√eigenvalue."""
    quaternions, half_sizes = gmm.ellipsoids(sigma)
    return quaternions, np.maximum(2.0 * half_sizes, MIN_MARKER_SCALE)


def encode_markers(
    gmm: Gmm,
    robot: str,
    frame_id: str,
    stamp: float = 0.0,
    *,
    sigma: float = 2.0,
    previous: int = 0,
    color: tuple[float, float, float] | None = None,
    distro: str = "jazzy",
) -> bytes:
    """A MarkerArray drawing ``gmm`` as SPHERE markers scaled to each component's ``sigma``
    ellipsoid, ns ``robot``, ids 0…K−1, in the robot's palette colour (or ``color``).

    ``previous``: how many markers the last array for this robot had; ids K…previous−1 are
    sent as DELETE so a map that shrank leaves no stale ellipsoids. Stamp 0 (the default) makes
    RViz use the latest transform of ``frame_id``.
    """
    if not isinstance(robot, str) or not robot:
        raise InvalidInputError(f"robot must be a non-empty name, got {robot!r}")
    if not (isinstance(sigma, int | float) and math.isfinite(sigma) and sigma > 0):
        raise InvalidInputError(f"sigma must be a positive number, got {sigma!r}")
    T = typestore(distro).types
    header = _header(T, frame_id, stamp)
    rgba = T["std_msgs/msg/ColorRGBA"](*(color or robot_color(robot)), MARKER_ALPHA)
    quats, diameters = ellipsoids(gmm, sigma)
    markers = []
    for i in range(len(gmm)):
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](*gmm.means[i].tolist()),
            orientation=T["geometry_msgs/msg/Quaternion"](*quats[i].tolist()),
        )
        scale = T["geometry_msgs/msg/Vector3"](*diameters[i].tolist())
        markers.append(_marker(T, header, robot, i, 0, pose, scale, rgba))  # 0: ADD
    for i in range(len(gmm), previous):
        markers.append(_marker(T, header, robot, i, 2, None, None, rgba))  # 2: DELETE
    return _serialize(T[MARKER_ARRAY](markers=markers), MARKER_ARRAY, distro)


def _marker(
    T: Any, header: Any, ns: str, marker_id: int, action: int, pose: Any, scale: Any, rgba: Any
) -> Any:
    """A SPHERE Marker (type 2) with every unused field empty."""
    empty = np.zeros(0, dtype=np.uint8)
    return T["visualization_msgs/msg/Marker"](
        header=header,
        ns=ns,
        id=marker_id,
        type=2,
        action=action,
        pose=pose
        or T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](0.0, 0.0, 0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0),
        ),
        scale=scale or T["geometry_msgs/msg/Vector3"](1.0, 1.0, 1.0),
        color=rgba,
        lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),  # 0: forever
        frame_locked=False,
        points=[],
        colors=[],
        texture_resource="",
        texture=T["sensor_msgs/msg/CompressedImage"](header=header, format="", data=empty),
        uv_coordinates=[],
        text="",
        mesh_resource="",
        mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=empty),
        mesh_use_embedded_materials=False,
    )
