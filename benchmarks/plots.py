"""The key plots of docs/benchmarks.md, drawn from the benchmarks' JSON outputs.

``benchmarks/report.py`` calls ``plots(benches, folder)`` when matplotlib is importable, with
every bench-<name>.json it read, and links the PNGs it gets back right after the scoreboard.
Each plot is drawn only when its JSON and keys are there:

- bytes per submap, submap by submap as the paper's Fig. 9, and their means by representation
  (``codec``: the voxelised point cloud as float32, the mixture as float32, the paper's
  5,099-byte message, gmmap's encoded submap);
- bytes each robot sends against what a point-cloud system would send, by fleet size
  (``fleet``);
- registration error distributions (percentiles and mean) against GICP on every data set
  both ran on (``registration``);
- place recognition: recall@N curves when the JSON has the ``recall_at_n`` lists, else
  recall@1 and recall@top-1 %, on GMMs against raw points, per place set (``place``).

Matplotlib with the Agg backend; nothing of gmmap, so it runs anywhere report.py does.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

PAPER_BYTES = 5099  # the paper's message per submap
METADATA = {"Software": None}  # no version stamp: the PNGs change only when the figures do


def get(data: Any, *path: str) -> Any:
    """The value at ``path`` in nested objects, or None."""
    for key in path:
        if not isinstance(data, dict):
            return None
        data = data.get(key)
    return data


def num(value: Any) -> float | None:
    """A finite JSON number as a float, else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def save(fig: Any, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight", metadata=METADATA)
    plt.close(fig)
    return path


def bars(
    ax: Any, groups: list[str], series: dict[str, list[float]], colors: list[str] | None = None
) -> None:
    """Grouped bars: one group per name in ``groups``, one bar per series in each."""
    width = 0.8 / max(len(series), 1)
    for i, (label, values) in enumerate(series.items()):
        xs = [g + (i - (len(series) - 1) / 2) * width for g in range(len(groups))]
        ax.bar(xs, values, width, label=label, color=None if colors is None else colors[i])
    ax.set_xticks(range(len(groups)), groups, rotation=20, ha="right")


def bytes_per_submap(benches: dict[str, Any], folder: Path) -> Path | None:
    """Bytes per submap by representation, means as bars (codec)."""
    size = get(benches.get("codec"), "size")
    found = {
        "point cloud\n(float32)": num(get(size, "float32_points_bytes_mean")),
        "GMM\n(float32)": num(get(size, "float32_gmm_bytes_mean")),
        "the paper's\nmessage": float(PAPER_BYTES),
        "gmmap\n(encoded)": num(get(size, "bytes_mean")),
    }
    if found["gmmap\n(encoded)"] is None:
        return None
    shown = {k: v for k, v in found.items() if v is not None}
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.bar(list(shown), list(shown.values()), color=["0.6"] * (len(shown) - 1) + ["C0"])
    for x, v in enumerate(shown.values()):
        ax.annotate(f"{v:,.0f} B", (x, v), ha="center", va="bottom", fontsize=8)
    ax.set(yscale="log", ylabel="bytes per submap (mean, log)", title="Bytes per submap")
    return save(fig, folder / "bytes_per_submap.png")


def bytes_over_time(benches: dict[str, Any], folder: Path) -> Path | None:
    """The paper's Fig. 9: each submap's bytes in the order built, by representation (codec)."""
    series = get(benches.get("codec"), "size", "series")
    lines = {
        "point cloud (float32)": ("float32_points_bytes", "0.6"),
        "GMM (float32)": ("float32_gmm_bytes", "C1"),
        "gmmap (encoded)": ("bytes", "C0"),
    }
    found = {k: (get(series, key), color) for k, (key, color) in lines.items()}
    found = {k: (v, c) for k, (v, c) in found.items() if isinstance(v, list) and v}
    if "gmmap (encoded)" not in found:
        return None
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for label, (values, color) in found.items():
        mean = sum(values) / len(values)
        ax.plot(range(1, len(values) + 1), values, color=color, label=f"{label}: {mean:,.0f} B")
    ax.axhline(
        PAPER_BYTES, color="C3", ls="--", lw=1, label=f"the paper's message: {PAPER_BYTES:,} B"
    )
    data = get(benches.get("codec"), "data")
    title = "Bytes per submap" + (f", {data.split(',')[0]}" if isinstance(data, str) else "")
    ax.set(yscale="log", xlabel="submap, in the order built", ylabel="bytes (log)", title=title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, folder / "bytes_over_time.png")


def fleet_bytes(benches: dict[str, Any], folder: Path) -> Path | None:
    """Bytes each robot sends against the point-cloud equivalent, by fleet size (fleet)."""
    rows = get(benches.get("fleet"), "fleets")
    if not isinstance(rows, list):
        return None
    points = []
    for r in rows:
        n, sent = num(get(r, "robots")), num(get(r, "bytes_sent", "mean"))
        cloud = num(get(r, "points_float32_sent_equivalent"))
        if n is not None and sent is not None and cloud is not None:
            points.append((n, sent, cloud))
    if not points:
        return None
    fig, ax = plt.subplots(figsize=(6, 3.6))
    bars(
        ax,
        [f"{n:.0f} robots" for n, _, _ in points],
        {
            "point cloud (float32)": [c for _, _, c in points],
            "gmmap": [s for _, s, _ in points],
        },
        ["0.6", "C0"],
    )
    ax.set(yscale="log", ylabel="bytes sent per robot (mean, log)", title="A fleet's traffic")
    ax.legend(loc="center right", framealpha=1)
    return save(fig, folder / "fleet_bytes.png")


def registration_errors(benches: dict[str, Any], folder: Path) -> Path | None:
    """Translation and rotation error distributions, Point-to-GMM against GICP on the same
    pairs: boxes from the 25th to the 75th percentile, whiskers at the 5th and 95th, a line at
    the median and a dot at the mean."""
    data = benches.get("registration")
    if not isinstance(data, dict):
        return None

    def quantiles(k: str, m: str, e: str) -> list[float] | None:
        q = get(data[k], "methods", m, f"{e}_error_quantiles")
        ok = isinstance(q, list) and len(q) == 5 and all(num(v) is not None for v in q)
        return [float(v) for v in q] if ok else None

    sets = [
        k
        for k, v in data.items()
        if all(quantiles(k, m, e) for m in ("points", "gicp") for e in ("t", "r"))
    ]
    if not sets:
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    methods = (("points", "gmmap", "C0"), ("gicp", "GICP", "C1"))
    for ax, (e, unit, scale) in zip(axes, (("t", "mm", 1000.0), ("r", "°", 1.0)), strict=True):
        for i, (m, name, color) in enumerate(methods):
            stats = []
            for k in sets:
                lo, q1, med, q3, hi = (max(v * scale, 1e-4) for v in quantiles(k, m, e))
                mean = num(get(data[k], "methods", m, f"{e}_error_mean"))
                stats.append({"whislo": lo, "q1": q1, "med": med, "q3": q3, "whishi": hi,
                              "mean": max((mean or 0.0) * scale, 1e-4), "label": k})  # fmt: skip
            boxes = ax.bxp(
                stats, positions=[g + (i - 0.5) * 0.38 for g in range(len(sets))], widths=0.32,
                showfliers=False, showmeans=True, patch_artist=True,
                meanprops={"marker": "o", "markersize": 3, "markerfacecolor": "k"},
                medianprops={"color": "k"},
            )  # fmt: skip
            for box in boxes["boxes"]:
                box.set(facecolor=color, alpha=0.6)
            boxes["boxes"][0].set_label(name)
        ax.set_xticks(range(len(sets)), sets, rotation=20, ha="right")
        what = "translation" if e == "t" else "rotation"
        ax.set(yscale="log", ylabel=f"{what} error ({unit}, log)", title=f"{what} error")
    axes[0].legend(fontsize=8)
    fig.suptitle("Registration against GICP, same pairs (5-25-50-75-95th percentiles, mean)")
    return save(fig, folder / "registration_errors.png")


def place_recall(benches: dict[str, Any], folder: Path) -> Path | None:
    """Recall@N curves of each place set and descriptor, GMMs against raw points; recall@1
    and recall@top-1 % as bars when the JSON has no curves."""
    data = benches.get("place")
    if not isinstance(data, dict):
        return None
    cases = {
        f"{name}, {d}": result
        for name, value in data.items()
        if isinstance(value, dict)
        for d, result in value.items()
        if isinstance(result, dict)
    }
    curves = {
        case: {k: r["recall_at_n"][k] for k in ("gmm", "points")}
        for case, r in cases.items()
        if all(
            isinstance(get(r, "recall_at_n", k), list)
            and all(num(v) is not None for v in r["recall_at_n"][k])
            for k in ("gmm", "points")
        )
    }
    if curves:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for i, (case, c) in enumerate(curves.items()):
            for k, style in (("gmm", "-"), ("points", ":")):
                n = range(1, len(c[k]) + 1)
                label = f"{case} ({'GMM' if k == 'gmm' else 'raw points'})"
                ax.plot(n, c[k], style, color=f"C{i % 10}", label=label)
        ax.set(xlabel="N", ylabel="recall@N", ylim=(0, 1.02), title="Place recognition")
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
        return save(fig, folder / "place_recall.png")
    keys = [(f"recall_at_{a}", b) for a in ("1", "1pct") for b in ("gmm", "points")]
    rows = {
        case: [num(get(r, a, b)) for a, b in keys]
        for case, r in cases.items()
        if all(num(get(r, a, b)) is not None for a, b in keys)
    }
    if not rows:
        return None
    fig, ax = plt.subplots(figsize=(10, 4))
    labels = ("recall@1, GMM", "recall@1, raw points", "recall@top-1 %, GMM", "recall@top-1 %, raw")
    bars(
        ax, list(rows), {lab: [v[i] or 0.0 for v in rows.values()] for i, lab in enumerate(labels)}
    )
    ax.set(ylabel="recall", ylim=(0, 1.02), title="Place recognition, GMMs against raw points")
    ax.legend(fontsize=8)
    return save(fig, folder / "place_recall.png")


PLOTS: tuple[tuple[str, Callable[[dict[str, Any], Path], Path | None]], ...] = (
    (
        "Bytes per submap over a recording, by representation (codec; the paper's Fig. 9)",
        bytes_over_time,
    ),
    ("Bytes per submap by representation, means (codec)", bytes_per_submap),
    ("Bytes sent per robot against point clouds, by fleet size (fleet)", fleet_bytes),
    ("Registration error distributions against GICP (registration)", registration_errors),
    ("Place recognition recall, GMMs against raw points (place)", place_recall),
)


def plots(benches: dict[str, Any], folder: Path) -> list[tuple[str, Path]]:
    """Every plot whose JSON is there, as a PNG in ``folder``: (title, path) for each."""
    made = []
    for title, draw in PLOTS:
        path = draw(benches, Path(folder))
        if path is not None:
            made.append((title, path))
    return made
