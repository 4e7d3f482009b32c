"""benchmarks/report.py: the scoreboard and the plots regenerated from a small JSON fixture
(tiny fake bench-*.json files with just the keys the rows read, never the real ones)."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_report():
    spec = importlib.util.spec_from_file_location("gmmap_bench_report", BENCHMARKS / "report.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


report = load_report()

EM = {"gmmap": {"time_s": 0.5}, "sklearn": {"time_s": 10.0}}
CODEC = {
    "size": {
        "bytes_mean": 800.0,
        "float32_gmm_bytes_mean": 3800.0,
        "float32_points_bytes_mean": 24000.0,
        "series": {
            "bytes": [780, 820, 800],
            "float32_gmm_bytes": [3700, 3900, 3800],
            "float32_points_bytes": [20000, 28000, 24000],
        },
    }
}
# TUM only: the KITTI rows must say "not run".
REGISTRATION = {
    "tum_fr1_xyz": {
        "methods": {
            name: {
                "t_error_mean": t,
                "t_error_median": t / 2,
                "r_error_mean": 0.5,
                "r_error_median": 0.0,
                "time_per_pair_s": s,
                "t_error_quantiles": [t / 4, t / 3, t / 2, t, 2 * t],
                "r_error_quantiles": [0.0, 0.0, 0.0, 0.5, 1.0],
            }
            for name, t, s in (("points", 0.006, 0.002), ("gicp", 0.008, 0.010))
        }
    }
}
FLEET = {
    "fleets": [
        {"robots": 2, "bytes_sent": {"mean": 6000}, "points_float32_sent_equivalent": 4.0e6},
        {"robots": 8, "bytes_sent": {"mean": 8000}, "points_float32_sent_equivalent": 4.8e6},
    ]
}
PLACE = {
    "office": {
        "shape": {
            "recall_at_1": {"gmm": 0.5, "points": 0.4},
            "recall_at_1pct": {"gmm": 0.6, "points": 0.6},
        }
    }
}


def write(root: Path, **benches: dict) -> Path:
    for name, data in benches.items():
        (root / f"bench-{name}.json").write_text(json.dumps(data))
    return root


def scoreboard_rows(text: str) -> list[list[str]]:
    """The scoreboard table's rows (header and rule left out), cells stripped."""
    section = text.split("## Scoreboard", 1)[1].split("\n## ", 1)[0]
    table = [line for line in section.splitlines() if line.startswith("| ")]
    return [[c.strip() for c in line.strip("|").split(" | ")] for line in table[1:]]


def rows_of(rows: list[list[str]], bench: str) -> list[list[str]]:
    return [r for r in rows if f"[{bench}](#{bench})" in r[0]]


def test_the_scoreboard_is_regenerated_from_the_json(tmp_path):
    text, present, _ = report.page(write(tmp_path, em=EM, codec=CODEC, registration=REGISTRATION))
    assert present == 3
    rows = scoreboard_rows(text)
    assert len(rows) == len(report.SCOREBOARD)
    assert text.index("## Scoreboard") < text.index("## em")  # the page opens with it

    (em,) = rows_of(rows, "em")
    assert em[1:4] == [
        "0.5 s",
        "scikit-learn GaussianMixture: 10 s",
        "20 (baseline / gmmap)",  # lower is better: the baseline's time over ours
    ]
    assert em[5] == "real"

    points, paper = rows_of(rows, "codec")
    assert points[1:4] == ["800 B", "voxelised points as float32: 24000 B", "30 (baseline / gmmap)"]
    assert paper[1:4] == ["800 B", "the paper's message: 5099 B", "6.374 (baseline / gmmap)"]

    tum_error, tum_time, kitti_error, kitti_time = rows_of(rows, "registration")
    assert tum_error[1:4] == [
        "6 mm",
        "small_gicp GICP on the points: 8 mm",
        "1.333 (baseline / gmmap)",
    ]
    assert tum_time[1:4] == ["2 ms", "small_gicp GICP on the points: 10 ms", "5 (baseline / gmmap)"]
    # Keys missing from a file that is there: not run, nothing invented.
    for row in (kitti_error, kitti_time):
        assert row[1] == "not run" and row[3] == "–"


def test_a_missing_benchmark_is_not_run(tmp_path):
    text, _, _ = report.page(write(tmp_path, em=EM))
    rows = scoreboard_rows(text)
    for bench in ("codec", "place", "planner", "fleet", "sensors"):
        assert rows_of(rows, bench)
        for row in rows_of(rows, bench):
            assert row[1] == "not run" and row[3] == "–", row
    (em,) = rows_of(rows, "em")
    assert em[1] == "0.5 s"


def test_unreadable_or_odd_json_never_crashes(tmp_path):
    (tmp_path / "bench-codec.json").write_text("{not json")
    write(tmp_path, em={"gmmap": {"time_s": "fast"}, "sklearn": {"time_s": 0}}, fleet={"fleets": 3})
    rows = scoreboard_rows(report.page(tmp_path)[0])
    assert all(r[1] == "not run" for r in rows)


def test_higher_is_better_and_selectors(tmp_path):
    sensors = {"lidar16_3_robots": {"met": 9, "joined": 6, "wrong": 1}}
    text, _, _ = report.page(write(tmp_path, fleet=FLEET, place=PLACE, sensors=sensors))
    rows = scoreboard_rows(text)
    (fleet,) = rows_of(rows, "fleet")
    assert fleet[1:4] == [
        "8000 B",
        "voxelised points as float32: 4800000 B",
        "600 (baseline / gmmap)",
    ]
    assert fleet[5] == "simulated"
    lidar16 = rows_of(rows, "sensors")[0]
    assert lidar16[1:4] == ["6 (wrong 1)", "pairs that met: 9", "0.6667 (gmmap / baseline)"]
    assert all(r[1] == "not run" for r in rows_of(rows, "sensors")[1:])
    # The place rows read sets this fixture does not have.
    assert all(r[1] == "not run" for r in rows_of(rows, "place"))


def test_lookup():
    data = {"a": [{"n": 2, "v": 1.5}, {"n": 8, "v": 3}], "b": {"c": True}}
    assert report.lookup(data, ("a", "n=8", "v")) == 3
    assert report.lookup(data, ("a", 0, "v")) == 1.5
    assert report.lookup(data, ("a", 5, "v")) is None
    assert report.lookup(data, ("a", "n=4", "v")) is None
    assert report.lookup(data, ("b", "c", "d")) is None
    assert report.number(report.lookup(data, ("b", "c"))) is None  # a boolean is no figure


def test_plots_are_written_for_the_fixture(tmp_path):
    pytest.importorskip("matplotlib")
    root = write(tmp_path, codec=CODEC, fleet=FLEET, registration=REGISTRATION, place=PLACE)
    out = tmp_path / "docs" / "benchmarks.md"
    subprocess.run(
        [sys.executable, str(BENCHMARKS / "report.py"), "--root", str(root), "--out", str(out)],
        check=True,
        capture_output=True,
    )
    names = ("bytes_over_time", "bytes_per_submap", "fleet_bytes", "registration_errors",
             "place_recall")  # fmt: skip
    for name in names:
        png = tmp_path / "docs" / "benchmarks" / f"{name}.png"
        assert png.read_bytes().startswith(b"\x89PNG"), name
    text = out.read_text()
    # Linked right after the scoreboard, before the first benchmark's section.
    plots = text.index("## Plots")
    assert text.index("## Scoreboard") < plots < text.index("## registration")
    for name in names:
        assert f"](benchmarks/{name}.png)" in text


def test_no_plot_without_its_json(tmp_path):
    pytest.importorskip("matplotlib")
    text, _, _ = report.page(write(tmp_path, em=EM), tmp_path / "plots")
    assert "## Plots" not in text
    assert not list(tmp_path.glob("plots/*.png"))


def test_place_recall_curves_when_the_json_has_them(tmp_path):
    pytest.importorskip("matplotlib")
    place = {"office": {"shape": {"recall_at_n": {"gmm": [0.5, 0.7], "points": [0.4, 0.8]}}}}
    text, _, _ = report.page(write(tmp_path, place=place), tmp_path / "plots")
    assert (tmp_path / "plots" / "place_recall.png").is_file()
    assert "](plots/place_recall.png)" in text


def test_no_plots_without_matplotlib(tmp_path, monkeypatch, capsys):
    real = report.importlib.util.find_spec
    monkeypatch.setattr(
        report.importlib.util,
        "find_spec",
        lambda name, *a: None if name == "matplotlib" else real(name, *a),
    )
    text, _, _ = report.page(write(tmp_path, codec=CODEC), tmp_path / "plots")
    assert "## Plots" not in text
    assert not (tmp_path / "plots").exists()
    assert "matplotlib is not importable" in capsys.readouterr().err
    assert rows_of(scoreboard_rows(text), "codec")[0][1] == "800 B"  # the scoreboard stays
