"""A stand-in ROS 2 node on real DDS: what rmw_cyclonedds puts on the wire for a node's
publishers and subscriptions, made with the `cyclonedds` package.

A ROS 2 topic ``/name`` is the DDS topic ``rt/name`` with the rosidl type names of
`gmmap.eval.ros2dds.messages`. A bridge or a ROS 2 tool learns which node owns which reader
and writer from ``ros_discovery_info`` (``ParticipantEntitiesInfo``: the participant's GID and,
per node, its readers' and writers' GIDs, each the first 16 bytes of the entity's DDS GUID),
which rmw publishes reliably and transient-local whenever an entity comes or goes;
zenoh-plugin-ros2dds routes only the entities listed there. QoS as rclcpp's profiles:
`SENSOR_DATA` (best effort, keep last 5), `DEFAULT` (reliable, keep last 10), `TF_STATIC`
(reliable, transient local, keep last 1).

The participant lives on loopback only (`LOCALHOST`: no multicast, localhost as the one
peer), as the bridge is told to with the same configuration.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from cyclonedds.core import Listener, Qos
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from gmmap.eval.ros2dds import messages as m
from gmmap.eval.ros2dds.bridge import LOCALHOST
from gmmap.math.geometry import matrix_to_quaternion

SENSOR_DATA = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
DEFAULT = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
TF_STATIC = Qos(
    Policy.Reliability.Reliable(duration(seconds=1)),
    Policy.Durability.TransientLocal,
    Policy.History.KeepLast(1),
)
DISCOVERY = TF_STATIC  # rmw's QoS for ros_discovery_info
FLOAT32 = 7  # sensor_msgs/PointField's datatype


_domains: dict[int, Domain] = {}  # one per id and process: DDS refuses a second


def gid(entity: Any) -> m.Gid:
    """An entity's ROS GID: its DDS GUID's 16 bytes."""
    return m.Gid(list(entity.guid.bytes))


class StandInNode:
    """One ROS 2 node on its own DDS participant in ``domain``: `publisher` and `subscription`
    create the DDS writer or reader of a ROS 2 topic and announce it on ros_discovery_info."""

    def __init__(self, name: str, domain: int, namespace: str = "/") -> None:
        if domain not in _domains:
            _domains[domain] = Domain(domain, LOCALHOST)
        self.participant = DomainParticipant(domain)
        self.name, self.namespace = name, namespace
        self._readers: list[m.Gid] = []
        self._writers: list[m.Gid] = []
        self._topics: dict[str, Topic] = {}
        self._entities: list = []  # cyclonedds deletes an entity once Python drops it
        topic = Topic(self.participant, "ros_discovery_info", m.ParticipantEntitiesInfo)
        self._discovery = DataWriter(self.participant, topic, DISCOVERY)
        self._lock = threading.Lock()

    def _topic(self, name: str, datatype: type) -> Topic:
        if name not in self._topics:
            self._topics[name] = Topic(self.participant, "rt" + name, datatype)
        return self._topics[name]

    def publisher(self, topic: str, datatype: type, qos: Qos = DEFAULT) -> DataWriter:
        writer = DataWriter(self.participant, self._topic(topic, datatype), qos)
        with self._lock:
            self._entities.append(writer)
            self._writers.append(gid(writer))
            self._announce()
        return writer

    def subscription(
        self,
        topic: str,
        datatype: type,
        qos: Qos = DEFAULT,
        callback: Callable[[Any], None] | None = None,
    ) -> DataReader:
        """A reader of ``topic``; ``callback`` (if any) gets every sample, on DDS's thread."""
        listener = None
        if callback is not None:

            def on_data_available(reader: DataReader) -> None:
                for sample in reader.take(N=100):
                    callback(sample)

            listener = Listener(on_data_available=on_data_available)
        reader = DataReader(self.participant, self._topic(topic, datatype), qos, listener)
        with self._lock:
            self._entities.append(reader)
            self._readers.append(gid(reader))
            self._announce()
        return reader

    def _announce(self) -> None:
        readers, writers = list(self._readers), list(self._writers)
        node = m.NodeEntitiesInfo(self.namespace, self.name, readers, writers)
        self._discovery.write(m.ParticipantEntitiesInfo(gid(self.participant), [node]))

    def close(self) -> None:
        """Leaves the DDS domain (its readers, writers and discovery go with it)."""
        self.participant = None  # cyclonedds deletes entities when they are collected
        self._entities.clear()
        self._topics.clear()
        self._discovery = None

    def __enter__(self) -> StandInNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def matched(writer: DataWriter, timeout: float = 10.0) -> bool:
    """Waits until ``writer`` has a matched reader (a bridge's route): a sample before that
    goes nowhere. True when it has one."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if writer.get_matched_subscriptions():
            return True
        time.sleep(0.05)
    return False


def stamp(seconds: float) -> m.Time:
    sec = int(seconds)
    return m.Time(sec, round((seconds - sec) * 1e9))


def point_cloud(points: np.ndarray, frame_id: str, seconds: float) -> m.PointCloud2:
    """An unorganised x, y, z float32 cloud, as a LiDAR driver publishes one."""
    data = np.ascontiguousarray(points, dtype="<f4")
    fields = [m.PointField(name, 4 * i, FLOAT32, 1) for i, name in enumerate("xyz")]
    return m.PointCloud2(
        m.Header(stamp(seconds), frame_id), 1, len(data), fields, False, 12, 12 * len(data),
        data.tobytes(), True,
    )  # fmt: skip


def pose(T: np.ndarray) -> m.Pose:
    q = matrix_to_quaternion(np.asarray(T)[None, :3, :3])[0]
    return m.Pose(m.Point(*map(float, T[:3, 3])), m.Quaternion(*map(float, q)))


def odometry(T: np.ndarray, seconds: float, frame_id: str = "odom", child: str = "base_link"):
    """A nav_msgs/Odometry of pose ``T`` (4×4) in ``frame_id``."""
    return m.Odometry(m.Header(stamp(seconds), frame_id), child, m.PoseWithCovariance(pose(T)))


def transforms(edges: list[tuple[str, str, np.ndarray]], seconds: float) -> m.TFMessage:
    """A tf2_msgs/TFMessage of (parent, child, 4×4 child-in-parent) edges."""
    out = []
    for parent, child, T in edges:
        p = pose(T)
        t = m.Transform(m.Vector3(p.position.x, p.position.y, p.position.z), p.orientation)
        out.append(m.TransformStamped(m.Header(stamp(seconds), parent), child, t))
    return m.TFMessage(out)
