"""A robot node's ROS 1 side (``gmmap robot --ros1``), through Debian's ROS 1 (``make ros1``:
ros-core, python3-rospy and the message packages, for the system Python 3.11).

The same inputs and outputs as the ROS 2 side (`gmmap.io.ros2bridge`,
`gmmap.ros_options.RosOptions`): sensor_msgs/PointCloud2 on ``cloud_topic``, or depth
sensor_msgs/Image on ``depth_topic`` with its CameraInfo, and nav_msgs/Odometry on
``odom_topic`` (or, with ``tf_parent``, the chain of /tf and /tf_static down to ``tf_child``:
`gmmap.io.tfchain`) in; the merged map as a MarkerArray of ellipsoids and a sampled
PointCloud2, the TF tree between the robots' maps on /tf and a JSON status out. rospy runs the
node against the ROS master of ``ROS_MASTER_URI``; /tf_static is latched there, so a node
started late still gets the mountings.
"""

from __future__ import annotations

import json
import logging
import sys
import threading
import time
from types import SimpleNamespace

import numpy as np

from gmmap.errors import FileFormatError, InvalidInputError
from gmmap.io import ros2msgs
from gmmap.io.datasets.rosbag import decode_pointcloud2
from gmmap.io.ros2bridge import MAP_POINTS, Bridge, tf_tree
from gmmap.io.ros2msgs import camera_of, depth_points, ellipsoids, pose_matrix, robot_color
from gmmap.mapping.live import LiveInput
from gmmap.math.geometry import matrix_to_quaternion
from gmmap.ros_options import RosOptions

log = logging.getLogger(__name__)

ROS1_PYTHON = "/usr/lib/python3/dist-packages"  # where Debian's python3-rospy lives
SETUP = "make ros1 (apt-get install ros-core python3-rospy python3-sensor-msgs ...)"


def rospy():
    """rospy, from Debian's packages where the environment lacks it; ImportError naming the
    set-up otherwise."""
    try:
        import rospy as ros
    except ImportError:
        if ROS1_PYTHON not in sys.path:
            sys.path.append(ROS1_PYTHON)  # after the venv's own: its packages stay first
        try:
            import rospy as ros
        except ImportError as err:
            raise ImportError(f"ROS 1 is not installed: {SETUP}") from err
    return ros


def available() -> bool:
    try:
        rospy()
    except ImportError:
        return False
    return True


class Ros1Bridge(Bridge):
    """ROS 1 topics → ``live``, and the node's outputs → ROS 1, for ``robot``."""

    name = "ROS 1"

    def __init__(self, robot: str, options: RosOptions, live: LiveInput | None = None) -> None:
        super().__init__(robot, options, live)
        ros = rospy()
        from nav_msgs.msg import Odometry
        from sensor_msgs.msg import CameraInfo, Image, PointCloud2
        from std_msgs.msg import String
        from tf2_msgs.msg import TFMessage
        from visualization_msgs.msg import MarkerArray

        ros.init_node(f"gmmap_{robot}", anonymous=False, disable_signals=True)
        self._ros = ros
        self._first = threading.Lock()  # guards _camera against _early, the image before it
        self._early = None
        o = options
        kinds = {ros2msgs.CAMERA_INFO: CameraInfo, ros2msgs.IMAGE: Image,
                 ros2msgs.POINTCLOUD2: PointCloud2, ros2msgs.ODOMETRY: Odometry,
                 ros2msgs.TF_MESSAGE: TFMessage}  # fmt: skip
        self._subs = [ros.Subscriber(topic, kinds[kind], self._safe(handle))
                      for topic, kind, handle in self._inputs()]  # fmt: skip
        self._pubs = {
            "map": ros.Publisher(o.map_topic, MarkerArray, queue_size=1, latch=True),
            "points": ros.Publisher(o.points_topic, PointCloud2, queue_size=1, latch=True),
            "tf": ros.Publisher("/tf", TFMessage, queue_size=10),
            "status": ros.Publisher(o.status_topic, String, queue_size=1, latch=True),
        }
        self._markers = 0

    def _safe(self, handle):
        def callback(msg) -> None:
            try:
                handle(msg)
            except (InvalidInputError, FileFormatError) as err:
                self.counts["bad"] += 1
                log.debug("%s: dropped a ROS message: %s", self.robot, err)

        return callback

    def _cloud(self, msg) -> None:
        view = SimpleNamespace(**{k: getattr(msg, k) for k in msg.__slots__})
        view.data = np.frombuffer(msg.data, np.uint8)  # rospy gives bytes
        self._frame(msg.header.stamp.to_sec(), msg.header.frame_id, decode_pointcloud2(view))

    def _camera_info(self, msg) -> None:
        with self._first:
            self._camera = camera_of(msg, msg.K)
            early, self._early = self._early, None
        if early is not None:
            self._depth(early)

    def _depth(self, msg) -> None:
        # rospy delivers each topic on its own connection and thread: a camera's first image
        # may come before its first CameraInfo. It waits for it (the latest such image only).
        with self._first:
            if self._camera is None:
                self._early = msg
                return
        points = depth_points(msg, self._intrinsics(), self.options.depth_stride)
        self._frame(msg.header.stamp.to_sec(), msg.header.frame_id, points)

    def _odom(self, msg) -> None:
        p = msg.pose.pose
        pose = pose_matrix(p.position, p.orientation, "Odometry pose")
        self._pose(msg.header.stamp.to_sec(), pose)

    def _tf(self, msg, static: bool = False) -> None:
        for t in msg.transforms:
            parent, child, r = t.header.frame_id, t.child_frame_id, t.transform
            pose = pose_matrix(r.translation, r.rotation, f"tf {parent}->{child}")
            self._transform(parent, child, t.header.stamp.to_sec(), pose, static)

    def publish(self, node) -> None:
        """The merged map, the TF tree and the status, once."""
        from std_msgs.msg import String
        from tf2_msgs.msg import TFMessage

        now = time.time()
        gmap = node.global_map()
        if gmap is not None:
            frame = f"{gmap.reference}/map"
            self._pubs["map"].publish(self._marker_array(gmap.gmm, frame))
            self._pubs["points"].publish(self._cloud_of(gmap.sample(MAP_POINTS), frame))
        tree = tf_tree(node, now)
        if tree:
            self._pubs["tf"].publish(TFMessage([self._stamped(*t) for t in tree]))
        self._pubs["status"].publish(String(json.dumps(self.status(node), sort_keys=True)))
        self.counts["published"] += 1

    def _header(self, frame: str):
        from std_msgs.msg import Header

        return Header(stamp=self._ros.Time.now(), frame_id=frame)

    def _marker_array(self, gmm, frame: str):
        from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
        from std_msgs.msg import ColorRGBA
        from visualization_msgs.msg import Marker, MarkerArray

        quats, sizes = ellipsoids(gmm)
        r, g, b = robot_color(self.robot)
        header, markers = self._header(frame), []
        for k, (mean, q, size) in enumerate(zip(gmm.means, quats, sizes, strict=True)):
            pose = Pose(Point(*map(float, mean)), Quaternion(*map(float, q)))
            markers.append(Marker(header=header, ns=self.robot, id=k, type=Marker.SPHERE,
                                  action=Marker.ADD, pose=pose, scale=Vector3(*map(float, size)),
                                  color=ColorRGBA(r, g, b, 0.5)))  # fmt: skip
        for k in range(len(gmm), self._markers):  # those a smaller map no longer has
            markers.append(Marker(header=header, ns=self.robot, id=k, action=Marker.DELETE))
        self._markers = len(gmm)
        return MarkerArray(markers)

    def _cloud_of(self, points: np.ndarray, frame: str):
        from sensor_msgs import point_cloud2

        return point_cloud2.create_cloud_xyz32(self._header(frame), points.tolist())

    def _stamped(self, parent: str, child: str, T: np.ndarray, _stamp: float):
        from geometry_msgs.msg import Quaternion, Transform, TransformStamped, Vector3

        q = matrix_to_quaternion(T[None, :3, :3])[0]
        transform = Transform(Vector3(*map(float, T[:3, 3])), Quaternion(*map(float, q)))
        return TransformStamped(self._header(parent), child, transform)

    def close(self) -> None:
        super().close()
        for sub in self._subs:
            sub.unregister()
        self._ros.signal_shutdown("gmmap robot ends")
