"""The station's live view in Rerun (the ``viz`` extra): its recording served to browsers by
the SDK (Rerun's web viewer, connected to a gRPC server in this process) and saved to an .rrd
that ``rerun station.rrd`` replays.

Each `update` logs, in the reference robot's map frame of each connected group (z up, under
``groups/<reference>``): every held submap's components as 2-sigma ellipsoids, coloured by
robot (``…/robots/<robot>/components``); each robot's anchors and trajectory; the kept
matches as segments between the two submaps' anchors. Beside them, as time series per robot,
the submaps held and the bytes the station received from it (``links/…/<robot>``). The timeline
is ``wall`` (clock time): the view grows as the fleet maps.
"""

from __future__ import annotations

import time
from pathlib import Path
from urllib.parse import quote

import numpy as np
from scipy.spatial.transform import Rotation

from gmmap.errors import GmmapError
from gmmap.io import viz
from gmmap.io.ros2msgs import robot_color

SIGMAS = 2.0


def _ellipsoids(gmms: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres, half sizes and quaternions (x, y, z, w) of the components of ``gmms``."""
    means = np.concatenate([g.means for g in gmms])
    covariances = np.concatenate([g.covariances for g in gmms])
    eigval, eigvec = np.linalg.eigh(covariances)
    eigvec[np.linalg.det(eigvec) < 0, :, 0] *= -1  # a rotation, not a reflection
    half = SIGMAS * np.sqrt(np.maximum(eigval, 0))
    return means, half, Rotation.from_matrix(eigvec).as_quat()


class LiveView:
    """A Rerun recording of a watched fleet, served on ``grpc_port`` (the data) and
    ``web_port`` (the viewer; None: no viewer, the data only) and saved to ``save``."""

    def __init__(
        self,
        name: str,
        grpc_port: int = 9876,
        web_port: int | None = 9090,
        save: str | Path | None = None,
        host: str = "127.0.0.1",
    ) -> None:
        if not viz.available():
            raise GmmapError("Rerun is not installed: pip install 'gmmap[viz]' (rerun-sdk)")
        import rerun as rr

        self._rr = rr
        self.rec = rr.RecordingStream(f"gmmap-station-{name}")
        server = rr.GrpcServerSink(bind_ip=host, port=grpc_port)
        sinks = [server] if save is None else [server, rr.FileSink(str(save))]
        self.rec.set_sinks(*sinks, default_blueprint=_layout())
        self.data_url = server.uri
        self.url = None
        if web_port is not None:
            rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=server.uri)
            self.url = f"http://{host}:{web_port}/?url={quote(server.uri, safe='')}"
        self.rec.log("groups", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.updates = 0
        self.shown: set[tuple[str, int]] = set()  # the submaps the last update showed

    def update(self, node) -> None:
        """Logs ``node``'s state now (a `RobotNode` or `StationNode`)."""
        rr, rec = self._rr, self.rec
        rec.set_time("wall", timestamp=time.time())
        mapper, result = node.mapper, node.mapper.result
        shown: set[tuple[str, int]] = set()
        if result is not None:
            for group in mapper.frames.groups():
                shown |= self._group(mapper, result, group)
        stats = node.transport.stats().get("received", {})
        keys = list(mapper.submaps.copy())
        for robot in sorted({r for r, _ in keys}):
            held = sum(1 for r, _ in keys if r == robot)
            got = sum(k.get("payload_bytes", 0) for k in stats.get(robot, {}).values())
            rec.log(f"links/submaps_held/{robot}", rr.Scalars(held))
            rec.log(f"links/bytes_received/{robot}", rr.Scalars(got))
        self.shown = shown
        self.updates += 1

    def _group(self, mapper, result, group: list[str]) -> set[tuple[str, int]]:
        rr, rec = self._rr, self.rec
        base = f"groups/{mapper.frames.reference(group)}"
        poses = {k: P for k, P in result.poses.items() if k[0] in group}
        everything = mapper.submaps.copy()  # one C-level copy: the matching stage adds meanwhile
        held = {k: s for k, s in everything.items() if k in poses}
        for robot in group:
            mine = sorted(k for k in held if k[0] == robot)
            if not mine:
                continue
            colour = (np.array(robot_color(robot)) * 255).astype(np.uint8)
            centres, half, quats = _ellipsoids([held[k].gmm.transform(poses[k]) for k in mine])
            quaternions = [rr.Quaternion(xyzw=q) for q in quats]
            rec.log(f"{base}/robots/{robot}/components", rr.Ellipsoids3D(
                centers=centres, half_sizes=half, quaternions=quaternions, colors=colour,
                fill_mode="solid"))  # fmt: skip
            anchors = np.array([poses[k][:3, 3] for k in mine])
            rec.log(
                f"{base}/robots/{robot}/anchors", rr.Points3D(anchors, colors=colour, radii=0.05)
            )
            rec.log(f"{base}/robots/{robot}/trajectory", rr.LineStrips3D([anchors], colors=colour))
        kept = [result.edges[i] for i in result.accepted]
        segments = [
            [poses[a][:3, 3], poses[b][:3, 3]] for a, b in kept if a in poses and b in poses
        ]
        rec.log(f"{base}/matches", rr.LineStrips3D(segments, colors=[255, 255, 255]))
        return set(held)


def _layout():
    """The map large on the left; the links' bytes and the submaps held beside it."""
    import rerun.blueprint as rrb

    series = [rrb.TimeSeriesView(origin=f"/links/{what}", name=name)
              for what, name in (("bytes_received", "bytes received"),
                                 ("submaps_held", "submaps held"))]  # fmt: skip
    map_view = rrb.Spatial3DView(origin="/groups", name="merged map")
    return rrb.Blueprint(rrb.Horizontal(map_view, rrb.Vertical(*series), column_shares=[3, 1]),
                         collapse_panels=True)  # fmt: skip
