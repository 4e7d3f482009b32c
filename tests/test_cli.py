import json

from click.testing import CliRunner

from gmmap import __version__
from gmmap.cli import main


def run(*args):
    result = CliRunner().invoke(main, list(args), catch_exceptions=False)
    assert result.exit_code == 0, result.output
    return result


def test_help_and_version():
    assert "demo" in run("--help").output and "bench" in run("--help").output
    assert __version__ in run("--version").output
    assert "--scaling" in run("bench", "em", "--help").output


def test_demo_help_lists_its_options():
    """The demo itself (robot processes over Zenoh) runs in tests/test_robot.py."""
    out = run("demo", "--help").output
    assert "--robots" in out and "--json" in out and "--out" in out


def test_bench_em_compares_with_sklearn():
    r = json.loads(
        run(
            "bench",
            "em",
            "--points",
            "3000",
            "--components",
            "10",
            "--iterations",
            "5",
            "--repeats",
            "1",
            "--json",
        ).stdout
    )
    assert r["points"] == 3000 and r["sklearn"]["time_s"] > 0 and r["speedup"] > 0


def test_bad_input_is_one_line_not_a_traceback(tmp_path):
    for args in (
        ["info", str(tmp_path)],
        ["eval", "registration", str(tmp_path)],
        ["build", str(tmp_path), "--out", str(tmp_path / "out")],
    ):
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 1, (args, r.output)
        assert "not a dataset gmmap can read" in r.output and "Traceback" not in r.output


def test_a_missing_extra_is_named(monkeypatch):
    import sys

    monkeypatch.delitem(sys.modules, "gmmap.fleet.net.transport", raising=False)
    monkeypatch.setitem(sys.modules, "zenoh", None)  # as if the fleet extra were not installed
    result = CliRunner().invoke(main, ["demo", "--robots", "1"])
    assert result.exit_code == 1
    assert "pip install 'gmmap[fleet]'" in result.output
