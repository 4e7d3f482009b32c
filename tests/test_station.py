"""The base station (`gmmap.fleet.node.station`, `gmmap.io.liveview`, ``gmmap station``): it joins
late and still holds every submap, sends nothing, holds no write permission in a secured
fleet, and a real headless browser (Debian's Chromium) shows its map."""

import base64
import contextlib
import json
import os
import shutil
import subprocess
import sys
import threading
import time
import urllib.request

import numpy as np
import pytest

from conftest import wait
from gmmap.config import Config
from gmmap.fleet.net.keys import listen_port
from gmmap.fleet.node.robot import RobotNode
from gmmap.fleet.node.station import StationNode
from gmmap.fleet.security.access import issue_fleet
from gmmap.fleet.security.credentials import add_member
from gmmap.io import viz
from gmmap.io.datasets import BUNDLED_TUM_SLICE, TumRgbd
from gmmap.options import (
    BackendOptions,
    BuildOptions,
    RobotOptions,
    SecurityOptions,
    TransportOptions,
)

BUILD = BuildOptions(frames_per_submap=2, n_components=60, covariance="full")


@pytest.fixture(scope="module")
def frames():
    return TumRgbd(BUNDLED_TUM_SLICE, stride=2)


def config(tmp_path, name, port, peers=(), credentials=None, scheme="tcp") -> Config:
    return Config(
        robot=RobotOptions(name=name, fleet="f", store=str(tmp_path / f"{name}.db")),
        transport=TransportOptions(port=port, connect=[f"{scheme}/127.0.0.1:{p}" for p in peers]),
        build=BUILD,
        backend=BackendOptions(min_matches=1),
        security=SecurityOptions(credentials=None if credentials is None else str(credentials)),
    )


@pytest.fixture
def fleet(tmp_path, frames, request):
    """Robots a and b (frames 0-3 and 4-7: one desk) that have mapped, and a station's
    config connecting to a; secured where the test is parametrised so."""
    secure = getattr(request, "param", False)
    members = {}
    if secure:
        members = issue_fleet(tmp_path / "fleet", "f", ["a", "b"])
        members["station"] = add_member(tmp_path / "fleet", "station", role="station")
    scheme = "tls" if secure else "tcp"
    ports = {"a": listen_port(), "b": listen_port()}
    nodes = []
    for name, chunk, peers in (("a", frames[0:4], ()), ("b", frames[4:8], (ports["a"],))):
        node = RobotNode(config(tmp_path, name, ports[name], peers, members.get(name), scheme))
        node.start()
        nodes.append(node)
        node.start_frames(chunk).join()
    assert wait(lambda: all(n.store.count("a") + n.store.count("b") == 4 for n in nodes), 20)
    station = config(tmp_path, "station", listen_port(), (ports["a"],), members.get("station"),
                     scheme)  # fmt: skip
    yield nodes, station
    for node in nodes:
        node.stop()


@pytest.mark.parametrize("fleet", [False, True], indirect=True, ids=["plain", "secured"])
def test_a_station_that_joins_late_holds_every_submap_and_sends_nothing(fleet):
    (a, b), config = fleet
    before = [n.transport.stats()["totals"].get("received", {}) for n in (a, b)]
    station = StationNode(config, sweep_s=1.0)
    station.start()
    try:
        assert wait(lambda: station.report()["held"] == {"a": 2, "b": 2, "station": 0}, 30)
        assert wait(lambda: station.groups() == [["a", "b"]], 30)
        assert station.transport.stats()["totals"].get("sent", {}).get("messages", 0) == 0
        assert wait(lambda: set(station.links) == {"a", "b"}, 15)  # the robots' byte counts
        counts = station.link_counts()
        assert sum(counts["a"]["sent"].values()) > 0 and counts["b"]["received"]["a"] > 0
        assert set(counts["station"]["received"]) == {"a", "b"}
        assert a.transport.peers() == ["b"] and b.transport.peers() == ["a"]  # not counted
        station.transport.publish("submap", 0, b"\x00" * 64)  # a put of its own
        time.sleep(1.0)
    finally:
        station.stop()
    after = [n.transport.stats()["totals"].get("received", {}) for n in (a, b)]
    if config.security.credentials is not None:  # access control drops it before the door
        assert after == before
    assert "station" not in a.store.robots() and "station" not in b.store.robots()


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@contextlib.contextmanager
def browser(url: str, tmp_path):
    """Headless Chromium (software GL) on ``url``; yields a function returning a screenshot
    (RGB array), driven over the DevTools protocol."""
    websocket = pytest.importorskip("websocket", reason="pip install websocket-client")
    from PIL import Image

    port = listen_port()
    args = [_chromium(), "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader", "--window-size=1280,800",
            f"--remote-debugging-port={port}", f"--user-data-dir={tmp_path / 'profile'}",
            url]  # fmt: skip
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    targets: list = []

    def listed() -> bool:
        try:
            targets[:] = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json"))
        except OSError:
            return False
        return any(t["type"] == "page" for t in targets)

    try:
        assert wait(listed, 30), "Chromium did not start"
        page = next(t for t in targets if t["type"] == "page")
        ws = websocket.create_connection(page["webSocketDebuggerUrl"], suppress_origin=True)

        def shot() -> np.ndarray:
            ws.send(json.dumps({"id": 1, "method": "Page.captureScreenshot"}))
            while (reply := json.loads(ws.recv())).get("id") != 1:
                pass
            png = tmp_path / "view.png"
            png.write_bytes(base64.b64decode(reply["result"]["data"]))
            return np.asarray(Image.open(png).convert("RGB"))

        yield shot
        ws.close()
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def coloured(shot: np.ndarray, robot: str) -> float:
    """The share of the 3D view's pixels near ``robot``'s colour (its shaded ellipsoids)."""
    from gmmap.io.ros2msgs import robot_color

    middle = shot[60:740, 20:940].reshape(-1, 3).astype(int)
    return float((np.linalg.norm(middle - np.array(robot_color(robot)) * 255, axis=1) < 60).mean())


@pytest.mark.skipif(_chromium() is None, reason="Chromium is not installed (make station)")
@pytest.mark.skipif(not viz.available(), reason="Rerun is not installed (the viz extra)")
def test_the_browser_shows_the_merged_map(fleet, tmp_path):
    from gmmap.io.liveview import LiveView

    (_a, _b), config = fleet
    station = StationNode(config, sweep_s=1.0)
    view = LiveView("station", listen_port(), listen_port(), tmp_path / "station.rrd")
    station.start()
    try:
        assert wait(lambda: sum(station.report()["held"].values()) == 4, 30)
        assert wait(lambda: station.groups() == [["a", "b"]], 30)
        every = {("a", 0), ("a", 1), ("b", 0), ("b", 1)}
        assert wait(lambda: view.update(station) or view.shown == every, 30)  # optimised
        with browser(view.url, tmp_path) as shot:
            time.sleep(25)  # the viewer's wasm loads and compiles in software
            image = shot()
    finally:
        station.stop()
    for robot in ("a", "b"):  # each robot's ellipsoids are on screen: not a blank canvas
        assert coloured(image, robot) > 0.002, robot
    assert (tmp_path / "station.rrd").stat().st_size > 1000  # the same recording, saved


def test_byte_counts_that_are_not_such_a_message_are_dropped():
    from gmmap.fleet.sharing import linkstats

    good = linkstats.encode({"sent": {"a": {"submap": {"payload_bytes": 5}}}}, "a")
    assert linkstats.decode(good) == {"robot": "a", "sent": {"a": 5}, "received": {}}
    for bad in (b"", b"[]", b'{"sent": 1, "received": {}}', b'{"sent": {"a": "x"}, "received": {}}',
                b"\xff", b"{" * 20_000):  # fmt: skip
        assert linkstats.decode(bad) is None


@pytest.mark.skipif(_chromium() is None, reason="Chromium is not installed (make station)")
@pytest.mark.skipif(not viz.available(), reason="Rerun is not installed (the viz extra)")
def test_the_demos_station_shows_the_map_in_a_browser_while_the_demo_runs(tmp_path):
    port = listen_port()
    paced = tmp_path / "paced.yaml"  # frames at twice real time: the view has time to load
    paced.write_text(
        f"sim: {{pace: 2.0}}\nstation: {{web_port: {port}, grpc_port: {listen_port()}}}\n"
    )
    cmd = [sys.executable, "-c", "from gmmap.cli import main; main()", "demo", "--station",
           "--out", str(tmp_path / "out"), "--config", str(paced), "--json"]  # fmt: skip
    demo = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})  # fmt: skip
    url = None
    for line in demo.stderr:  # the station says where its view is
        if "view at http" in line:
            url = line.split("view at ", 1)[1].split()[0]
            break
    threading.Thread(target=demo.stderr.read, daemon=True).start()  # keep the pipe drained
    assert url is not None and url.startswith(f"http://127.0.0.1:{port}/")
    seen = []
    with browser(url, tmp_path) as shot:
        while demo.poll() is None and not seen:
            time.sleep(3)
            image = shot()
            seen = [r for r in ("robot_0", "robot_1", "robot_2") if coloured(image, r) > 0.001]
    out = demo.stdout.read()
    demo.wait(timeout=300)
    assert demo.returncode == 0
    assert seen, "the view showed no robot's map while the demo ran"
    report = json.loads(out)
    held = report["station"]["held"]
    assert sum(v for k, v in held.items() if k != "station") == report["submaps"]


@pytest.mark.skipif(not viz.available(), reason="Rerun is not installed (the viz extra)")
def test_a_view_port_in_use_is_a_clear_error():
    import socket

    from gmmap.errors import GmmapError
    from gmmap.io.liveview import LiveView

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        with pytest.raises(GmmapError, match=r"--grpc-port .* is not free"):
            LiveView("x", grpc_port=taken.getsockname()[1], web_port=None)


def test_a_station_refuses_a_robots_credentials(tmp_path):
    from gmmap.fleet.security.credentials import CredentialsError

    members = issue_fleet(tmp_path / "fleet", "f", ["a"])
    with pytest.raises(CredentialsError, match="role station"):
        StationNode(config(tmp_path, "a", listen_port(), (), members["a"], "tls"))
