"""The station's live view in Rerun (the ``viz`` extra): its recording served to browsers by
the SDK (Rerun's web viewer, connected to a gRPC server in this process) and saved to an .rrd
that ``rerun station.rrd`` replays.

Each `update` logs what changed since the last (new submaps, a new optimisation), in the
reference robot's map frame of each connected group (z up, under ``groups/<reference>``): every
held submap's components as 2-sigma ellipsoids, coloured by robot
(``…/robots/<robot>/components``), at its optimised pose or, until the next optimisation places
it, at its odometry pose (so it shows the moment it arrives; a robot not yet in any group is
shown alone, in its own map frame); each robot's anchors and trajectory; the kept matches as
segments between the two submaps' anchors. Beside them, as time series: per robot the bytes it
sent and, per link, received (``links/received/<robot>/from_<peer>``, as the robots tell the
station: `gmmap.fleet.sharing.linkstats`; the station's own too), and the submaps held. The timeline
is ``wall`` (clock time): the view grows as the fleet maps.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path
from urllib.parse import quote

import numpy as np

from gmmap.errors import GmmapError
from gmmap.io import viz
from gmmap.io.ros2msgs import robot_color

SIGMAS = 2.0


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

        for port, what in ((grpc_port, "--grpc-port"), (web_port, "--web-port")):
            _check_free(host, port, what)
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
        self.first_shown: dict[tuple[str, int], float] = {}  # clock time each first showed
        self._placed: dict[str, str] = {}  # robot → the group path it was last logged under
        # What was last logged, by robot (its submaps) and by group path (its matches), with
        # the backend result it came from: only what changed is logged again.
        self._logged: dict[str, tuple] = {}

    def update(self, node) -> None:
        """Logs ``node``'s state now (a `RobotNode` or `StationNode`)."""
        rr, rec = self._rr, self.rec
        rec.set_time("wall", timestamp=time.time())
        mapper, result = node.mapper, node.mapper.result
        # One C-level copy each (the stages add meanwhile); a station's arrivals too.
        held = {**getattr(node, "arrived", {}).copy(), **mapper.submaps.copy()}
        robots = sorted({r for r, _ in held})
        groups = mapper.frames.groups() if result is not None else []
        grouped = {r for g in groups for r in g}
        groups += [[r] for r in robots if r not in grouped]  # arrived since the optimisation
        shown: set[tuple[str, int]] = set()
        for group in groups:
            shown |= self._group(mapper, result if group[0] in grouped else None, group, held)
        for robot in robots:
            rec.log(f"links/submaps_held/{robot}", rr.Scalars(sum(r == robot for r, _ in held)))
        self._links(node)
        now = time.time()
        for key in shown - self.shown:
            self.first_shown.setdefault(key, now)
        self.shown = shown
        self.updates += 1

    def _links(self, node) -> None:
        """Bytes each robot sent, and received per link (from whom), as the robots last told
        the station (`StationNode.link_counts`), and what the station itself received."""
        rr, rec = self._rr, self.rec
        counts_of = getattr(node, "link_counts", None)  # a StationNode's
        for robot, counts in (counts_of() if counts_of else {}).items():
            if robot != node.robot:
                rec.log(f"links/sent/{robot}", rr.Scalars(sum(counts["sent"].values())))
            for peer, n in counts["received"].items():
                rec.log(f"links/received/{robot}/from_{peer}", rr.Scalars(n))

    def _poses(self, mapper, result, group: list[str], held: dict) -> dict:
        """Each held submap of ``group`` in its reference frame: optimised, or, for one that
        arrived since, its odometry anchor moved by its robot's frame (shown at once)."""
        poses = {}
        for k, s in held.items():
            if k[0] not in group:
                continue
            optimised = None if result is None else result.poses.get(k)
            if optimised is None:
                to_ref = np.eye(4) if result is None else mapper.frames.to_reference(k[0])
                optimised = np.asarray(to_ref) @ s.anchor
            poses[k] = optimised
        return poses

    def _group(self, mapper, result, group: list[str], held: dict) -> set[tuple[str, int]]:
        rr, rec = self._rr, self.rec
        base = f"groups/{group[0] if result is None else mapper.frames.reference(group)}"
        poses = self._poses(mapper, result, group, held)
        for robot in group:
            if self._placed.get(robot, base) != base:  # it joined another group: move it
                rec.log(f"{self._placed[robot]}/robots/{robot}", rr.Clear(recursive=True))
                rec.log(f"{self._placed[robot]}/matches", rr.Clear(recursive=True))
                self._logged.pop(self._placed[robot], None)
            self._placed[robot] = base
            mine = sorted(k for k in poses if k[0] == robot)
            if not self._changed(robot, result, (base, mine)):
                continue
            colour = (np.array(robot_color(robot)) * 255).astype(np.uint8)
            placed = [held[k].gmm.transform(poses[k]) for k in mine]
            ellipsoids = viz.ellipsoids3d(placed, SIGMAS, colors=colour, fill_mode="solid")
            rec.log(f"{base}/robots/{robot}/components", ellipsoids)
            anchors = np.array([poses[k][:3, 3] for k in mine])
            rec.log(
                f"{base}/robots/{robot}/anchors", rr.Points3D(anchors, colors=colour, radii=0.05)
            )
            rec.log(f"{base}/robots/{robot}/trajectory", rr.LineStrips3D([anchors], colors=colour))
        if self._changed(base, result, sorted(poses)):
            kept = [] if result is None else [result.edges[i] for i in result.accepted]
            segments = [
                [poses[a][:3, 3], poses[b][:3, 3]] for a, b in kept if a in poses and b in poses
            ]
            rec.log(f"{base}/matches", rr.LineStrips3D(segments, colors=[255, 255, 255]))
        return set(poses)

    def _changed(self, what: str, result, state) -> bool:
        """Whether ``what`` (a robot, a group path) differs from its last logging: another
        backend result (a new optimisation) or another ``state``; noted as logged now."""
        last = self._logged.get(what)
        if last is not None and last[0] is result and last[1] == state:
            return False
        self._logged[what] = (result, state)
        return True


def _check_free(host: str, port: int | None, what: str) -> None:
    """Rerun's servers fail on a port in use only in their log: say so here, typed."""
    if not port:
        return
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as a server would
        try:
            probe.bind((host, port))
        except OSError as err:
            raise GmmapError(f"{what} {port} on {host} is not free: {err.strerror}") from err


def _layout():
    """The map large on the left; the links' bytes and the submaps held beside it."""
    import rerun.blueprint as rrb

    series = [rrb.TimeSeriesView(origin=f"/links/{what}", name=name)
              for what, name in (("sent", "bytes sent, per robot"),
                                 ("received", "bytes received, per link"),
                                 ("submaps_held", "submaps held"))]  # fmt: skip
    map_view = rrb.Spatial3DView(origin="/groups", name="merged map")
    return rrb.Blueprint(rrb.Horizontal(map_view, rrb.Vertical(*series), column_shares=[3, 1]),
                         collapse_panels=True)  # fmt: skip
