"""The ROS section of the configuration (`gmmap.config`, re-exported by `gmmap.options`): which
topics and frames a robot maps from a bag or live over ROS 1 or 2, and where it publishes its map.
Like `gmmap.options`, nothing heavy is imported here, and each field's meaning is its ``#:``
comment.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gmmap.errors import InvalidInputError

KEY_FORMATS = ("rmw_zenoh", "bridge")
DISTROS = ("humble", "jazzy", "kilted")


@dataclass(frozen=True)
class RosOptions:
    """Which ROS topics and frames a robot maps, in a recorded bag (`gmmap.io.datasets.RosBag`)
    and live. ``cloud_topic``: the sensor_msgs/PointCloud2 topic (None: a bag's only one).
    Poses from ``odom_topic`` (nav_msgs/Odometry, geometry_msgs/PoseStamped or
    PoseWithCovarianceStamped; None: a bag's only one), or, with ``tf_parent``, from /tf and
    /tf_static: the chain from ``tf_parent`` (the odom or map frame) down to ``tf_child`` (None:
    the clouds' frame). ``extrinsic``: the sensor in that frame (4×4 rows; None: identity).

    Live over ROS 2 (``gmmap robot --ros2``, `gmmap.io.ros2bridge`): the topics in ``key_format``
    ``rmw_zenoh`` (ROS ``domain_id``, type hashes of ``distro``) or ``bridge``
    (zenoh-bridge-ros2dds: the topic name as the key), on a Zenoh session connecting to
    ``connect`` (rmw_zenoh's router listens on tcp/127.0.0.1:7447); live, ``cloud_topic`` and
    ``odom_topic`` default to /points and /odom; with ``depth_topic``, depth images (16UC1 or
    32FC1, every ``depth_stride``-th pixel) with the intrinsics of ``camera_info_topic``
    (default: camera_info beside the depth topic) instead of clouds; with ``tf_parent``, poses
    from the chain of /tf and /tf_static as in bags (`gmmap.io.tfchain`). Out, every
    ``publish_every_s``: the merged map on ``map_topic`` (MarkerArray of ellipsoids) and
    ``points_topic`` (PointCloud2 sampled from it), the frames between the robots' maps on /tf
    (a spanning tree: ``<reference>/map`` → ``<robot>/map``), and a JSON status on
    ``status_topic``. Live over ROS 1 (``gmmap robot --ros1``, `gmmap.io.ros1bridge`): the same
    topics, frames and outputs, through the ROS master."""

    cloud_topic: str | None = None  #: The PointCloud2 topic; null: a bag's only one (live: /points)
    odom_topic: str | None = None  #: Odometry or pose topic; null: a bag's only one (live: /odom)
    tf_parent: str | None = None  #: Poses from /tf: the chain from this frame (odom or map) down
    tf_child: str | None = None  #: ... to this frame; null: the clouds' frame
    #: The sensor in that frame, 4×4 rows; null: identity
    extrinsic: tuple[tuple[float, ...], ...] | None = None
    depth_topic: str | None = None  #: Live: depth images (16UC1, 32FC1) on this topic, not clouds
    camera_info_topic: str | None = None  #: Depth intrinsics; null: camera_info beside depth_topic
    depth_stride: int = 4  #: Live: every this-many-th pixel of a depth image is used
    key_format: str = "rmw_zenoh"  #: ROS 2: rmw_zenoh keys, or bridge (zenoh-bridge-ros2dds)
    distro: str = "jazzy"  #: Live over ROS 2 with rmw_zenoh: the distro whose type hashes are used
    domain_id: int = 0  #: Live over ROS 2 with rmw_zenoh: the ROS domain id
    #: Live over ROS 2: Zenoh endpoints to connect to (rmw_zenoh's router)
    connect: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    map_topic: str = "/gmmap/map"  #: Out: the merged map, a MarkerArray of ellipsoids
    points_topic: str = "/gmmap/map_points"  #: Out: a PointCloud2 sampled from the merged map
    status_topic: str = "/gmmap/status"  #: Out: a JSON status
    publish_every_s: float = 2.0  #: Seconds between outputs

    def __post_init__(self) -> None:
        if self.extrinsic is not None:
            T = np.asarray(self.extrinsic, dtype=float)
            R = T[:3, :3] if T.shape == (4, 4) else np.zeros((3, 3))
            rigid = np.allclose(R @ R.T, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0
            if not (rigid and np.isfinite(T).all() and np.allclose(T[3], [0, 0, 0, 1])):
                raise InvalidInputError(f"ros.extrinsic must be a rigid 4x4 transform: {T}")
        if self.tf_child is not None and self.tf_parent is None:
            raise InvalidInputError("ros.tf_child needs ros.tf_parent (poses from /tf)")
        if self.key_format not in KEY_FORMATS or self.distro not in DISTROS:
            raise InvalidInputError(f"ros.key_format in {KEY_FORMATS}, ros.distro in {DISTROS}")
        if isinstance(self.depth_stride, bool) or not 1 <= self.depth_stride <= 64:
            raise InvalidInputError(f"ros.depth_stride must be 1..64, got {self.depth_stride}")
        if not (0 <= self.domain_id <= 232 and self.publish_every_s > 0):
            raise InvalidInputError("ros.domain_id must be in 0..232, publish_every_s > 0")

    def bag_options(self) -> dict[str, Any]:
        """The `RosBag` options these settings give (those set)."""
        extrinsic = None if self.extrinsic is None else np.asarray(self.extrinsic, dtype=float)
        given = {
            "topic": self.cloud_topic,
            "odom_topic": self.odom_topic,
            "tf_parent": self.tf_parent,
            "tf_child": self.tf_child,
            "extrinsic": extrinsic,
        }
        return {k: v for k, v in given.items() if v is not None}
