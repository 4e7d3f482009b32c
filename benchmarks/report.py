"""Regenerate docs/benchmarks.md from the benchmarks' JSON outputs.

Each script benchmarks/<name>.py prints one JSON object, which ``make bench`` saves as
bench-<name>.json in the repository root. This script reads every such file that exists and
writes the page: first a scoreboard, one row per headline figure against its baseline
(``SCOREBOARD``; a row whose file or keys are missing says "not run"), then the key plots
(``benchmarks/plots.py``, PNGs beside the page, when matplotlib is importable), then one
section per benchmark: a sentence on what it measures and against which baseline,
then its figures. The figures are the JSON walked generically:

- an object's scalars (and lists of scalars) form a two-column table, figure and value;
- sibling objects whose figures are flat and mostly shared form one table, a row each;
- a list of flat objects forms one table, a row per object (nested keys dotted), or a column
  per object when the figures are too many to fit across;
- anything else goes under its own sub-heading, walked the same way.

Floats are rounded to 4 significant digits. Integers, which are counts, stay exact. Lists of
more than 25 values are shortened (the JSON files have them all). Benchmarks without a
readable JSON file are listed as not run, each with the command that runs it.

    python benchmarks/report.py [--root DIR] [--out FILE|-] [--no-plots]

Python 3.10+, standard library only (matplotlib for the plots, skipped without it). It imports
nothing of gmmap, so it runs anywhere.
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import json
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

# What each benchmark measures and its baseline, from the scripts' docstrings.
DESCRIPTIONS: dict[str, str] = {
    "em": "EM fit time and final mean log-likelihood on 50,000 voxelised TUM fr1_xyz points "
    "(K = 100, k-means++, 30 fixed iterations), plus time and peak memory as N grows from 10k "
    "to 500k and K from 25 to 400. Baseline: scikit-learn's GaussianMixture with the same "
    "points and settings.",
    "raycast": "640×480 depth frames rendered per second along a robot's route in the "
    "simulated office, on one core and on all cores, and the full sensor model with noise and "
    "quantisation. Baseline: per-ray BVH traversal (the LiDAR path) of the same pixels.",
    "loaders": "Dataset loader throughput in frames per second: TUM fr1_xyz at pixel stride 1 "
    "(the bundled slice when ../shared/data is absent), and KITTI 00 scans when present. "
    "Baselines: decoding the same PNGs alone (PIL), and numpy reading the same KITTI .bin "
    "files.",
    "selection": "Adaptive model selection on TUM fr1_xyz, TUM fr3 cabinet, KITTI 00 and the "
    "simulated office: components and float32 bytes before and after, held-out "
    "log-likelihood, and a sweep of the KL threshold. Also the time to build one 40-frame "
    "depth submap, and the paper's Fig. 2 argument. Baselines: the paper's merge without the "
    "refit, the 1.33 s a 30 Hz camera takes for 40 frames, and GMM-merge submaps.",
    "codec": "Bytes per encoded submap, Table I registration accuracy on decoded submaps, "
    "encode and decode time, and a sweep of the distortion. Baselines: the mixture as float32, "
    "the paper's 5,099-byte message, the voxelised points as float32, and registration on the "
    "float64 mixtures.",
    "registration": "The paper's Table I: translation and rotation error (mean, RMSE) and "
    "success rate when registering consecutive submaps on TUM and KITTI, checked against "
    "ground truth. Also the global mode (random yaw, no initial guess) and the time per pair. "
    "Baselines: GMM-merge and per-frame GMM submaps, and small_gicp's GICP on the same points "
    "and pairs.",
    "place": "The paper's Fig. 7/8: place-recognition recall@1 and recall@top-1 %, recall at "
    "100 % precision after verification, the time to describe a submap, and query time "
    "against 1,000 and 10,000 submaps, for the training-free shape descriptor and the learned "
    "PointNetVLAD. Data, none used in training: held-out simulated worlds pooled into one "
    "database (procedural offices and the demo office, LiDAR and depth), TUM fr1_xyz split "
    "into two robots, and the demo office with 3 and 5 robots. Baselines: each descriptor on "
    "the raw submap points (the paper: PointNetVLAD 87.4 % on resampled GMMs against 88.3 % "
    "on raw clouds), and verification by points + small_gicp's GICP.",
    "merge": "The offline merge (`gmmap merge`) against ground truth, on TUM fr1_xyz split "
    "into two robots and on the simulated office. Measured: each robot pair's relative pose "
    "where they met, their map frames, the kept matches, the ATE (evo) of all anchors, and "
    "how many injected wrong matches were rejected. Baseline: the anchors before "
    "optimisation.",
    "backend": "Pose-graph time per update as 8 robots' joint graph grows to 1,000 synthetic "
    "submaps, and robustness to 20 % wrong matches. Baselines: plain Levenberg-Marquardt on "
    "every match (no PCM, no GNC), and an oracle given only the true matches (also timed with "
    "GTSAM's ISAM2).",
    "fleet": "The whole demo with 2 to 8 robot processes: bytes sent and received per robot, "
    "CPU time, peak memory, and how accurate the kept matches, robot pairs and map frames are. "
    "Baseline: the bytes a point-cloud system would send for the same submaps (voxelised "
    "points as float32, the paper's Fig. 9).",
    "channel": "The demo on one radio channel shared by the whole fleet (a namespace's "
    "loopback capped by tc tbf for all robots together), 3 and 5 robots, 10 kB/s to 250 B/s: "
    "submaps lost, time until every robot holds every submap, bytes on the air per submap "
    "built. Baseline: the unicast mesh (each submap to each peer over its own Zenoh link) on "
    "the same channel.",
    "planner": "Time per step of the GMM gradient-field planner on the paper's four scenes, "
    "and how it grows with the map's component count. Baseline: one full A* plan on a 5 cm "
    "grid of the same scans (`astar_over_gmm`: how many GMM steps one A* plan costs).",
    "explore": "Simulated robots exploring procedural offices never used while the explorer "
    "was written (`gmmap explore`, random-office:101 and 102 with the 16-beam LiDAR, 101 with "
    "the depth camera, 3 robots, 300 simulated seconds at most; `sweep`: the team alone on more "
    "worlds with both sensors, 150 s): "
    "coverage of the true world's surfaces and floor, time to 90 % surface coverage, "
    "collisions and bytes sent. Baselines in the same run: one robot alone, the same robots "
    "without sharing, and frontier exploration on a 5 cm grid from shared point clouds (given "
    "the frames between robots). `processes`: the same team with each robot a `gmmap robot "
    "--explore` process over Zenoh (`gmmap explore`'s default) beside it in one process, "
    "and the wall time of each. `aerial`: one aerial robot exploring in 3D (`gmmap explore "
    "--aerial`, a 32-beam ±45° LiDAR; coverage of the surfaces at every height, `area` the "
    "share of the reachable space known free), with no baseline.",
}
ORDER = tuple(DESCRIPTIONS)
MAX_LIST = 25  # longer lists of scalars are shortened in the page (the JSON has them all)
MAX_COLUMNS = 14  # a table gets at most this many value columns
MAX_LEVEL = 6  # deepest Markdown heading; deeper objects get a bold title

Key = str | int  # an object's key; a list's index, or "name=value" for its item with that figure


@dataclass(frozen=True)
class Row:
    """One scoreboard row: a headline figure of gmmap against its baseline, both read from
    bench-<bench>.json by a path of keys (``also``: more of gmmap's figures shown beside its
    value, e.g. wrong joins), or the baseline a published constant."""

    figure: str
    bench: str
    gmmap: tuple[Key, ...]
    baseline: str
    base: tuple[Key, ...] | float
    data: str
    real: bool
    lower_is_better: bool = False
    unit: str = ""
    scale: float = 1.0  # shown value = JSON value × scale (e.g. m to mm); ratios unchanged
    also: tuple[tuple[str, tuple[Key, ...]], ...] = ()


def _registration(data: str, key: str, real: bool = True) -> tuple[Row, Row]:
    """Mean translation error and time per pair of Point-to-GMM registration against GICP."""
    m = (key, "methods")
    return (
        Row(
            "Registration, mean translation error",
            "registration",
            (*m, "points", "t_error_mean"),
            "small_gicp GICP on the points",
            (*m, "gicp", "t_error_mean"),
            data,
            real,
            lower_is_better=True,
            unit=" mm",
            scale=1000.0,
        ),
        Row(
            "Registration, time per pair",
            "registration",
            (*m, "points", "time_per_pair_s"),
            "small_gicp GICP on the points",
            (*m, "gicp", "time_per_pair_s"),
            data,
            real,
            lower_is_better=True,
            unit=" ms",
            scale=1000.0,
        ),
    )


def _sensors(setup: tuple[str, ...], data: str, real: bool = False) -> Row:
    """Robot pairs whose maps were joined (and joined wrongly) of the pairs that met."""
    return Row(
        "Robot pairs joined, of those that met",
        "sensors",
        (*setup, "joined"),
        "pairs that met",
        (*setup, "met"),
        data,
        real,
        also=(("wrong", (*setup, "wrong")),),
    )


def _explore(title: str, case: str, data: str, also: tuple) -> Row:
    """The exploring team's time to 90 % coverage against the dense grid's, in one case."""
    runs = ("cases", case, "runs")
    return Row(
        f"Time to 90 % coverage, 3 robots exploring{title}",
        "explore",
        (*runs, "gmm", "time_to_90_s"),
        "dense grid from shared point clouds",
        (*runs, "dense", "time_to_90_s"),
        data,
        False,
        lower_is_better=True,
        unit=" s",
        also=also,
    )


# The headline figures, in page order.
SCOREBOARD: tuple[Row, ...] = (
    Row(
        "EM fit time (K = 100, 30 iterations)",
        "em",
        ("gmmap", "time_s"),
        "scikit-learn GaussianMixture",
        ("sklearn", "time_s"),
        "TUM fr1_xyz, 50,000 voxelised points",
        True,
        lower_is_better=True,
        unit=" s",
    ),
    *_registration("TUM fr1_xyz, consecutive 5-frame submaps", "tum_fr1_xyz"),
    *_registration("KITTI 00, consecutive scans", "kitti_00"),
    Row(
        "Bytes per encoded submap",
        "codec",
        ("size", "bytes_mean"),
        "voxelised points as float32",
        ("size", "float32_points_bytes_mean"),
        "TUM fr1_xyz, 5-frame submaps",
        True,
        lower_is_better=True,
        unit=" B",
    ),
    Row(
        "Bytes per encoded submap",
        "codec",
        ("size", "bytes_mean"),
        "the paper's message",
        5099.0,
        "TUM fr1_xyz, 5-frame submaps",
        True,
        lower_is_better=True,
        unit=" B",
    ),
    Row(
        "Place recall@1, shape descriptor on GMMs",
        "place",
        ("held_out_sim_pooled", "shape", "recall_at_1", "gmm"),
        "the same descriptor on raw points",
        ("held_out_sim_pooled", "shape", "recall_at_1", "points"),
        "held-out worlds pooled (LiDAR and depth)",
        False,
    ),
    Row(
        "Place recall at 100 % precision, verified",
        "place",
        ("tum_fr1_xyz_halves", "shape", "verified_at_full_precision", "gmm"),
        "points + small_gicp GICP",
        ("tum_fr1_xyz_halves", "shape", "verified_at_full_precision", "points_gicp"),
        "TUM fr1_xyz split into two robots",
        True,
    ),
    Row(
        "Planner: one GMM step against one A* plan",
        "planner",
        ("scenes", "clutter", "gmm_time_per_step_s"),
        "A* on a 5 cm grid",
        ("scenes", "clutter", "astar_plan_s"),
        "the paper's clutter scene",
        False,
        lower_is_better=True,
        unit=" ms",
        scale=1000.0,
    ),
    Row(
        "Bytes sent per robot, 8-robot fleet",
        "fleet",
        ("fleets", "robots=8", "bytes_sent", "mean"),
        "voxelised points as float32",
        ("fleets", "robots=8", "points_float32_sent_equivalent"),
        "the demo office, 8 robots",
        False,
        lower_is_better=True,
        unit=" B",
    ),
    Row(
        "Bytes on a shared 2 kB/s channel per submap built",
        "channel",
        ("3_robots_2000_Bps_broadcast", "air_bytes_per_submap"),
        "the unicast mesh",
        ("3_robots_2000_Bps_unicast", "air_bytes_per_submap"),
        "the demo office, 3 robots, one channel of 2 kB/s",
        False,
        lower_is_better=True,
        unit=" B",
        also=(("lost", ("3_robots_2000_Bps_broadcast", "lost")),),
    ),
    Row(
        "Submaps delivered on a shared 500 B/s channel",
        "channel",
        ("3_robots_500_Bps_broadcast", "delivered"),
        "the unicast mesh",
        ("3_robots_500_Bps_unicast", "delivered"),
        "the demo office, 3 robots, one channel of 500 B/s",
        False,
        also=(("lost", ("3_robots_500_Bps_broadcast", "lost")),),
    ),
    Row(
        "Submaps delivered on a shared 500 B/s channel",
        "channel",
        ("5_robots_500_Bps_broadcast", "delivered"),
        "the unicast mesh",
        ("5_robots_500_Bps_unicast", "delivered"),
        "the demo office, 5 robots, one channel of 500 B/s",
        False,
        also=(("lost", ("5_robots_500_Bps_broadcast", "lost")),),
    ),
    Row(
        "Depth frames mapped through the real ROS 2 DDS bridge",
        "ros2",
        ("depth_image_30hz", "ros2", "mapped"),
        "frames published",
        ("depth_image_30hz", "ros2", "published"),
        "TUM fr1_xyz depth images at 30 Hz, CycloneDDS → zenoh-bridge-ros2dds",
        True,
        also=(("latency median s", ("depth_image_30hz", "ros2", "latency_median_s")),),
    ),
    _explore(
        "",
        "sensor=lidar",
        "random-office:101, 16-beam LiDAR, 3 robots",
        (
            ("dense bytes / GMM bytes", ("cases", "sensor=lidar", "bytes_dense_over_gmm")),
            ("collisions in every run, LiDAR and depth", ("collisions",)),
        ),
    ),
    _explore(
        " in a second world",
        "world=random-office:102",
        "random-office:102, 16-beam LiDAR, 3 robots",
        (
            (
                "one robot alone",
                ("cases", "world=random-office:102", "runs", "alone", "time_to_90_s"),
            ),
        ),
    ),
    _explore(
        " with depth cameras",
        "sensor=depth",
        "random-office:101, depth camera, 3 robots",
        (("one robot alone", ("cases", "sensor=depth", "runs", "alone", "time_to_90_s")),),
    ),
    _sensors(("lidar16_3_robots",), "office, 16-beam LiDAR, 3 robots × seeds"),
    _sensors(("lidar360_2hz_3_robots",), "office, handheld 360° LiDAR 2 Hz, 3 robots × seeds"),
    _sensors(("lidar360_10hz_3_robots",), "office, handheld 360° LiDAR 10 Hz, 3 robots × seeds"),
    _sensors(("depth_3_robots",), "office, depth camera, 3 robots × seeds"),
    _sensors(
        ("real", "tum_fr1_xyz_second_session_10hz"),
        "TUM fr1_xyz, two sessions (the second at 10 Hz)",
        real=True,
    ),
    _sensors(
        ("real", "tum_fr3_cabinet_halves"),
        "TUM fr3 cabinet, two halves of its loop",
        real=True,
    ),
)


def fmt(value: Any) -> str:
    """A JSON leaf as page text; floats to 4 significant digits, integers exact."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        text = f"{value:.4g}"
        if "e" in text and 1e-4 <= abs(value) < 1e16:
            text = f"{float(text):.0f}"  # large values: 123500, not 1.235e+05
        return text
    if isinstance(value, list):
        shown = ", ".join(fmt(v) for v in value[:MAX_LIST])
        more = len(value) - MAX_LIST
        return f"[{shown}, … {more} more]" if more > 0 else f"[{shown}]"
    return str(value)


def cell(value: Any) -> str:
    """``fmt`` made safe for a Markdown table cell."""
    return fmt(value).replace("|", "\\|").replace("\n", " ")


def code(text: str) -> str:
    """``text`` as inline code, fenced by more backticks than it contains in a row."""
    fence = "`"
    while fence in text:
        fence += "`"
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def is_leaf(value: Any) -> bool:
    """A scalar, or a list (of lists) of scalars: shown in one table cell."""
    if isinstance(value, list):
        return all(is_leaf(v) for v in value)
    return not isinstance(value, dict)


def flatten(obj: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested objects as one level of dotted keys."""
    out: dict[str, Any] = {}
    for key, value in obj.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict) and value:
            out.update(flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def record(value: Any) -> dict[str, Any] | None:
    """A non-empty object whose flattened values are all leaves (one table row), else None."""
    if not isinstance(value, dict) or not value:
        return None
    flat = flatten(value)
    return flat if all(is_leaf(v) for v in flat.values()) else None


def heading(title: str, level: int) -> list[str]:
    """A Markdown heading at ``level``, or a bold title below the deepest one."""
    if level > MAX_LEVEL:
        return [f"**{title}**", ""]
    return [f"{'#' * level} {title}", ""]


def key_table(items: dict[str, Any]) -> list[str]:
    """A two-column table: one figure per row."""
    lines = ["| figure | value |", "|---|---|"]
    lines += [f"| {cell(k)} | {cell(v)} |" for k, v in items.items()]
    return [*lines, ""]


def grid(
    corner: str | None, rows: list[str], columns: list[str], value: Callable[[int, int], Any]
) -> list[str]:
    """A table with ``value(row_index, column_index)`` in its cells, and the row names in a
    first column headed ``corner`` (no such column when ``corner`` is None)."""
    head = [] if corner is None else [corner]
    lines = ["| " + " | ".join(cell(c) for c in [*head, *columns]) + " |"]
    lines.append("|---" * (len(head) + len(columns)) + "|")
    for i, row in enumerate(rows):
        cells = [cell(value(i, j)) for j in range(len(columns))]
        lines.append("| " + " | ".join([cell(row)] * len(head) + cells) + " |")
    return [*lines, ""]


def record_table(
    records: list[dict[str, Any]], labels: list[str], label_column: bool = True
) -> list[str] | None:
    """Flat records as one table: a row per record (led by its label if ``label_column``),
    or a column per record when there are more figures than fit across; None when neither
    fits."""
    columns: list[str] = []
    for r in records:
        columns += [k for k in r if k not in columns]
    if len(columns) <= MAX_COLUMNS:
        corner = "" if label_column else None
        return grid(corner, labels, columns, lambda i, j: records[i].get(columns[j]))
    if len(records) <= MAX_COLUMNS:
        return grid("figure", columns, labels, lambda i, j: records[j].get(columns[i]))
    return None


def labels(items: list[Any]) -> list[str]:
    """Names for list items: their common first key's value when that tells them apart
    (e.g. "robots 4"), else their index."""
    index = [f"[{i}]" for i in range(len(items))]
    if not items or not all(isinstance(v, dict) and v for v in items):
        return index
    key = next(iter(items[0]))
    if any(next(iter(v)) != key or not is_scalar(v[key]) for v in items):
        return index
    names_ = [f"{key} {fmt(v[key])}" for v in items]
    return names_ if len(set(names_)) == len(names_) else index


def is_scalar(value: Any) -> bool:
    """Neither an object nor a list."""
    return not isinstance(value, dict | list)


def similar(records: list[dict[str, Any]]) -> bool:
    """Whether records share most of their figures (worth one table together)."""
    union = set().union(*records)
    common = set(records[0]).intersection(*records[1:])
    return bool(common) and 2 * len(common) >= len(union)


def render(value: Any, level: int) -> list[str]:
    """Markdown lines for one JSON value, whose heading (if any) the caller wrote."""
    if isinstance(value, dict):
        return render_object(value, level)
    if isinstance(value, list) and not is_leaf(value):
        return render_list(value, level)
    return [fmt(value), ""]


def render_object(obj: dict[str, Any], level: int) -> list[str]:
    """Leaf figures as one table; sibling objects of similar flat figures as one table
    together; every other value under its own heading."""
    if not obj:
        return ["(empty)", ""]
    leaves = {k: v for k, v in obj.items() if is_leaf(v)}
    lines = key_table(leaves) if leaves else []
    flat = {k: r for k, v in obj.items() if (r := record(v)) is not None}
    table = None
    if len(flat) >= 2 and similar(list(flat.values())):
        table = record_table(list(flat.values()), list(flat))
    if table is not None:
        lines += table
    for key, value in obj.items():
        if key not in leaves and (table is None or key not in flat):
            lines += heading(key, level) + render(value, level + 1)
    return lines


def render_list(items: list[Any], level: int) -> list[str]:
    """A list holding objects or lists: one table if it can, else one heading per item."""
    names_ = labels(items)
    records = [record(v) for v in items]
    if all(r is not None for r in records):
        table = record_table([r for r in records if r is not None], names_, label_column=False)
        if table is not None:
            return table
    lines: list[str] = []
    for name, value in zip(names_, items, strict=True):
        lines += heading(name, level) + render(value, level + 1)
    return lines


def docstring(name: str) -> str:
    """The module docstring of benchmarks/<name>.py, read without importing it."""
    path = ROOT / "benchmarks" / f"{name}.py"
    try:
        return ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    except (OSError, SyntaxError):
        return ""


def description(name: str) -> str:
    """What the benchmark measures: ours, else its docstring's first line."""
    if name in DESCRIPTIONS:
        return DESCRIPTIONS[name]
    first = docstring(name).strip().splitlines()
    return first[0] if first else "(no description)"


def command(name: str) -> str:
    """How to run the benchmark on its own and save its output where this script reads it."""
    return f".venv/bin/python benchmarks/{name}.py > bench-{name}.json"


def options(name: str) -> str:
    """The options of the benchmark's usage line in its docstring ("" when it has none)."""
    script = f"benchmarks/{name}.py"
    for line in docstring(name).splitlines():
        if script in line:
            return line.split(script, 1)[1].strip()
    return ""


def names(root: Path) -> list[str]:
    """The known benchmarks in order, then any other script or JSON output found."""
    found = {p.stem for p in (ROOT / "benchmarks").glob("*.py")} - {"report", "plots"}
    found |= {p.stem.removeprefix("bench-") for p in root.glob("bench-*.json")}
    return [*ORDER, *sorted(found - set(ORDER))]


def load(path: Path) -> tuple[dict[str, Any] | None, str | None]:
    """The JSON object in ``path``, or None and why not."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        return None, f"unreadable ({type(e).__name__}: {e})"
    if not isinstance(data, dict):
        return None, f"not one JSON object (a {type(data).__name__})"
    return data, None


def section(name: str, data: dict[str, Any]) -> list[str]:
    """One benchmark's section: what it measures, then its figures."""
    lines = [f"## {name}", "", description(name), ""]
    script = f"benchmarks/{name}.py"
    source = f" ({code(script)})" if (ROOT / script).exists() else ""
    lines += [f"From `bench-{name}.json`{source}.", ""]
    return lines + render_object(data, 3)


def not_run(missing: list[tuple[str, str]], total: int) -> list[str]:
    """The benchmarks with no (usable) output, each with how to run it alone."""
    lines = ["## Not run", ""]
    if len(missing) == total:
        lines += ["No benchmark has been run yet.", ""]
    lines += [
        "To run them all, use `make bench`, which saves each benchmark's JSON as "
        "`bench-<name>.json` in the repository root and regenerates this page. To run one, "
        "use the command given for it below, then regenerate the page with "
        "`python benchmarks/report.py`.",
        "",
    ]
    for name, status in missing:
        lines += [f"### {name}", ""]
        if status != "not run":
            lines += [f"Output {status}.", ""]
        lines += [description(name), ""]
        lines += [f"Run alone: {code(command(name))}", ""]
        if options(name):
            lines += [f"Options: {code(options(name))}", ""]
    return lines


def lookup(data: Any, path: tuple[Key, ...]) -> Any:
    """The value at ``path`` in ``data``, or None when a key is missing. In a list, an int is
    an index and "name=value" the first item whose figure ``name`` reads ``value``."""
    for key in path:
        if isinstance(data, dict) and isinstance(key, str):
            data = data.get(key)
        elif isinstance(data, list) and isinstance(key, int):
            data = data[key] if -len(data) <= key < len(data) else None
        elif isinstance(data, list) and isinstance(key, str) and "=" in key:
            name, _, want = key.partition("=")
            found = (v for v in data if isinstance(v, dict) and fmt(v.get(name)) == want)
            data = next(found, None)
        else:
            return None
        if data is None:
            return None
    return data


def number(value: Any) -> float | None:
    """A finite JSON number as a float, else None (booleans are not numbers here)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def ratio(row: Row, ours: float, base: float) -> str:
    """gmmap ÷ baseline, or baseline ÷ gmmap where lower is better: above 1, gmmap is ahead."""
    top, bottom = (base, ours) if row.lower_is_better else (ours, base)
    if bottom == 0:
        return "–"
    which = "baseline / gmmap" if row.lower_is_better else "gmmap / baseline"
    return f"{fmt(top / bottom)} ({which})"


def score(row: Row, benches: dict[str, dict[str, Any]]) -> list[str]:
    """The row's cells: figure, gmmap, baseline, ratio, data, real or simulated."""
    data = benches.get(row.bench)
    ours = None if data is None else number(lookup(data, row.gmmap))
    if isinstance(row.base, tuple):
        base = None if data is None else number(lookup(data, row.base))
    else:
        base = number(row.base)
    also = [(name, None if data is None else number(lookup(data, p))) for name, p in row.also]
    figure = f"{row.figure} ([{row.bench}](#{row.bench}))"
    kind = "real" if row.real else "simulated"
    if ours is None or base is None or any(v is None for _, v in also):
        return [figure, "not run", row.baseline, "–", row.data, kind]
    shown = fmt(ours * row.scale) + row.unit
    if also:
        shown += " (" + ", ".join(f"{name} {fmt(v)}" for name, v in also) + ")"
    baseline = f"{row.baseline}: {fmt(base * row.scale)}{row.unit}"
    return [figure, shown, baseline, ratio(row, ours, base), row.data, kind]


def scoreboard(benches: dict[str, dict[str, Any]], rows: tuple[Row, ...] = SCOREBOARD) -> list[str]:
    """The page's opening table: a row per headline figure, "not run" where its JSON is not
    there, then where each figure is read from."""
    lines = [
        "## Scoreboard",
        "",
        "One row per headline figure, gmmap against the baseline measured in the same run. The "
        "ratio is gmmap / baseline, or baseline / gmmap where lower is better, so above 1 means "
        "gmmap is ahead; for the robot pairs joined it is the share of the pairs that met. Real "
        "data: TUM RGB-D and KITTI recordings; simulated: gmmap's simulator. Each benchmark's "
        "name links to its section.",
        "",
        "| figure | gmmap | baseline | ratio | data | real or simulated |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in score(row, benches)) + " |")
    lines += ["", "<details><summary>Where each figure is read from</summary>", ""]
    for row in rows:
        base = code(dotted(row.base)) if isinstance(row.base, tuple) else f"{fmt(row.base)}"
        lines.append(
            f"- {row.figure}, against {row.baseline}: `bench-{row.bench}.json` "
            f"{code(dotted(row.gmmap))}, baseline {base}"
        )
    return [*lines, "", "</details>", ""]


def dotted(path: tuple[Key, ...]) -> str:
    """A key path as page text."""
    return "".join(
        f"[{k}]" if isinstance(k, int) or "=" in k else f".{k}" if i else k
        for i, k in enumerate(path)
    )


def plot_module() -> Any:
    """benchmarks/plots.py loaded, or None (and why, on stderr) when matplotlib is missing."""
    path = ROOT / "benchmarks" / "plots.py"
    if importlib.util.find_spec("matplotlib") is None or not path.exists():
        print("matplotlib is not importable: the page has no plots", file=sys.stderr)
        return None
    spec = importlib.util.spec_from_file_location("gmmap_bench_plots", path)
    if spec is None or spec.loader is None:
        return None
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except ImportError as e:
        print(f"plots skipped ({e})", file=sys.stderr)
        return None
    return module


def plot_section(benches: dict[str, dict[str, Any]], folder: Path, page_dir: Path) -> list[str]:
    """The key plots as PNGs in ``folder``, linked from a page in ``page_dir``; none (and no
    section) without matplotlib or without the JSON they need."""
    module = plot_module()
    made = [] if module is None else module.plots(benches, folder)
    if not made:
        return []
    lines = ["## Plots", ""]
    for title, png in made:
        link = Path(os.path.relpath(png, page_dir)).as_posix()
        lines += [f"![{title}]({link})", "", f"*{title}*", ""]
    return lines


def page(
    root: Path, plots: Path | None = None, page_dir: Path | None = None
) -> tuple[str, int, int]:
    """The whole page, how many benchmarks it has figures for, and how many there are. With
    ``plots``, the key plots are written there as PNGs and linked from a page in ``page_dir``
    (default: the folder above ``plots``)."""
    every = names(root)
    lines = [
        "# Benchmarks",
        "",
        "Generated by `benchmarks/report.py` from the `bench-<name>.json` files that "
        "`make bench` writes; do not edit by hand. Every benchmark measures gmmap and a named "
        "baseline in the same run, so compare the ratios: absolute times on shared machines "
        "vary from run to run. Floats are rounded to 4 significant digits; the JSON files hold "
        "the full figures.",
        "",
    ]
    benches: dict[str, dict[str, Any]] = {}
    missing: list[tuple[str, str]] = []
    for name in every:
        path = root / f"bench-{name}.json"
        if not path.exists():
            missing.append((name, "not run"))
            continue
        data, error = load(path)
        if data is None:
            missing.append((name, error or "unreadable"))
            continue
        benches[name] = data
    lines += scoreboard(benches)
    if plots is not None:
        lines += plot_section(benches, plots, page_dir or plots.parent)
    for name, data in benches.items():
        lines += section(name, data)
    if missing:
        lines += not_run(missing, len(every))
    return "\n".join(lines).rstrip() + "\n", len(benches), len(every)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT, help="where the bench-*.json are")
    parser.add_argument(
        "--out", default=str(ROOT / "docs" / "benchmarks.md"), help="the page ('-': stdout)"
    )
    parser.add_argument(
        "--no-plots", action="store_true", help="no PNGs (written beside the page otherwise)"
    )
    args = parser.parse_args()
    if args.out == "-":
        sys.stdout.write(page(args.root)[0])
        return
    out = Path(args.out)
    # docs/benchmarks.md's plots go in docs/benchmarks/.
    plots = None if args.no_plots else out.parent / out.stem
    text, present, total = page(args.root, plots, out.parent)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    print(f"wrote {out}: {present} of {total} benchmarks", file=sys.stderr)


if __name__ == "__main__":
    main()
