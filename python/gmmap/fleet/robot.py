"""A robot node (paper IV): three concurrent stages fed by queues, sharing only encoded submaps.

Stages, each a thread:

- **construction**: frames → `SubmapBuilder` → `gmmap.encode` → own store → publish (kind
  "submap"). The node works on what it sent: the decoded copy of its own submap, the same bytes
  every other robot sees, goes on to place recognition.
- **transmission**: the transport's subscription (and fetch replies) → inbox queue → decode →
  store → place recognition against the submaps of *other* robots held (a new own submap is
  queried against received ones, a received one against everything not of its robot) →
  verification by registration → edges stored (accepted or rejected; a judged pair is never
  registered again) → optimisation queue.
- **optimisation**: one incremental `PoseGraph` over every held submap (received submaps carry
  their anchors, so each robot's odometry chain is known) and the accepted matches → optimize →
  `TfGraph`; the latest groups and ``to_reference`` frames are kept for status and the report.

Persistence: the store holds own and received submaps, edges, and in ``meta`` how many input
frames the construction stage had consumed when it emitted its last submap. A restarted node
reloads all of it, continues its own sequence after its last seq, skips the frames already
turned into submaps, and re-uses the judged pairs. On a peer's join it fetches, for every robot
it knows of, what it misses (from the first gap, else from the latest seq + 1); it serves fetches
from its store, so a robot that was away catches up from whoever is present.

Shutdown: `RobotNode.stop` (called on SIGINT/SIGTERM by `run_robot`) stops taking frames,
drops what is still queued (everything is in the store, so a restart recovers it), joins the
stages, and closes the transport and the store.
"""

from __future__ import annotations

import contextlib
import json
import logging
import queue
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gmmap.fleet.codec import DecodeError, decode, encode
from gmmap.fleet.store import Edge, Store
from gmmap.fleet.transport import Transport, TransportConfig
from gmmap.mapping.backend import BackendOptions, BackendResult, PoseGraph
from gmmap.mapping.frame import Frame
from gmmap.mapping.place import PlaceDatabase, PlaceOptions
from gmmap.mapping.submap import BuildOptions, Submap, SubmapBuilder
from gmmap.mapping.tfgraph import TfGraph

try:
    import resource
except ImportError:  # Windows: no getrusage
    resource = None  # type: ignore[assignment]

__all__ = ["RobotConfig", "RobotNode", "run_robot"]

log = logging.getLogger(__name__)

KIND = "submap"
META_FRAMES = "frames_consumed"

Status = Callable[[dict], None]


@dataclass
class RobotConfig:
    """What a node needs besides its frames. ``store`` None: a temporary store (lost on exit).
    ``wait_for``: peers to wait for (up to ``wait_timeout`` s) before consuming frames."""

    robot: str
    fleet: str
    store: Path | None = None
    listen: tuple[str, ...] | None = None
    port: int = 0
    connect: tuple[str, ...] = ()
    build: BuildOptions = field(default_factory=lambda: BuildOptions(frames_per_submap=20))
    place: PlaceOptions = field(default_factory=PlaceOptions)
    backend: BackendOptions = field(default_factory=BackendOptions)
    linger: float = 5.0
    wait_for: tuple[str, ...] = ()
    wait_timeout: float = 30.0
    fetch_timeout: float = 2.0


class RobotNode:
    """One robot: ``start()``, feed it with ``run(frames)`` (or ``start_frames``), ``stop()``."""

    def __init__(self, config: RobotConfig, status: Status | None = None) -> None:
        self.config = config
        self.robot = config.robot
        self._status = status
        self._tmp: tempfile.TemporaryDirectory | None = None
        path = config.store
        if path is None:
            self._tmp = tempfile.TemporaryDirectory(prefix=f"gmmap-{config.robot}-")
            path = Path(self._tmp.name) / "store.sqlite"
        self.store = Store(path)
        self.db = PlaceDatabase(options=config.place)
        self.inbox: queue.Queue = queue.Queue()
        self.opt_queue: queue.Queue = queue.Queue()
        self.fetch_queue: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._frames_done = threading.Event()
        self._threads: list[threading.Thread] = []
        self._held: dict[tuple[str, int], Submap] = {}  # decoded, own and received
        self._judged: set[frozenset] = set()
        self._busy = 0  # items taken from the inbox and not finished
        self.result: BackendResult | None = None
        self.tf: TfGraph | None = None
        self._arrived: dict[str, set[int]] = {}  # seqs received per robot, stored or queued
        self._graph_edges: dict[int, Edge] = {}  # backend edge id → the stored registration
        self.gt_anchors: dict[int, np.ndarray] = {}  # own submaps' ground truth, evaluation only
        self.counts = dict(built=0, sent=0, received=0, fetched=0, decode_errors=0, optimised=0)
        self.wire: dict[int, dict] = {}  # own seq → bytes
        self.frames_consumed = int(self.store.get_meta(META_FRAMES, "0") or 0)
        self._reload()
        self.transport = Transport(
            TransportConfig(
                fleet=config.fleet,
                robot=config.robot,
                listen=config.listen,
                port=config.port,
                connect=config.connect,
                fetch_timeout=config.fetch_timeout,
            )
        )

    # ---- persistence ------------------------------------------------------------------------

    def _reload(self) -> None:
        """Own and received submaps and the judged edges from the store (a restart)."""
        for rec in self.store.submaps():
            try:
                s = decode(rec.payload)
            except DecodeError:
                log.warning(
                    "%s: stored %s/%d does not decode; dropped", self.robot, rec.robot, rec.seq
                )
                continue
            self._hold(s)
            if rec.own:
                self.wire[s.seq] = _sizes(s, len(rec.payload), None)
        for e in self.store.edges():
            self._judged.add(
                frozenset({(e.target_robot, e.target_seq), (e.source_robot, e.source_seq)})
            )
            if e.status == "accepted":
                self.opt_queue.put(("edge", e))
        self.reloaded = len(self._held)

    def _hold(self, s: Submap) -> None:
        key = (s.robot, s.seq)
        self._held[key] = s
        self.db.add(s.robot, s.seq, s.gmm)
        self.opt_queue.put(("submap", s.robot, s.seq, s.anchor))

    # ---- lifecycle --------------------------------------------------------------------------

    def start(self) -> None:
        t = self.transport
        t.serve(self._serve, self.store.robots)
        t.subscribe(lambda robot, kind, seq, payload: self._receive(robot, kind, seq, payload))
        t.on_join(lambda robot: self.fetch_queue.put(robot))
        for name, target in (
            ("match", self._transmission),
            ("optimise", self._optimisation),
            ("fetch", self._fetcher),
        ):
            th = threading.Thread(target=target, name=f"gmmap-{self.robot}-{name}", daemon=True)
            th.start()
            self._threads.append(th)

    def start_frames(self, frames: Sequence[Frame]) -> threading.Thread:
        th = threading.Thread(
            target=self._construction,
            args=(frames,),
            name=f"gmmap-{self.robot}-build",
            daemon=True,
        )
        th.start()
        self._threads.append(th)
        return th

    def run(self, frames: Sequence[Frame]) -> dict:
        """Start, consume ``frames``, linger, and return the report (the node stays open)."""
        self.start()
        self.start_frames(frames).join()
        self.linger(self.config.linger)
        return self.report()

    def linger(self, seconds: float) -> None:
        """Keep receiving, matching and optimising for ``seconds`` after the frames are done
        (a catch-up fetch at the start and half-way), then wait for the queues to drain."""
        if self._stopping.is_set():
            return
        deadline = time.monotonic() + seconds
        self._catch_up()
        half = time.monotonic() + seconds / 2
        caught = False
        while not self._stopping.is_set() and time.monotonic() < deadline:
            if not caught and time.monotonic() >= half:
                self._catch_up()
                caught = True
            time.sleep(0.05)
        if not self._stopping.is_set():
            self.drain(timeout=max(5.0, seconds))

    def drain(self, timeout: float = 10.0) -> bool:
        """Wait until inbox, fetches and optimisation are idle (True) or ``timeout`` s pass."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not self._stopping.is_set():
            with self._lock:
                busy = self._busy
            if (
                busy == 0
                and self.inbox.empty()
                and self.fetch_queue.empty()
                and self.opt_queue.empty()
                and not self._optimising
            ):
                return True
            time.sleep(0.02)
        return False

    _optimising = False
    _closed = False

    def stop(self) -> None:
        """Stop the stages (queued work is dropped: it is in the store), close transport/store."""
        if self._closed:
            return
        self._closed = True
        self._stopping.set()
        for q in (self.inbox, self.opt_queue, self.fetch_queue):
            q.put(None)
        self.transport.close()
        for th in self._threads:
            if th is not threading.current_thread():
                th.join(timeout=10)
        self.store.close()
        if self._tmp is not None:
            self._tmp.cleanup()

    # ---- construction -----------------------------------------------------------------------

    def _construction(self, frames: Sequence[Frame]) -> None:
        try:
            builder = SubmapBuilder(self.robot, self.config.build)
            last = self.store.latest_seq(self.robot)
            builder.seq = 0 if last is None else last + 1
            i = self.frames_consumed
            while i < len(frames) and not self._stopping.is_set():
                s = builder.add(frames[i])
                i += 1
                if s is not None:
                    self._emit(s, i)
            if not self._stopping.is_set() and i > self.frames_consumed:
                s = builder.flush()
                if s is not None:
                    self._emit(s, i)
        except Exception:
            log.exception("%s: construction failed", self.robot)
        finally:
            self._frames_done.set()

    def _emit(self, s: Submap, consumed: int) -> None:
        payload = encode(s)
        self.store.put_submap(self.robot, s.seq, payload, own=True)
        self.store.set_meta(META_FRAMES, str(consumed))
        self.frames_consumed = consumed
        self.counts["built"] += 1
        self.wire[s.seq] = _sizes(s, len(payload), s.n_points)
        if s.gt_anchor is not None:
            self.gt_anchors[s.seq] = s.gt_anchor
        self.transport.publish(KIND, s.seq, payload)
        self.counts["sent"] += 1
        with self._lock:
            self._busy += 1
        self.inbox.put(("own", self.robot, s.seq, payload))

    # ---- transmission -----------------------------------------------------------------------

    def _receive(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        if kind == KIND:
            with self._lock:
                self._busy += 1
                self._arrived.setdefault(robot, set()).add(seq)
            self.inbox.put(("received", robot, seq, payload))

    def _serve(self, robot: str, kind: str, since: int) -> list[tuple[int, bytes]]:
        """A fetch is answered by the submaps' owner while it is present, else by every robot
        holding them: N robots answering every query would send each submap N - 1 times."""
        if robot != self.robot and robot in self.transport.peers():
            return []
        return self.store.fetch_provider(robot, kind, since)

    def _fetcher(self) -> None:
        while not self._stopping.is_set():
            peers = {self.fetch_queue.get()}
            # One round covers every robot known: joins queued meanwhile need no round of their own.
            with contextlib.suppress(queue.Empty):
                while True:
                    peers.add(self.fetch_queue.get_nowait())
            if None in peers:
                return
            with contextlib.suppress(Exception):
                self._fetch_for(peers)

    def _catch_up(self) -> None:
        for peer in self.transport.peers():
            self.fetch_queue.put(peer)

    def _fetch_for(self, peers: set[str]) -> None:
        """Fetch what we miss of ``peers`` and of every other robot we know (its owner answers,
        or, when the owner is away, whoever holds it)."""
        robots = (peers | set(self.store.robots())) - {self.robot}
        for r in sorted(robots):
            if self._stopping.is_set():
                return
            # What arrived counts, stored or still queued: asking again for submaps waiting in
            # the inbox of a busy robot would have them sent twice.
            stored = set(self.store.seqs(r))  # read outside the lock the receivers take
            with self._lock:
                have = stored | self._arrived.get(r, set())
            gaps = [seq for seq in range(max(have) + 1) if seq not in have] if have else []
            since = gaps[0] if gaps else (max(have) + 1 if have else 0)
            for seq, payload in self.transport.fetch(r, KIND, since):
                self._enqueue_fetched(r, seq, payload)
        # Robots no one present has named: those that left before we came.
        for r, held in self.transport.fetch_unknown(robots | {self.robot}, KIND).items():
            for seq, payload in held:
                self._enqueue_fetched(r, seq, payload)

    def _enqueue_fetched(self, robot: str, seq: int, payload: bytes) -> None:
        with self._lock:
            if seq in self._arrived.setdefault(robot, set()):
                return
            self._arrived[robot].add(seq)
            self._busy += 1
        self.counts["fetched"] += 1
        self.inbox.put(("fetched", robot, seq, payload))

    def _transmission(self) -> None:
        while True:
            item = self.inbox.get()
            if item is None or self._stopping.is_set():
                return
            try:
                self._handle(*item)
            except Exception:
                log.exception("%s: handling %s failed", self.robot, item[:3])
            finally:
                with self._lock:
                    self._busy -= 1

    def _handle(self, how: str, robot: str, seq: int, payload: bytes) -> None:
        key = (robot, seq)
        if how == "own":
            s = decode(payload)
            self._hold(s)
        else:
            if key in self._held:
                return
            try:
                s = decode(payload)
            except DecodeError as err:
                self.counts["decode_errors"] += 1
                log.warning("%s: %s/%d does not decode: %s", self.robot, robot, seq, err)
                return
            if (s.robot, s.seq) != key:
                self.counts["decode_errors"] += 1
                log.warning(
                    "%s: %s/%d carries %s/%d; dropped", self.robot, robot, seq, s.robot, s.seq
                )
                return
            self.store.put_submap(robot, seq, payload, own=False)
            self.counts["received"] += 1
            self._hold(s)
        self._match(s)

    def _match(self, s: Submap) -> None:
        for c in self.db.query(s.robot, s.seq, s.gmm, others_only=True):
            pair = frozenset({(s.robot, s.seq), (c.robot, c.seq)})
            if pair in self._judged or self._stopping.is_set():
                continue
            self._judged.add(pair)
            m = self.db.verify(s.robot, s.seq, s.gmm, c)
            r = m.registration
            edge = Edge(
                c.robot,
                c.seq,
                s.robot,
                s.seq,
                r.transform,
                r.information,
                float(min(1.0, max(0.0, r.confidence))),
                "accepted" if m.accepted else "rejected",
            )
            self.store.put_edge(edge)
            if m.accepted:
                self.opt_queue.put(("edge", edge))

    # ---- optimisation -----------------------------------------------------------------------

    def _optimisation(self) -> None:
        graph = PoseGraph(self.config.backend)
        pending: list[Edge] = []
        while True:
            item = self.opt_queue.get()
            if item is None:
                return
            self._optimising = True
            try:
                items = [item]
                while True:  # coalesce everything queued into one update
                    try:
                        more = self.opt_queue.get_nowait()
                    except queue.Empty:
                        break
                    if more is None:
                        return
                    items.append(more)
                changed = False
                for it in items:
                    if it[0] == "submap":
                        graph.add_submap(it[1], it[2], it[3])
                        changed = True
                    else:
                        pending.append(it[1])
                still = []
                for e in pending:  # a match waits for both of its submaps
                    nodes = ((e.target_robot, e.target_seq), (e.source_robot, e.source_seq))
                    if all(graph.has_submap(n) for n in nodes):
                        edge_id = graph.add_match(
                            nodes[0], nodes[1], e.transform, e.information, e.confidence
                        )
                        self._graph_edges[edge_id] = e
                        changed = True
                    else:
                        still.append(e)
                pending = still
                if changed and graph.n_submaps and not self._stopping.is_set():
                    result = graph.optimize()
                    tf = TfGraph.from_result(result)
                    with self._lock:
                        self.result, self.tf = result, tf
                    self.counts["optimised"] += 1
            except Exception:
                log.exception("%s: optimisation failed", self.robot)
            finally:
                self._optimising = False

    # ---- status and report ------------------------------------------------------------------

    def status(self, seq: int | None = None) -> dict:
        with self._lock:
            result = self.result
        edges = self.store.edges()
        return {
            "robot": self.robot,
            "seq": seq,
            "bytes": self.wire.get(seq, {}).get("wire") if seq is not None else None,
            "received": self.counts["received"],
            "matches": sum(e.status == "accepted" for e in edges),
            "groups": result.groups if result else [[self.robot]],
        }

    def report(self) -> dict:
        with self._lock:
            result = self.result
        stats = self.transport.stats()
        edges = self.store.edges()
        held = sorted(self._held)
        robots = sorted({r for r, _ in held} | {self.robot})
        by_kind = {d: {k: v for k, v in stats.get(d, {}).items()} for d in ("sent", "received")}
        to_ref = {}
        reference = {}
        if result is not None:
            to_ref = {r: np.asarray(T).tolist() for r, T in result.to_reference.items()}
            reference = dict(result.reference)
        return {
            "robot": self.robot,
            "fleet": self.config.fleet,
            "frames_consumed": self.frames_consumed,
            "submaps_built": self.counts["built"],
            "submaps_sent": self.counts["sent"],
            "submaps_received": self.counts["received"],
            "submaps_fetched": self.counts["fetched"],
            "decode_errors": self.counts["decode_errors"],
            "reloaded": self.reloaded,
            "held": {r: sum(1 for x, _ in held if x == r) for r in robots},
            "bytes": {
                "by_robot_and_kind": by_kind,
                "totals": stats.get("totals", {}),
                "ignored": stats.get("ignored", 0),
            },
            "matches_accepted": sum(e.status == "accepted" for e in edges),
            "matches_rejected": sum(e.status == "rejected" for e in edges),
            "backend_accepted": len(result.accepted) if result else 0,
            "backend_rejected": len(result.rejected) if result else 0,
            "groups": result.groups if result else [[self.robot]],
            "reference": reference,
            "to_reference": to_ref,
            "poses": (
                {f"{r}/{seq}": P.tolist() for (r, seq), P in sorted(result.poses.items())}
                if result
                else {}
            ),
            "submaps": [{"seq": k, **v} for k, v in sorted(self.wire.items())],
            "optimisations": self.counts["optimised"],
            "resources": resources(),
            # For evaluation only (the report stays on the robot): own anchors' ground truth
            # where the frames carry it, and the accepted registrations.
            "ground_truth": {str(seq): T.tolist() for seq, T in sorted(self.gt_anchors.items())},
            "edges": [
                {
                    "target": [e.target_robot, e.target_seq],
                    "source": [e.source_robot, e.source_seq],
                    "transform": np.asarray(e.transform).tolist(),
                    "backend": "accepted" if result and i in result.accepted else "rejected",
                }
                for i, e in sorted(self._graph_edges.items())
            ],
        }

    def global_map(self):
        """The merged map of this robot's group (built from the held submaps), or None."""
        from gmmap.mapping.globalmap import build_global_map

        with self._lock:
            result = self.result
        if result is None:
            return None
        ref = result.reference.get(self.robot, self.robot)
        group = next((g for g in result.groups if self.robot in g), [self.robot])
        poses = {k: v for k, v in result.poses.items() if k[0] in group}
        subs = [s for k, s in self._held.items() if k in poses]
        return build_global_map(subs, poses, ref)

    def emit_status(self, seq: int) -> None:
        if self._status is not None:
            self._status(self.status(seq))


def _sizes(s: Submap, wire: int, n_points: int | None) -> dict:
    return {
        "wire": wire,
        "points_float32": None if n_points is None else 12 * int(n_points),
        "gmm_float32": int(s.gmm.float32_bytes),
        "components": len(s.gmm),
    }


def run_robot(
    config: RobotConfig,
    frames: Sequence[Frame],
    report_path: Path | None = None,
    map_path: Path | None = None,
    status: Status | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """The ``gmmap robot`` process: run the node over ``frames``, linger, report, shut down.
    SIGINT/SIGTERM stop it cleanly (the report is still written, with what was done)."""
    say = progress or (lambda _m: None)
    node = RobotNode(config, status)
    stopped = threading.Event()

    def on_signal(signum, _frame):
        say(f"{config.robot}: signal {signum}, stopping")
        stopped.set()
        node._stopping.set()  # the stages stop taking work; stop() below closes everything

    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            old[sig] = signal.signal(sig, on_signal)
    report: dict = {}
    try:
        node.start()
        if config.wait_for:
            ok = node.transport.wait_for_peers(config.wait_for, config.wait_timeout)
            say(
                f"{config.robot}: peers {'present' if ok else 'missing'}: "
                f"{', '.join(node.transport.peers()) or 'none'}"
            )
        say(
            f"{config.robot}: {len(frames)} frames, resuming at {node.frames_consumed}, "
            f"{node.reloaded} submaps reloaded"
        )
        seen = set(node.wire)

        def poll() -> None:
            for seq in sorted(set(node.wire) - seen):
                seen.add(seq)
                node.emit_status(seq)

        builder = node.start_frames(frames)
        while builder.is_alive() and not stopped.is_set():
            builder.join(0.1)
            poll()
        poll()
        node.linger(config.linger)
        report = node.report()
        report["interrupted"] = stopped.is_set()
        if map_path is not None and not stopped.is_set():
            gmap = node.global_map()
            if gmap is not None:
                map_path.parent.mkdir(parents=True, exist_ok=True)
                gmap.save_png(map_path)
                report["map_png"] = str(map_path)
                from gmmap.io import viz

                if viz.available():  # the optional viz extra: a Rerun recording beside it
                    report["map_rrd"] = str(viz.save_rerun(gmap, map_path.with_suffix(".rrd")))
        if report_path is not None:
            report_path.parent.mkdir(parents=True, exist_ok=True)
            report_path.write_text(json.dumps(report, indent=1))
    finally:
        node.stop()
        for sig, handler in old.items():
            signal.signal(sig, handler)
    return report


def resources() -> dict | None:
    """This process's CPU time (user + system, all threads) and peak resident memory so far."""
    if resource is None:
        return None
    usage = resource.getrusage(resource.RUSAGE_SELF)
    # ru_maxrss is in kilobytes on Linux and in bytes on macOS.
    scale = 1 / 1024**2 if sys.platform == "darwin" else 1 / 1024
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "max_rss_mb": usage.ru_maxrss * scale}
