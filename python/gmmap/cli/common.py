"""What the commands share: the configuration options, progress output and frame selection."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np

from gmmap.config import Config, load_config
from gmmap.fleet_options import PROTOCOLS
from gmmap.options import SENSORS, RosOptions, drift_overrides

SEP = "__"  # a flag's parameter name is its config key with '.' → '__'


def log(msg: str) -> None:
    click.echo(msg, err=True)


def _default(key: str) -> Any:
    section, name = key.split(".")
    return getattr(getattr(Config(), section), name)


def setting(flag: str, key: str, help: str, **kw: Any):
    """A flag that overrides one configuration key (it defaults to the config's value)."""
    default = _default(key)
    shown = ",".join(map(str, default)) if isinstance(default, tuple) else default
    return click.option(
        flag, key.replace(".", SEP), default=None, help=f"{help}  [{key}: {shown}]", **kw
    )


def config_option(fn: Callable) -> Callable:
    """``--config FILE`` (the tree flags override) and ``--odometry-drift`` where the command
    has a backend; the command receives ``config`` (a `Config`) instead of the flags."""

    @click.option(
        "--config",
        "config_path",
        type=click.Path(exists=True, dir_okay=False, path_type=Path),
        help="A YAML configuration (see gmmap config --dump); flags override it.",
    )
    @functools.wraps(fn)
    def wrapper(config_path: Path | None, **kw: Any):
        # An option with multiple=True that was not given arrives as (): not an override.
        given = {k: kw.pop(k) for k in list(kw) if SEP in k}
        overrides = {k.replace(SEP, "."): v for k, v in given.items() if v != ()}
        drift = kw.pop("odometry_drift", None)
        if drift is not None:
            overrides.update({f"backend.{k}": v for k, v in drift_overrides(drift).items()})
        return fn(config=load_config(config_path).override(overrides), **kw)

    return wrapper


def odometry_drift_option(fn: Callable) -> Callable:
    return click.option(
        "--odometry-drift",
        type=float,
        help="The pose graph's odometry noise per metre (backend.translation, rotation_per_rad; "
        "a quarter in rotation_per_m). 0.002 for motion-capture poses.  "
        f"[backend.translation: {_default('backend.translation')}]",
    )(fn)


def frame_options(fn: Callable) -> Callable:
    """--frames START:STOP and --max-frames, given to the command as one ``select`` function."""

    @click.option("--frames", "frame_range", help="Use only frames START:STOP (e.g. :400, 400:).")
    @click.option("--max-frames", type=int, help="Use only the first frames (after --frames).")
    @functools.wraps(fn)
    def wrapper(frame_range: str | None, max_frames: int | None, **kw: Any):
        return fn(pick=lambda frames: pick_frames(frames, frame_range, max_frames), **kw)

    return wrapper


def pick_frames(frames, frame_range: str | None, max_frames: int | None):
    """Frames START:STOP of a lazy sequence, then the first ``max_frames``, still lazy."""
    chosen = range(len(frames))[_slice(frame_range)] if frame_range else range(len(frames))
    return Frames(frames, chosen[:max_frames] if max_frames else chosen)


class Frames:
    """Frames ``indices`` of a lazy sequence, itself a lazy sequence."""

    def __init__(self, frames, indices: range) -> None:
        self.frames, self.indices = frames, indices

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int):
        return self.frames[self.indices[i]]

    def __iter__(self):
        return (self.frames[i] for i in self.indices)


def _slice(text: str) -> slice:
    try:
        parts = [int(p) if p.strip() else None for p in text.split(":")]
    except ValueError:
        parts = []
    if len(parts) != 2:
        raise click.BadParameter(f"{text!r} is not START:STOP", param_hint="--frames")
    return slice(*parts)


def open_data(
    path: Path,
    stride: int | None = None,
    ros: RosOptions | None = None,
    format: str | None = None,
    **options,
):
    """The dataset at ``path`` (``format``: None, detected); a ROS bag with the topics and
    frames of ``ros`` (the config's ``ros`` section, `gmmap.ros_options.RosOptions`)."""
    from gmmap.io import datasets

    if ros is not None and (format or datasets.detect_format(path)) == "rosbag":
        options = {**ros.bag_options(), **options}
    given = {"stride": stride} if stride else {}
    return datasets.open(path, format=format, **given, **options)


ROS_SETTINGS = (
    setting("--cloud-topic", "ros.cloud_topic", "ROS bag: the PointCloud2 topic."),
    setting("--odom-topic", "ros.odom_topic", "ROS bag: the odometry or pose topic."),
    setting("--tf-parent", "ros.tf_parent", "ROS bag: poses from /tf, from this frame down."),
    setting("--tf-child", "ros.tf_child", "ROS bag: ...to this frame (default the clouds')."),
)


def ros_settings(fn: Callable) -> Callable:
    for option in reversed(ROS_SETTINGS):
        fn = option(fn)
    return fn


SIM_SETTINGS = (
    setting(
        "--world", "sim.world", "A built-in world, random-office:<seed> or a world .json file."
    ),
    setting("--robots", "sim.robots", "Simulated robots.", type=int),
    setting("--seed", "sim.seed", "Sensor noise and odometry seed.", type=int),
    setting(
        "--sensor",
        "sim.sensor",
        "16-beam LiDAR or 60° depth camera.",
        type=click.Choice(SENSORS),
    ),
    setting("--sim-width", "sim.width", "Depth camera image width (px, 4:3).", type=int),
    setting("--rate", "sim.rate", "Frames per second.", type=float),
    setting("--speed", "sim.speed", "Driving speed (m/s).", type=float),
    setting(
        "--beams",
        "sim.beams",
        "LiDAR channels over ±lidar-fov of elevation.",
        type=click.IntRange(1),
    ),
    setting("--lidar-fov", "sim.lidar_fov", "LiDAR elevation field, ± degrees.", type=float),
    setting("--sway", "sim.sway", "Carrier roll and pitch, ± degrees (handheld).", type=float),
    setting("--sim-drift", "sim.drift", "Simulated odometry error per metre.", type=float),
    setting(
        "--sim-pace",
        "sim.pace",
        "Frames due at this many times the simulated rate (unset: as fast as mapped).",
        type=float,
    ),
)


# Settings several commands share.
SUBMAP_SIZE = (
    setting(
        "--frames-per-submap",
        "build.frames_per_submap",
        "Frames per submap (with a distance or an angle: the most).",
        type=int,
    ),
    setting(
        "--submap-distance",
        "build.submap_distance",
        "Close a submap after this much odometry path (m; 0: off).",
        type=float,
    ),
    setting(
        "--submap-angle",
        "build.submap_angle",
        "Close a submap after turning this much (degrees; 0: off).",
        type=float,
    ),
)


def submap_size(fn: Callable) -> Callable:
    """The flags that say when a submap closes: by frame count, by space or both."""
    for option in reversed(SUBMAP_SIZE):
        fn = option(fn)
    return fn


COVARIANCE = setting(
    "--covariance", "build.covariance", "Covariance type.", type=click.Choice(["diag", "full"])
)
MIN_MATCHES = setting(
    "--min-matches",
    "backend.min_matches",
    "Consistent matches before two robots' maps join.",
    type=click.IntRange(min=1),
)
BUDGET = setting(
    "--budget",
    "robot.budget",
    "Bytes/s of payload the robot puts on each link, newest submaps first.",
    type=float,
)
BUNDLE = setting(
    "--bundle",
    "robot.bundle",
    "Own submaps sent together, each waiting up to robot.bundle_wait s (unset: 3, or 1 on "
    "the demo's rendezvous links).",
    type=click.IntRange(min=1),
)
PROTOCOL = setting(
    "--protocol",
    "transport.protocol",
    "Zenoh over tcp, or udp datagrams: no ACKs or handshakes, what a lost datagram carried is "
    "fetched again; not secured (unset: tcp, or udp on the demo's rendezvous links).",
    type=click.Choice(PROTOCOLS),
)
BROADCAST = setting(
    "--broadcast",
    "transport.broadcast",
    "UDP multicast group of a radio channel the fleet shares (udp/224.0.0.224:7447): submaps "
    "and adverts go on the air once for all; fetches stay unicast.",
)
CHANNEL_RATE = setting(
    "--channel-rate",
    "transport.channel_rate",
    "Bytes/s of the radio channel all robots share; each robot sends within an equal share.",
    type=float,
)
DESCRIPTOR = setting(
    "--descriptor",
    "place.descriptor",
    "Place descriptor: training-free shape, or learned PointNetVLAD.",
    type=click.Choice(["shape", "learned"]),
)
MIN_CONFIDENCE = setting(
    "--min-confidence", "place.min_confidence", "C_thr of the verification.", type=float
)


def sim_settings(fn: Callable) -> Callable:
    for option in reversed(SIM_SETTINGS):
        fn = option(fn)
    return fn


def as_json_option(fn: Callable) -> Callable:
    return click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")(fn)


def save_trajectories(mapper, folder: Path, prefix: str = "") -> list[Path]:
    """Every held robot's optimised anchor trajectory, in its group's reference frame, as a
    TUM file ``<prefix>trajectory_<robot>.txt`` (stamp: the anchor frame's; evo reads it)."""
    from gmmap.io.datasets.trajectory import write_trajectory

    result = mapper.result
    if result is None:
        return []
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for robot in sorted({r for r, _ in mapper.submaps}):
        subs = sorted((s for (r, _), s in mapper.submaps.items() if r == robot), key=_seq)
        poses = np.array([result.poses[(robot, s.seq)] for s in subs])
        path = folder / f"{prefix}trajectory_{robot}.txt"
        header = f"gmmap: {robot}'s anchors in {mapper.frames.reference(robot)}'s frame"
        write_trajectory(path, anchor_stamps(subs), poses, header=header)
        written.append(path)
    return written


def _seq(submap) -> int:
    return submap.seq


def anchor_stamps(submaps) -> np.ndarray:
    """Each submap's anchor stamp: its first frame's (the anchor is that frame's pose)."""
    return np.array([float(s.stamps[0]) if len(s.stamps) else float(s.seq) for s in submaps])
