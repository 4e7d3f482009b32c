"""A robot node's ROS 2 side, over Zenoh (``gmmap robot --ros2``): ROS 2 topics in, the merged
map, the frames between robots and a status out (`gmmap.ros_options.RosOptions`).

ROS 2 speaks Zenoh two ways, and both are plain Zenoh key expressions with CDR payloads
(`gmmap.io.ros2`): rmw_zenoh (``<domain>/<topic>/<type>/<hash>``, with an attachment of
sequence number, timestamp and source id) and zenoh-bridge-ros2dds (the topic as the key). The
bridge opens its own Zenoh session to ``ros.connect`` (the ROS graph's router), apart from the
fleet's: ROS traffic never goes on the fleet's links, and the fleet's keys never reach ROS.

In: sensor_msgs/PointCloud2 on ``cloud_topic``, or sensor_msgs/Image depth on ``depth_topic``
with its CameraInfo, → `LiveInput.push_frame`; nav_msgs/Odometry on ``odom_topic``, or
tf2_msgs/TFMessage on /tf and /tf_static: the chain from ``tf_parent`` down to ``tf_child``
(`gmmap.io.tfchain`), → `LiveInput.push_pose`. /tf_static is transient local: the bridge keeps
its last samples in a zenoh-ext publication cache (an AdvancedPublisher), which the node's
history subscriber reads when it starts, so mountings sent before the node started reach it
(tested against the real bridge; against rmw_zenoh's caching, not: there, give such mountings
as ``ros.extrinsic``). A message that does not decode is
counted and dropped. Subscriptions in rmw_zenoh's format take any type hash (a Humble publisher
sends none) and check it where given. Out, every ``publish_every_s``: the group's merged map as
a MarkerArray and as a sampled PointCloud2, the TF tree (`TfGraph`: a spanning tree, never a
loop) and the status. In rmw_zenoh's format the node, its subscriptions and publishers hold
rmw_zenoh's liveliness tokens (`ros2keys.liveliness_token`), so ROS 2 tools list them. The
bridge format is tested against the real zenoh-bridge-ros2dds and CycloneDDS
(tests/test_ros2dds.py); the rmw_zenoh format only against rosbags' serialisation and type
hashes and rmw_zenoh's design document.
"""

from __future__ import annotations

import json
import logging
import os
import re
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import zenoh
import zenoh.ext

from gmmap.errors import InvalidInputError, TransportError
from gmmap.io import ros2
from gmmap.io.tfchain import TfChain
from gmmap.mapping.live import LiveInput
from gmmap.ros_options import RosOptions

log = logging.getLogger(__name__)

MAP_POINTS = 20_000  # points sampled from the merged map for points_topic
TRANSIENT_LOCAL = {"/tf_static"}  # topics whose publishers serve late subscribers


class Bridge:
    """What the ROS 1 and ROS 2 sides share: the live input they feed (by default through
    ``ros.extrinsic``), their counts, and publishing the node's outputs every
    ``publish_every_s`` (`publish`, theirs) from `attach` until `close`."""

    name = "ROS"

    def __init__(self, robot: str, options: RosOptions, live: LiveInput | None = None) -> None:
        if live is None:
            mount = np.eye(4) if options.extrinsic is None else np.asarray(options.extrinsic)
            live = LiveInput(extrinsic=mount)
        self.robot, self.options, self.live = robot, options, live
        self.counts = {"clouds": 0, "poses": 0, "bad": 0, "published": 0}
        # Poses from /tf: the chain down to ros.tf_child, or to the clouds' frame once known.
        o = options
        self.tf = None if o.tf_parent is None else TfChain(o.tf_parent, o.tf_child)
        self._camera: ros2.Camera | None = None  # from CameraInfo, for depth images
        self._stop = threading.Event()

    def _frame(self, stamp: float, frame_id: str, points: np.ndarray) -> None:
        if self.tf is not None and self.tf.child is None:
            self._poses(self.tf.set_child(frame_id))
        # Counted once handed on: a waiter on the counts finds the frame in the live input.
        self.live.push_frame(stamp, points)
        self.counts["clouds"] += 1

    def _pose(self, stamp: float, pose: np.ndarray) -> None:
        self.live.push_pose(stamp, pose)
        self.counts["poses"] += 1

    def _inputs(self) -> list[tuple[str, str, Callable]]:
        """(topic, ROS 2 type name, handler) of every subscription the settings ask for: depth
        images with their CameraInfo or clouds, and /tf with /tf_static or odometry."""
        o = self.options
        if o.depth_topic is not None:
            info = o.camera_info_topic or f"{o.depth_topic.rsplit('/', 1)[0]}/camera_info"
            frames = [(info, ros2.CAMERA_INFO, self._camera_info),
                      (o.depth_topic, ros2.IMAGE, self._depth)]  # fmt: skip
        else:
            frames = [(o.cloud_topic or "/points", ros2.POINTCLOUD2, self._cloud)]
        if o.tf_parent is not None:
            return [*frames, ("/tf", ros2.TF_MESSAGE, self._tf),
                    ("/tf_static", ros2.TF_MESSAGE, self._tf_static)]  # fmt: skip
        return [*frames, (o.odom_topic or "/odom", ros2.ODOMETRY, self._odom)]

    def _intrinsics(self) -> ros2.Camera:
        if self._camera is None:  # no intrinsics yet: nothing to back-project with
            raise InvalidInputError("a depth image before its CameraInfo")
        return self._camera

    def _tf_static(self, msg) -> None:
        self._tf(msg, static=True)

    def _poses(self, poses: list[tuple[float, np.ndarray]]) -> None:
        for stamp, pose in poses:
            self._pose(stamp, pose)

    def _transform(self, parent: str, child: str, stamp: float, T: np.ndarray, static: bool):
        """One transform of /tf (``static``: of /tf_static) into the chain."""
        if self.tf is not None:
            self._poses(self.tf.add(parent, child, stamp, T, static))

    def attach(self, node) -> threading.Thread:
        """Publishes ``node``'s outputs every ``publish_every_s`` until `close`."""

        def run() -> None:
            while not self._stop.wait(self.options.publish_every_s):
                try:
                    self.publish(node)
                except Exception:
                    log.exception("%s: publishing to %s failed", self.robot, self.name)

        thread = threading.Thread(target=run, name=f"gmmap-{self.name}-{self.robot}", daemon=True)
        thread.start()
        return thread

    def publish(self, node) -> None:
        raise NotImplementedError

    def status(self, node) -> dict:
        return {**node.status(), "live": vars(self.live.counts), "ros": dict(self.counts)}

    def close(self) -> None:
        self._stop.set()
        self.live.close()


class Ros2Bridge(Bridge):
    """ROS 2 topics over Zenoh → ``live``, and the node's outputs → ROS 2, for ``robot``."""

    name = "ROS 2"

    def __init__(self, robot: str, options: RosOptions, live: LiveInput | None = None) -> None:
        super().__init__(robot, options, live)
        self._seq = 0
        self._gid = os.urandom(ros2.GID_SIZE)
        self._markers = 0  # markers sent last time: the extra ones are deleted
        cfg = zenoh.Config()
        entries = {"mode": "peer", "connect/endpoints": list(options.connect),
                   "listen/endpoints": [], "scouting/multicast/enabled": False}  # fmt: skip
        for key, value in entries.items():
            cfg.insert_json5(key, json.dumps(value))
        try:
            self.session = zenoh.open(cfg)
        except zenoh.ZError as err:
            raise TransportError(f"cannot open the ROS 2 Zenoh session: {err}") from err
        self.node_name = "gmmap_" + re.sub(r"[^A-Za-z0-9_]", "_", robot)  # a ROS name token
        self._tokens: list = []
        self._declare("NN")
        self._subs = [self._subscribe(*plan) for plan in self._inputs()]
        for topic, typename, depth in self.outputs():
            self._declare("MP", topic, typename, depth)

    def outputs(self) -> list[tuple[str, str, int]]:
        """What `publish` puts: (topic, type, the depth its rmw_zenoh token announces)."""
        o = self.options
        return [(o.map_topic, ros2.MARKER_ARRAY, 1), (o.points_topic, ros2.POINTCLOUD2, 1),
                ("/tf", ros2.TF_MESSAGE, 100), (o.status_topic, ros2.STRING, 1)]  # fmt: skip

    def _declare(self, kind: str, topic: str | None = None, typename: str | None = None,
                 depth: int = 10) -> None:  # fmt: skip
        """An rmw_zenoh liveliness token, by which ROS 2 tools see the node and its topics
        (rmw_zenoh key format only: zenoh-bridge-ros2dds announces DDS endpoints itself)."""
        o = self.options
        if o.key_format != "rmw_zenoh":
            return
        zid, entity = str(self.session.info.zid()), len(self._tokens)
        key = ros2.liveliness_token(zid, 0, entity, kind, self.node_name, topic, typename, depth,
                                    o.domain_id, o.distro)  # fmt: skip
        self._tokens.append(self.session.liveliness().declare_token(key))

    # ---- in ---------------------------------------------------------------------------------

    def _key(self, topic: str, typename: str, subscribe: bool) -> str:
        o = self.options
        if o.key_format == "bridge":
            return ros2.bridge_key(topic)
        if subscribe:
            return ros2.rmw_zenoh_subscription_key(topic, typename, o.domain_id)
        return ros2.rmw_zenoh_key(topic, typename, o.domain_id, o.distro)

    def _subscribe(self, topic: str, typename: str, handle) -> Any:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                key = ros2.parse_key(str(sample.key_expr))
                if key.type_hash not in (None, ros2.HUMBLE_TYPE_HASH) and key.type_hash != (
                    ros2.type_hash(typename, self.options.distro)
                ):
                    raise InvalidInputError(f"{key.topic}: type hash {key.type_hash}")
                handle(sample.payload.to_bytes())
            except InvalidInputError as err:  # RosMessageError among them
                self.counts["bad"] += 1
                log.debug("%s: dropped a ROS message: %s", self.robot, err)

        self._declare("MS", topic, typename, 100 if topic.startswith("/tf") else 10)
        key = self._key(topic, typename, True)
        if topic in TRANSIENT_LOCAL:
            # The bridge keeps a transient-local topic's last samples in a zenoh-ext
            # publication cache: a history subscriber reads them when it starts.
            history = zenoh.ext.HistoryConfig(detect_late_publishers=True)
            return zenoh.ext.declare_advanced_subscriber(
                self.session, key, on_sample, history=history
            )
        return self.session.declare_subscriber(key, on_sample)

    def _cloud(self, data: bytes) -> None:
        self._push(ros2.decode_pointcloud2(data, self.options.distro))

    def _push(self, cloud: ros2.Cloud) -> None:
        self._frame(cloud.stamp, cloud.frame_id, cloud.points)

    def _camera_info(self, data: bytes) -> None:
        self._camera = ros2.decode_camera_info(data, self.options.distro)

    def _depth(self, data: bytes) -> None:
        o = self.options
        self._push(ros2.decode_depth_image(data, self._intrinsics(), o.depth_stride, o.distro))

    def _odom(self, data: bytes) -> None:
        p = ros2.decode_odometry(data, self.options.distro)
        self._pose(p.stamp, p.pose)

    def _tf(self, data: bytes, static: bool = False) -> None:
        for p in ros2.decode_tf(data, self.options.distro):
            self._transform(p.parent, p.child, p.stamp, p.pose, static)

    # ---- out --------------------------------------------------------------------------------

    def publish(self, node) -> None:
        """The merged map, the TF tree and the status, once."""
        o, d, now = self.options, self.options.distro, time.time()
        gmap = node.global_map()
        if gmap is not None:
            frame = f"{gmap.reference}/map"
            markers = ros2.encode_markers(gmap.gmm, self.robot, frame, now,
                                          previous=self._markers, distro=d)  # fmt: skip
            self._markers = len(gmap.gmm)
            self._put(o.map_topic, ros2.MARKER_ARRAY, markers)
            points = gmap.sample(MAP_POINTS)
            self._put(
                o.points_topic, ros2.POINTCLOUD2, ros2.encode_pointcloud2(points, frame, now, d)
            )
        tree = tf_tree(node, now)
        if tree:
            self._put("/tf", ros2.TF_MESSAGE, ros2.encode_tf(tree, d))
        self._put(o.status_topic, ros2.STRING, ros2.encode_status(self.status(node), d))

    def _put(self, topic: str, typename: str, payload: bytes) -> None:
        self._seq += 1
        attachment = None
        if self.options.key_format == "rmw_zenoh":
            a = ros2.Attachment(self._seq, time.time_ns(), self._gid)
            attachment = ros2.encode_attachment(a)
        self.session.put(self._key(topic, typename, False), payload, attachment=attachment)
        self.counts["published"] += 1

    def close(self) -> None:
        super().close()
        for token in self._tokens:
            token.undeclare()
        self.session.close()


def tf_tree(node, stamp: float) -> list[tuple[str, str, np.ndarray, float]]:
    """Each robot's map frame under its group's reference robot's: a star per group."""
    mapper = node.mapper
    if mapper.result is None:
        return []
    frames = mapper.frames
    return [
        (f"{frames.reference(r)}/map", f"{r}/map", np.asarray(frames.to_reference(r)), stamp)
        for r in frames.robots
        if frames.reference(r) != r
    ]
