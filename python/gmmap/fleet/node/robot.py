"""A robot node (paper IV): threads, a transport and a store around one `Mapper`.

Stages, each a thread:

- **construction**: frames → `SubmapBuilder` → `gmmap.encode` → own store → outbox (kind
  "submap"; `gmmap.fleet.net.outbox`: in bundles, in priority order within ``robot.budget``). The
  node works on what it sent: the decoded copy of its own submap, the same bytes every other robot
  sees, goes on to matching. Each built submap is also given to ``on_built`` (a `Built`
  event: status lines, evaluation outside the node).
- **keeping**: the transport's subscription (and fetch replies) → inbox (`Arrived` events) →
  decode → store, at once however far matching lags: what is stored is what the adverts
  count and the fetches serve, so a robot in between hands on a submap while it still meets
  the robot that lacks it.
- **matching**: kept submaps → `Mapper.add` (place recognition against the other robots'
  submaps held, verification, a judged pair never registered again) → each judged pair stored
  as an edge.
- **optimisation**: woken whenever the graph changed; `Mapper.optimize`, whose `TfGraph` gives
  the frames between robots for status and the report.
- **fetch** (its `Fetcher`, `gmmap.fleet.sharing.fetching`): when a peer joins, a robot that
  holds anything tells it, alone, what (an advert, `gmmap.fleet.sharing.holdings`), and each
  fetches the robots the other's advert holds more of (from the first gap, else from the latest
  seq + 1); it serves fetches from its store, so a robot that was away catches up from whoever
  is present, and the submaps of a robot out of its reach, or present but silent or quiet
  (`gmmap.fleet.sharing.arrivals`), come through the robots in between (`Transport.fetch`,
  ``via``), even while it maps (while it maps it also asks them for the newest of a robot that
  fell quiet). Robots that meet fresh send neither.
- **ending** (its `Lingerer`, `gmmap.fleet.sharing.lingering`): after its frames the node
  lingers, telling its peers what it holds, until they hold the same and every robot it knows
  of is done mapping; then it leaves the fleet and finishes its matching.

Parts: the node owns its store, `Mapper`, `Transport`, `Outbox` and `Door`, and the two parts
that talk to its peers for it, the `Fetcher` and the `Lingerer` (which also tells joining
peers what it holds). Both are built on one `Shared` (`gmmap.fleet.sharing.shared`): the
collaborators they use, the node's lock and stop flag, and the way into its keeping stage.

Persistence: the store holds own and received submaps, edges, and in ``meta`` how many input
frames the construction stage had consumed when it emitted its last submap. A restarted node
reloads all of it, continues its own sequence after its last seq, skips the frames already
turned into submaps, re-uses the judged pairs and judges those it had not reached.

Shutdown: `RobotNode.stop` stops taking frames, drops what is still queued (everything is in
the store, so a restart recovers it), joins the stages, and closes the transport and the store.
"""

from __future__ import annotations

import json
import logging
import queue
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from gmmap.config import Config
from gmmap.errors import DecodeError
from gmmap.fleet.net.outbox import Budget, Outbox, air_share
from gmmap.fleet.net.transport import Transport, TransportConfig
from gmmap.fleet.node.report import node_report
from gmmap.fleet.security.credentials import load_for
from gmmap.fleet.security.door import Door
from gmmap.fleet.sharing import holdings, linkstats
from gmmap.fleet.sharing.arrivals import Arrivals, quiet_for
from gmmap.fleet.sharing.events import Arrived, Built, BuiltCallback, sizes_of
from gmmap.fleet.sharing.fetching import Fetcher
from gmmap.fleet.sharing.lingering import Lingerer
from gmmap.fleet.sharing.shared import KIND, Shared
from gmmap.fleet.storage.records import edge_of
from gmmap.fleet.storage.reload import reload
from gmmap.fleet.storage.store import Store
from gmmap.fleet.wire.codec import decode, encode
from gmmap.mapping.frame import Frame
from gmmap.mapping.live import LiveInput
from gmmap.mapping.mapper import Mapper
from gmmap.mapping.submap import Submap, SubmapBuilder

__all__ = ["Arrived", "Built", "RobotNode"]

log = logging.getLogger(__name__)

META_FRAMES = "frames_consumed"
META_CARRIED = "builder_state"  # `SubmapBuilder.state` after the robot's last submap
STOP_FLUSH_S = 2.0  # a stopped robot's last chance to send the bundle it held back
# On a shared channel a peer counts as quiet after the air time of this many submaps of this
# size at its share of the channel.
QUIET_MESSAGES, SUBMAP_BYTES = 3, 1_000
HEARD_MIN_S = 10.0  # a robot heard on the air counts for at least this long (s)


class RobotNode:
    """One robot: ``start()``, feed it with ``run(frames)`` (or ``start_frames``), ``stop()``.

    ``config.robot`` names it, its fleet and its store; ``config.transport`` its endpoints;
    build, select, place, register and backend configure its mapping. Its fetch stage is its
    ``fetcher``, its adverts and ending its ``lingerer``; both work on what ``shared`` holds."""

    watch = False  # a station (`gmmap.fleet.node.station`) holds no liveliness token
    tells = True  # whether it advertises what it holds (a station does not: `Lingerer.tells`)

    def __init__(self, config: Config, on_built: BuiltCallback | None = None) -> None:
        self.config = config
        self.robot = config.robot.name
        self.on_built = on_built
        self._tmp: tempfile.TemporaryDirectory | None = None
        path = Path(config.robot.store) if config.robot.store else None
        if path is None:
            self._tmp = tempfile.TemporaryDirectory(prefix=f"gmmap-{self.robot}-")
            path = Path(self._tmp.name) / "store.sqlite"
        self.store = Store(path)
        self.mapper = Mapper(config)
        self.inbox: queue.Queue[Arrived | None] = queue.Queue()
        self.kept: queue.Queue[Submap | None] = queue.Queue()  # stored, for matching
        # Robots a peer holds more of, None: stop.
        self.fetch_queue: queue.Queue[tuple[str, ...] | None] = queue.Queue()
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._changed = threading.Event()  # the graph changed since the last optimisation
        self._threads: list[threading.Thread] = []
        self._busy = 0  # arrivals not yet kept and matched, and a running optimisation
        self._unkept = 0  # arrivals not yet stored (or dropped)
        bundled = config.robot.bundle_size > 1
        self.arrivals = Arrivals(
            quiet_s=quiet_for(config.robot),
            patient=bundled,
            shared_channel=config.transport.broadcast is not None,
        )
        self.holdings = holdings.Holdings()  # what the peers say they hold
        self._closed, self._live = False, None
        self.counts = dict(built=0, sent=0, received=0, fetched=0, decode_errors=0, optimised=0)
        self.frames_consumed = int(self.store.get_meta(META_FRAMES, "0") or 0)
        c = config.security.credentials
        credentials = None if c is None else load_for(Path(c), config.robot.fleet, self.robot)
        self.door = Door(config.robot.fleet, config.security, credentials)
        r = reload(self.store, self.mapper, self.door.inner, self.robot)
        self.reloaded, self._pending_reload = r.held, r.pending
        self.wire = {seq: sizes_of(s, n, None) for seq, (s, n) in r.own.items()}  # own seq → bytes
        self._changed.set()
        fleet = config.robot.fleet
        transport = TransportConfig(fleet, self.robot, config.transport, credentials, self.watch)
        self.transport = Transport(transport)
        self.budget = Budget(config.robot.budget)
        sending = (fleet, self.robot), config.robot.bundle_size, config.robot.bundle_wait
        self.outbox = Outbox(self._publish, self.budget, holdings.KIND, *sending)
        self.shared = Shared(
            robot=self.robot,
            store=self.store,
            transport=self.transport,
            door=self.door,
            arrivals=self.arrivals,
            holdings=self.holdings,
            fetch_queue=self.fetch_queue,
            counts=self.counts,
            enqueue=self._enqueue,
            lock=self._lock,
            stop=self._stopping,
            lossy=config.transport.protocol == "udp",
        )
        self.fetcher = Fetcher(self.shared)
        self.lingerer = Lingerer(self.shared, self.outbox, self._delivered, self.tells)

    # ---- lifecycle --------------------------------------------------------------------------

    def start(self) -> None:
        t = self.transport
        self._serve()
        t.subscribe(self._receive)
        t.on_join(self.holdings.meet)
        t.on_join(self._joined)
        t.on_join(self._share_air)
        t.on_leave(self._share_air)
        self._share_air()
        with self._lock:
            self._busy += 1  # the reloaded submaps, judged first by the matching stage
        for name, target in (
            ("keep", self._keeping),
            ("match", self._matching),
            ("optimise", self._optimisation),
            ("fetch", self.fetcher.run),
        ):
            self._spawn(name, target)

    def _serve(self) -> None:
        self.transport.serve(linkstats.provider(self), self.store.robots, self.budget)

    def _spawn(self, name: str, target: Callable[..., None], *args: object) -> threading.Thread:
        th = threading.Thread(
            target=target, args=args, name=f"gmmap-{self.robot}-{name}", daemon=True
        )
        th.start()
        self._threads.append(th)
        return th

    def start_frames(self, frames: Sequence[Frame] | LiveInput) -> threading.Thread:
        """Map ``frames``: a recording, resumed after the frames already turned into submaps,
        or a `LiveInput` a driver pushes into (`gmmap.mapping.live`), until it is closed."""
        if isinstance(frames, LiveInput):
            self._live = frames
        return self._spawn("build", self._construction, frames)

    def run(self, frames: Sequence[Frame]) -> dict:
        """Start, consume ``frames``, linger, and return the report (the node stays open)."""
        self.start()
        self.start_frames(frames).join()
        self.linger(self.config.robot.linger)
        return self.report()

    def linger(self, seconds: float, progress: Callable | None = None) -> bool:
        """Work on for ``seconds`` after the frames, then until the peers hold what we hold and
        no more, and every robot we know of is done mapping and its last submap is here
        (`gmmap.fleet.sharing.holdings`), or ``robot.deadline`` s; True if complete. Then leave the
        fleet (`gmmap.fleet.sharing.lingering`), and finish matching."""
        if self.stopping:
            return False
        end = time.monotonic() + max(seconds, self.config.robot.deadline)
        complete = self.lingerer.linger(seconds, end, progress)
        # The rejudging needs every submap held by the matching stage first.
        self.shared.wait(self._matched, max(5.0, end - time.monotonic()))
        if self.config.robot.rejudge and not self.stopping:
            if progress:
                progress(f"{self.robot}: judging all {len(self.mapper.submaps)} submaps again")
            self.mapper = self.mapper.rejudged()
            self.store.replace_edges(edge_of(m) for m in self.mapper.matches)
        return complete

    @property
    def stopping(self) -> bool:
        return self._stopping.is_set()

    def request_stop(self) -> None:
        """Ask the stages to stop taking work (safe from a signal handler); `stop` closes."""
        self._stopping.set()
        if self._live is not None:
            self._live.close()

    def _publish(self, kind: str, seq: int, payload: bytes, to: frozenset[str] | None) -> None:
        """The outbox's way out (its thread): a submap counts as sent once published."""
        if to is None:
            self.transport.publish(kind, seq, payload)
        for peer in sorted(to or ()):
            self.transport.tell(peer, kind, seq, payload)
        if kind == KIND:
            self.counts["sent"] += 1

    def _delivered(self) -> bool:
        """Nothing that arrived waits to be stored, nothing to fetch, nothing to send."""
        with self._lock:
            unkept = self._unkept
        return unkept == 0 and self.fetch_queue.empty() and not self.outbox.pending()

    def _matched(self) -> bool:
        """Nothing waits to be matched or optimised."""
        with self._lock:
            busy = self._busy
        return busy == 0 and self.kept.empty() and not self._changed.is_set()

    def drain(self, timeout: float = 10.0) -> bool:
        """Wait until inbox, fetches and optimisation are idle (True) or ``timeout`` s pass."""
        return self.shared.wait(lambda: self._delivered() and self._matched(), timeout)

    def stop(self) -> None:
        """Stop the stages (queued work is dropped: it is in the store; a held bundle gets
        STOP_FLUSH_S to leave), close transport and store."""
        if self._closed:
            return
        self._closed = True
        self.request_stop()
        self._changed.set()
        self.inbox.put(None)
        self.fetch_queue.put(None)
        self.outbox.close(flush_s=0.0 if self.transport.closed else STOP_FLUSH_S)
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
            builder = SubmapBuilder(self.robot, self.config.build, self.config.select)
            last = self.store.latest_seq(self.robot)
            builder.seq = 0 if last is None else last + 1
            i = self.frames_consumed
            live = isinstance(frames, LiveInput)
            carried = self.store.get_meta(META_CARRIED, "")
            if carried:
                builder.resume(json.loads(carried))
            for frame in iter(frames) if live else (frames[j] for j in range(i, len(frames))):
                if self.stopping:
                    break
                s = builder.add(frame)
                i += 1
                if s is not None:
                    self._emit(s, i, builder)
            if not self.stopping and i > self.frames_consumed:
                s = builder.flush()
                if s is not None:
                    self._emit(s, i, builder)
        except Exception:
            log.exception("%s: construction failed", self.robot)

    def _emit(self, s: Submap, consumed: int, builder: SubmapBuilder) -> None:
        payload = self.door.seal(self.robot, KIND, s.seq, encode(s))
        meta = {META_FRAMES: str(consumed), META_CARRIED: json.dumps(builder.state())}
        self.store.put_submap(self.robot, s.seq, payload, own=True, meta=meta)
        self.frames_consumed = consumed
        self.counts["built"] += 1
        self.wire[s.seq] = {**sizes_of(s, len(payload), s.n_points), "built_at": time.time()}
        self.outbox.put(KIND, s.seq, payload)
        self._enqueue(Arrived("own", self.robot, s.seq, payload))
        if self.on_built is not None:
            try:
                self.on_built(Built(s, self.wire[s.seq], self.status(s.seq)))
            except Exception:
                log.exception("%s: the on_built callback failed", self.robot)

    # ---- transmission -----------------------------------------------------------------------

    def _enqueue(self, item: Arrived) -> None:
        with self._lock:
            self._busy += 1
            self._unkept += 1
        self.inbox.put(item)

    def _joined(self, peer: str) -> None:
        self.lingerer.joined(peer)

    def _share_air(self, _peer: str | None = None) -> None:
        options, budget = self.config.transport, self.config.robot.budget
        robots = 1 + len(self.transport.peers())
        rate = air_share(options.channel_rate, robots, budget)
        if rate and options.broadcast is not None:
            # Shared with the robots present and those heard on the air lately (over two
            # submaps' air time at an equal share), a session with them open or not. Hearing
            # lags by the channel's queue: a share over the talkers alone, larger while the
            # others' first messages queued, lost 12 of 248 submaps (5 robots, 500 B/s).
            window = max(HEARD_MIN_S, 2 * SUBMAP_BYTES / rate)
            t = self.transport
            self.budget.follow(
                lambda: air_share(
                    options.channel_rate, 1 + len({*t.peers(), *t.talkers(window)}), budget
                )
            )
        else:
            self.budget.set_rate(rate)
        if rate and self.arrivals.shared_channel:
            # Paced to its share, a robot is quiet between messages as long as one takes.
            quiet = max(quiet_for(self.config.robot), QUIET_MESSAGES * SUBMAP_BYTES / rate)
            self.arrivals.quiet_s = quiet

    def _receive(self, robot: str, kind: str, seq: int, payload: bytes) -> None:
        if not self.door.admit(robot, kind, seq, payload):
            return
        if self.shared.lossy:
            self.lingerer.heard_again(robot, seq if kind == KIND else None)
        if self.arrivals.shared_channel:  # on the air: the robot itself talks to us
            self.arrivals.hear(robot)
        if kind == KIND:
            if self.arrivals.add(robot, seq, direct=True):  # else a duplicate, or a replay
                self._enqueue(Arrived("received", robot, seq, payload))
        elif kind == holdings.KIND and self.holdings.update(robot, self.door.inner(payload), seq):
            wanted = holdings.wanted({robot: self.holdings.adverts()[robot]}, self.shared.held())
            # After its first advert since it joined, only what it alone can hand on to us.
            if not self.holdings.caught_up(robot):
                wanted = [r for r in wanted if self.arrivals.relayed(r, self.transport.peers())]
            if wanted:
                self.fetch_queue.put(tuple(wanted))

    def _matching(self) -> None:
        try:
            self._judge(self._pending_reload)
        except Exception:
            log.exception("%s: matching the reloaded submaps failed", self.robot)
        finally:
            with self._lock:
                self._busy -= 1
        while (s := self.kept.get()) is not None and not self.stopping:
            try:
                self._judge(self.mapper.hold([s]))
            except Exception:
                log.exception("%s: matching %s/%d failed", self.robot, s.robot, s.seq)
            finally:
                with self._lock:
                    self._busy -= 1

    def _keeping(self) -> None:
        while (item := self.inbox.get()) is not None and not self.stopping:
            s = None
            try:
                s = self._accept(item)
            except Exception:
                log.exception("%s: keeping %s/%d failed", self.robot, item.robot, item.seq)
            if s is not None:
                self.kept.put(s)  # before the count drops: matching is never seen done early
            with self._lock:
                self._unkept -= 1
                if s is None:
                    self._busy -= 1
        self.kept.put(None)

    def _accept(self, item: Arrived) -> Submap | None:
        """The decoded submap of ``item``, stored if received; None if held or bad."""
        key = (item.robot, item.seq)
        if item.origin == "own":
            return decode(self.door.inner(item.payload))
        if key in self.mapper.submaps:
            return None
        try:
            s = decode(self.door.inner(item.payload))
        except DecodeError as err:
            self.counts["decode_errors"] += 1
            log.warning("%s: %s/%d does not decode: %s", self.robot, *key, err)
            return None
        if (s.robot, s.seq) != key:
            self.counts["decode_errors"] += 1
            log.warning("%s: %s/%d carries %s/%d; dropped", self.robot, *key, s.robot, s.seq)
            return None
        self.store.put_submap(item.robot, item.seq, item.payload, own=False)
        self.counts["received"] += 1
        return s

    def _judge(self, submaps: list[Submap]) -> None:
        """Matches newly held ``submaps``; every judged pair is stored, accepted ones join the
        graph."""
        if submaps:
            self._changed.set()
        for s in submaps:
            if self.stopping:
                return
            for m in self.mapper.verify([s]):
                self.store.put_edge(edge_of(m))
                if self.mapper.add_match(m) is not None:
                    self._changed.set()

    # ---- optimisation -----------------------------------------------------------------------

    def _optimisation(self) -> None:
        while True:
            self._changed.wait()
            if self.stopping:
                return
            with self._lock:
                self._busy += 1
            self._changed.clear()
            try:
                if self.mapper.submaps:
                    self.mapper.optimize()
                    self.counts["optimised"] += 1
            except Exception:
                log.exception("%s: optimisation failed", self.robot)
            finally:
                with self._lock:
                    self._busy -= 1

    # ---- status and report ------------------------------------------------------------------

    def groups(self) -> list[list[str]]:
        return self.mapper.frames.groups() if self.mapper.result else [[self.robot]]

    def status(self, seq: int | None = None) -> dict:
        edges = self.store.edges()
        return {
            "robot": self.robot,
            "seq": seq,
            "bytes": self.wire.get(seq, {}).get("wire") if seq is not None else None,
            "received": self.counts["received"],
            "matches": sum(e.status == "accepted" for e in edges),
            "groups": self.groups(),
        }

    def report(self) -> dict:
        """What the node did, held and concluded (frames, poses, kept matches); no ground truth."""
        return node_report(self)

    def global_map(self):
        """The merged map of this robot's group (built from the held submaps), or None."""
        return self.mapper.global_map(self.robot)
