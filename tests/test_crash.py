"""Crash safety: a robot process killed with SIGKILL mid-run and restarted on its store loses
nothing, and the fleet ends as an uninterrupted run of the same robots ends."""

import json
from dataclasses import replace

from gmmap.cli.demo import run_demo
from gmmap.config import Config
from gmmap.options import RobotOptions, SimOptions

FRAMES = 160


def _run(out, crash=None) -> tuple[dict, dict]:
    """Two demo robots over ``FRAMES`` frames: the demo's summary and each robot's report."""
    config = Config(sim=SimOptions(robots=2), robot=RobotOptions(linger=1.5))
    config = replace(config, backend=replace(config.backend, min_matches=1))
    said: list[str] = []
    r = run_demo(config, FRAMES, out, said.append, crash)
    reports = {n: json.loads((out / f"{n}.json").read_text()) for n in r["received"]}
    return r, reports


def test_kill_9_and_restart_on_the_store_loses_nothing(tmp_path) -> None:
    _, expected = _run(tmp_path / "ref")
    assert expected["robot_1"]["submaps_built"] > 2
    # The same two robots; robot_1 dies once it has stored two submaps of its own.
    r, got = _run(tmp_path / "run", crash=(1, 2))
    assert got["robot_1"]["reloaded"] >= 2  # its own submaps came back from the store
    assert r["lost"] == {"robot_0": 0, "robot_1": 0}
    for name, report in got.items():
        assert report["held"] == expected[name]["held"], name  # nothing lost, nothing extra
        assert report["groups"] == expected[name]["groups"], name
        assert report["complete"], name
