"""Crash safety: a robot process killed with SIGKILL mid-run and restarted on its store loses
nothing, and the fleet ends as an uninterrupted run of the same robots ends."""

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import replace

from gmmap.config import load_config

CLI = [sys.executable, "-c", "from gmmap.cli import main; main()"]
FRAMES = "160"


def _robot(config, index: int, report) -> subprocess.Popen:
    cmd = [*CLI, "robot", "--config", str(config), "--sim", "--sim-index", str(index),
           "--report", str(report), "--json", "--max-frames", FRAMES]  # fmt: skip
    return subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _own_submaps(store, robot: str) -> int:
    try:
        with sqlite3.connect(f"file:{store}?mode=ro", uri=True, timeout=1) as db:
            (n,) = db.execute("SELECT COUNT(*) FROM submaps WHERE robot = ?", (robot,)).fetchone()
            return n
    except sqlite3.Error:  # not created yet
        return 0


def test_kill_9_and_restart_on_the_store_loses_nothing(tmp_path) -> None:
    ref = tmp_path / "ref"
    out = subprocess.run(
        [*CLI, "demo", "--robots", "2", "--linger", "1.5", "--out", str(ref), "--json",
         "--min-matches", "1", "--max-frames", FRAMES],
        capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    expected = {n: json.loads((ref / f"{n}.json").read_text()) for n in ("robot_0", "robot_1")}

    # The same two robots (the demo's configurations), fresh stores; robot_1 dies mid-run.
    run = tmp_path / "run"
    configs, stores = [], []
    for name in expected:
        c = load_config(ref / f"{name}.yaml")
        stores.append(run / f"{name}.sqlite")
        configs.append(
            replace(c, robot=replace(c.robot, store=str(stores[-1]))).save(run / f"{name}.yaml")
        )
    reports = [run / f"{name}.json" for name in expected]
    procs = [_robot(configs[i], i, reports[i]) for i in (0, 1)]
    try:
        deadline = time.monotonic() + 120
        while _own_submaps(stores[1], "robot_1") < 2 and time.monotonic() < deadline:
            assert procs[1].poll() is None, procs[1].stderr.read()
            time.sleep(0.1)
        before = _own_submaps(stores[1], "robot_1")
        assert 2 <= before < expected["robot_1"]["submaps_built"]
        os.kill(procs[1].pid, signal.SIGKILL)
        assert procs[1].wait(10) == -signal.SIGKILL
        procs[1] = _robot(configs[1], 1, reports[1])
        for p in procs:
            assert p.wait(240) == 0, p.stderr.read()
    finally:
        for p in procs:
            p.kill()
    got = {n: json.loads(r.read_text()) for n, r in zip(expected, reports, strict=True)}
    assert got["robot_1"]["reloaded"] >= before  # its own submaps came back from the store
    for name, report in got.items():
        assert report["held"] == expected[name]["held"], name  # nothing lost, nothing extra
        assert report["groups"] == expected[name]["groups"], name
        assert report["complete"], name
