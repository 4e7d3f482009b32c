"""ROS 1 (.bag) and ROS 2 (folder with metadata.yaml, or a .db3 / .mcap file) recordings.

Read with the pure-Python ``rosbags`` package. Frames are the messages of one
sensor_msgs/PointCloud2 topic; poses come from an odometry-like topic or from the tf tree and
are interpolated to each cloud's header stamp.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Iterator
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_typestore

from gmmap.errors import FileFormatError, InvalidInputError, TopicNotFoundError
from gmmap.io.datasets.base import FrameSequence, crop
from gmmap.math.geometry import interpolate_poses, make_poses

CLOUD = "sensor_msgs/msg/PointCloud2"
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")  # the second in old ROS 1 bags
# Pose-carrying message types and how to reach their geometry_msgs/Pose.
POSE_TYPES: dict[str, Callable[[object], object]] = {
    "nav_msgs/msg/Odometry": lambda m: m.pose.pose,
    "geometry_msgs/msg/PoseStamped": lambda m: m.pose,
    "geometry_msgs/msg/PoseWithCovarianceStamped": lambda m: m.pose.pose,
}
# sensor_msgs/PointField datatype codes → numpy type codes.
FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def bag_paths(path: Path) -> list[Path]:
    """What AnyReader opens: a .bag file, a ROS 2 bag folder, or a bare .db3/.mcap file."""
    if (
        path.is_file()
        and path.suffix in (".db3", ".mcap")
        and (path.parent / "metadata.yaml").is_file()
    ):
        return [path.parent]  # the folder knows about split files and compression
    return [path]


def decode_pointcloud2(msg: object) -> np.ndarray:
    """A sensor_msgs/PointCloud2 → (N, 3) float32 x y z, non-finite points dropped.

    Handles any field offsets and types, ``point_step`` padding, row padding (``row_step``)
    and big-endian data.
    """
    fields = {f.name: f for f in msg.fields}
    missing = [a for a in "xyz" if a not in fields]
    if missing:
        raise FileFormatError(f"PointCloud2 has no {', '.join(missing)} field")
    order = ">" if msg.is_bigendian else "<"
    try:
        formats = [order + FIELD_TYPES[fields[a].datatype] for a in "xyz"]
    except KeyError as exc:
        raise FileFormatError(f"PointCloud2 field of unknown datatype {exc}") from exc
    for a, fmt in zip("xyz", formats, strict=True):
        # Checked here, as numpy would only say "cannot override to smaller itemsize".
        if fields[a].offset + np.dtype(fmt).itemsize > msg.point_step:
            raise FileFormatError(
                f"PointCloud2 field {a} at offset {fields[a].offset} does not fit in "
                f"point_step={msg.point_step}"
            )
    dtype = np.dtype(
        {
            "names": list("xyz"),
            "formats": formats,
            "offsets": [fields[a].offset for a in "xyz"],
            "itemsize": msg.point_step,
        }
    )
    rows = _cloud_rows(np.asarray(msg.data, dtype=np.uint8), msg)
    points = np.frombuffer(rows, dtype=dtype)
    xyz = np.stack([points[a] for a in "xyz"], axis=1).astype(np.float32)
    return xyz[np.isfinite(xyz).all(axis=1)]


def _cloud_rows(data: np.ndarray, msg: object) -> bytes:
    """The point bytes without row padding, after checking the sizes add up."""
    row_bytes = msg.width * msg.point_step
    if msg.point_step <= 0 or msg.row_step < row_bytes:
        raise FileFormatError(
            f"PointCloud2 with point_step={msg.point_step}, row_step={msg.row_step} for "
            f"width={msg.width}"
        )
    if len(data) < msg.height * msg.row_step:
        raise FileFormatError(
            f"truncated PointCloud2: {len(data)} bytes for {msg.height} rows of {msg.row_step}"
        )
    table = data[: msg.height * msg.row_step].reshape(msg.height, msg.row_step)
    return table[:, :row_bytes].tobytes()


def header_stamp(raw: bytes | memoryview, ros2: bool) -> float:
    """The header stamp of a serialised stamped message, without deserialising it.

    ROS 1: uint32 seq, uint32 sec, uint32 nsec (little-endian). CDR: a 4-byte encapsulation
    header (byte 1 odd = little-endian), then int32 sec, uint32 nanosec.
    """
    if len(raw) < 12:
        raise FileFormatError(f"a {len(raw)}-byte message is too short for a header")
    if ros2:
        order = "<" if raw[1] & 1 else ">"
        sec, nsec = struct.unpack_from(order + "iI", raw, 4)
    else:
        sec, nsec = struct.unpack_from("<II", raw, 4)
    return sec + nsec * 1e-9


@dataclass
class Track:
    """A time series of poses (sorted stamps), or one ``static`` pose valid at any time."""

    stamps: np.ndarray
    translations: np.ndarray
    quaternions: np.ndarray
    static: bool = False

    @classmethod
    def from_samples(cls, samples: list[tuple[float, list, list]], static: bool) -> Track:
        """From (stamp, [tx ty tz], [qx qy qz qw]) samples in any order; duplicates: last wins."""
        stamps = np.array([s[0] for s in samples])
        order = np.argsort(stamps, kind="stable")
        keep = np.append(np.diff(stamps[order]) > 0, True)  # last of equal stamps
        idx = order[keep]
        t = np.array([s[1] for s in samples])[idx]
        q = np.array([s[2] for s in samples])[idx]
        return cls(stamps[idx], t, q, static)

    def covers(self, query: np.ndarray) -> np.ndarray:
        if self.static:
            return np.ones(len(query), dtype=bool)
        return (query >= self.stamps[0]) & (query <= self.stamps[-1])

    def at(self, query: np.ndarray) -> np.ndarray:
        if self.static:
            pose = make_poses(self.translations[-1:], self.quaternions[-1:])
            return np.repeat(pose, len(query), axis=0)
        return interpolate_poses(self.stamps, self.translations, self.quaternions, query)


def _vec(v: object) -> list[float]:
    return [v.x, v.y, v.z]


def _quat(q: object) -> list[float]:
    return [q.x, q.y, q.z, q.w]


def _frame_id(name: str) -> str:
    return name.lstrip("/")  # ROS 1 bags often write "/odom"


class RosBag(FrameSequence):
    """A ROS 1 or ROS 2 bag as a lazy sequence of Frames, one per PointCloud2 message.

    At open, only the cloud messages' stamps are read (from the raw header bytes) and the pose
    messages are decoded; each cloud is read from the bag when its frame is accessed. Poses are
    interpolated to the cloud stamps (linear in translation, slerp in rotation); clouds outside
    the poses' time range are dropped. ``gt_pose`` is None. Call ``close()`` (or use ``with``)
    to release the bag's files.

    Options:
        topic: the PointCloud2 topic; default the only one in the bag.
        odom_topic: a nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped
            topic giving sensor→map poses; default the only such topic when ``tf_parent`` is
            not given.
        tf_parent, tf_child: take poses from /tf and /tf_static instead: the chain of
            transforms from ``tf_parent`` (the map or odom frame) down to ``tf_child`` (default
            the clouds' frame_id).
        extrinsic: 4x4 sensor → (odometry child or tf_child) frame, applied on the right
            (default identity), for clouds in a frame other than the pose source's.
        min_range, max_range: keep points at these distances from the sensor (metres).
        voxel: voxel size (metres) for ``gmmap.voxel_filter`` per cloud; None keeps all.
    """

    format = "rosbag"

    def __init__(
        self,
        path: str | Path,
        *,
        topic: str | None = None,
        odom_topic: str | None = None,
        tf_parent: str | None = None,
        tf_child: str | None = None,
        extrinsic: np.ndarray | None = None,
        min_range: float = 0.0,
        max_range: float = math.inf,
        voxel: float | None = None,
    ) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"{self.path}: no such bag")
        self.options = dict(min_range=min_range, max_range=max_range, voxel=voxel)
        self._reader = self._open()
        try:
            self._index(topic, odom_topic, tf_parent, tf_child, extrinsic)
        except BaseException:
            self.close()
            raise

    def _open(self) -> AnyReader:
        try:
            reader = AnyReader(
                bag_paths(self.path), default_typestore=get_typestore(Stores.ROS2_HUMBLE)
            )
            reader.open()
        except AnyReaderError as exc:
            raise FileFormatError(f"{self.path}: unreadable bag ({exc})") from exc
        return reader

    def close(self) -> None:
        """Closes the bag; frames can no longer be read."""
        if self._reader is not None and self._reader.stack is not None:
            self._reader.close()

    def __enter__(self) -> RosBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def topics(self) -> dict[str, str]:
        """Every topic of the bag and its message type."""
        return {name: info.msgtype or "?" for name, info in self._reader.topics.items()}

    def _index(
        self,
        topic: str | None,
        odom_topic: str | None,
        tf_parent: str | None,
        tf_child: str | None,
        extrinsic: np.ndarray | None,
    ) -> None:
        self.topic = self._pick_topic(topic, {CLOUD}, "topic")
        self._clouds = [c for c in self._reader.connections if c.topic == self.topic]
        log_times, ordinals, stamps = self._cloud_stamps()
        if tf_parent is not None:
            child = tf_child or self._cloud_frame()
            self.pose_source = f"tf {tf_parent} -> {child}"
            tracks = self._tf_chain(_frame_id(tf_parent), _frame_id(child))
        else:
            odom_topic = self._pick_topic(odom_topic, set(POSE_TYPES), "odom_topic")
            self.pose_source = odom_topic
            tracks = [self._pose_track(odom_topic)]
        keep = np.logical_and.reduce([t.covers(stamps) for t in tracks])
        if not keep.any():
            raise FileFormatError(
                f"{self.path}: no cloud of {self.topic} lies within the time range of the poses "
                f"({self.pose_source}); cloud stamps {stamps.min():.3f}..{stamps.max():.3f}"
            )
        self.stamps = stamps[keep]
        self._where = list(zip(log_times[keep].tolist(), ordinals[keep].tolist(), strict=True))
        poses = np.tile(np.eye(4), (len(self.stamps), 1, 1))
        for track in tracks:
            poses = poses @ track.at(self.stamps)
        self.poses = poses @ (np.eye(4) if extrinsic is None else np.asarray(extrinsic, float))
        self.gt_poses = None

    def _pick_topic(self, topic: str | None, types: set[str], option: str) -> str:
        """The named topic, checked against ``types``, or the only topic of those types."""
        topics = self.topics
        listing = ", ".join(f"{n} ({t})" for n, t in sorted(topics.items())) or "none"
        if topic is not None:
            if topics.get(topic) not in types:
                what = "absent" if topic not in topics else f"a {topics[topic]}"
                raise TopicNotFoundError(
                    f"{self.path}: {option}={topic!r} is {what}, not a "
                    f"{' / '.join(sorted(types))}; topics: {listing}",
                    topics,
                )
            return topic
        found = sorted(n for n, t in topics.items() if t in types)
        if len(found) != 1:
            raise TopicNotFoundError(
                f"{self.path}: {len(found)} topics of type {' / '.join(sorted(types))}; "
                f"pass {option}= (topics: {listing})"
                + ("; or tf_parent= for poses from /tf" if option == "odom_topic" else ""),
                topics,
            )
        return found[0]

    def _cloud_stamps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Log time, ordinal among equal log times, and header stamp of every cloud."""
        log_times, ordinals, stamps = [], [], []
        for _, log_time, raw in self._reader.messages(connections=self._clouds):
            same = log_times[-1] == log_time if log_times else False
            ordinals.append(ordinals[-1] + 1 if same else 0)
            log_times.append(log_time)
            try:
                stamps.append(header_stamp(raw, self._reader.is2))
            except FileFormatError as exc:
                raise FileFormatError(f"{self.path}: {self.topic}: {exc}") from exc
        if not stamps:
            raise FileFormatError(f"{self.path}: topic {self.topic} has no messages")
        return np.array(log_times, dtype=np.int64), np.array(ordinals), np.array(stamps)

    def _cloud_frame(self) -> str:
        """The frame_id of the first cloud (the default ``tf_child``)."""
        conn, _, raw = next(self._reader.messages(connections=self._clouds))
        return _frame_id(self._reader.deserialize(raw, conn.msgtype).header.frame_id)

    def _messages(self, topics: list[str]) -> Iterator[tuple[str, object]]:
        """Decoded (topic, message) pairs of the given topics, in log-time order."""
        conns = [c for c in self._reader.connections if c.topic in topics]
        for conn, _, raw in self._reader.messages(connections=conns):
            yield conn.topic, self._reader.deserialize(raw, conn.msgtype)

    def _pose_track(self, topic: str) -> Track:
        get_pose = POSE_TYPES[self.topics[topic]]
        samples = []
        for _, msg in self._messages([topic]):
            pose = get_pose(msg)
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            samples.append((stamp, _vec(pose.position), _quat(pose.orientation)))
        if not samples:
            raise FileFormatError(f"{self.path}: pose topic {topic} has no messages")
        return Track.from_samples(samples, static=False)

    def _tf_chain(self, parent: str, child: str) -> list[Track]:
        """The tracks of the transforms from ``parent`` down to ``child``, in order."""
        edges = self._tf_edges()
        up = {c: p for (p, c) in edges}
        chain, frame = [], child
        while frame != parent:
            if frame not in up or len(chain) > len(edges):
                known = ", ".join(f"{p}->{c}" for p, c in sorted(edges)) or "none"
                raise InvalidInputError(
                    f"{self.path}: no tf chain from {parent!r} down to {child!r}; "
                    f"transforms in the bag: {known}"
                )
            chain.append(edges[(up[frame], frame)])
            frame = up[frame]
        return chain[::-1]

    def _tf_edges(self) -> dict[tuple[str, str], Track]:
        tf_topics = [n for n, t in self.topics.items() if t in TF_TYPES]
        samples: dict[tuple[str, str], list] = {}
        static: set[tuple[str, str]] = set()
        for topic, msg in self._messages(tf_topics):
            for tr in msg.transforms:
                key = (_frame_id(tr.header.frame_id), _frame_id(tr.child_frame_id))
                stamp = tr.header.stamp.sec + tr.header.stamp.nanosec * 1e-9
                t = tr.transform
                samples.setdefault(key, []).append((stamp, _vec(t.translation), _quat(t.rotation)))
                if topic.endswith("tf_static"):
                    static.add(key)
        return {k: Track.from_samples(v, k in static) for k, v in samples.items()}

    def _points(self, i: int) -> np.ndarray:
        if self._reader.stack is None:
            raise InvalidInputError(f"{self.path}: the bag is closed")
        log_time, ordinal = self._where[i]
        msgs = self._reader.messages(connections=self._clouds, start=log_time, stop=log_time + 1)
        with closing(msgs):
            for n, (conn, _, raw) in enumerate(msgs):
                if n == ordinal:
                    return self._decode(raw, conn.msgtype, i)
        raise FileFormatError(f"{self.path}: cloud {i} of {self.topic} vanished from the bag")

    def _decode(self, raw: bytes, msgtype: str, i: int) -> np.ndarray:
        try:
            cloud = decode_pointcloud2(self._reader.deserialize(raw, msgtype))
        except (AnyReaderError, FileFormatError) as exc:
            raise FileFormatError(
                f"{self.path}: {self.topic} message at {self.stamps[i]:.6f}: {exc}"
            ) from exc
        return crop(cloud, **self.options)
