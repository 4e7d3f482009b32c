"""Regenerate docs/benchmarks.md from the benchmarks' JSON outputs.

Each script benchmarks/<name>.py prints one JSON object, which ``make bench`` saves as
bench-<name>.json in the repository root. This script reads every such file that exists and
writes one section per benchmark: a sentence on what it measures and against which baseline,
then its figures. The figures are the JSON walked generically:

- an object's scalars (and lists of scalars) form a two-column table, figure and value;
- sibling objects whose figures are flat and mostly shared form one table, a row each;
- a list of flat objects forms one table, a row per object (nested keys dotted), or a column
  per object when the figures are too many to fit across;
- anything else goes under its own sub-heading, walked the same way.

Floats are rounded to 4 significant digits. Integers, which are counts, stay exact. Lists of
more than 25 values are shortened (the JSON files have them all). Benchmarks without a
readable JSON file are listed as not run, each with the command that runs it.

    python benchmarks/report.py [--root DIR] [--out FILE|-]

Python 3.10+, standard library only. It imports nothing of gmmap, so it runs anywhere.
"""

from __future__ import annotations

import argparse
import ast
import json
import math
import sys
from collections.abc import Callable
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
    "planner": "Time per step of the GMM gradient-field planner on the paper's four scenes, "
    "and how it grows with the map's component count. Baseline: one full A* plan on a 5 cm "
    "grid of the same scans (`astar_over_gmm`: how many GMM steps one A* plan costs).",
}
ORDER = tuple(DESCRIPTIONS)
MAX_LIST = 25  # longer lists of scalars are shortened in the page (the JSON has them all)
MAX_COLUMNS = 14  # a table gets at most this many value columns
MAX_LEVEL = 6  # deepest Markdown heading; deeper objects get a bold title


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
    found = {p.stem for p in (ROOT / "benchmarks").glob("*.py") if p.stem != "report"}
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


def page(root: Path) -> tuple[str, int, int]:
    """The whole page, how many benchmarks it has figures for, and how many there are."""
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
    missing: list[tuple[str, str]] = []
    present = 0
    for name in every:
        path = root / f"bench-{name}.json"
        if not path.exists():
            missing.append((name, "not run"))
            continue
        data, error = load(path)
        if data is None:
            missing.append((name, error or "unreadable"))
            continue
        lines += section(name, data)
        present += 1
    if missing:
        lines += not_run(missing, len(every))
    return "\n".join(lines).rstrip() + "\n", present, len(every)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=ROOT, help="where the bench-*.json are")
    parser.add_argument(
        "--out", default=str(ROOT / "docs" / "benchmarks.md"), help="the page ('-': stdout)"
    )
    args = parser.parse_args()
    text, present, total = page(args.root)
    if args.out == "-":
        sys.stdout.write(text)
        return
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    print(f"wrote {out}: {present} of {total} benchmarks", file=sys.stderr)


if __name__ == "__main__":
    main()
