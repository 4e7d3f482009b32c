"""Plots of a fleet run from its robots' stores and reports (``gmmap demo --plots``,
``benchmarks/links.py``).

- `completeness`: the share of all the fleet's submaps each robot holds over time, from the
  time each submap entered its store (own ones when built, others when they arrived).
- `plot_bytes`: the paper's Fig. 9, cumulative bytes sent over time if every submap went as
  raw points (float32 xyz), as a float32 GMM plus a 1 kB descriptor, and as gmmap encodes it.
- `plot_completeness`: completeness curves, one per run or robot.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from gmmap.fleet.storage.store import Store

DESCRIPTOR_BYTES = 1024  # a 256-float descriptor, as the paper's Fig. 9 adds to the GMM


def completeness(stores: Mapping[str, Path]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per robot, (seconds since the fleet's first submap, its share of all the submaps any
    robot holds), one step per submap its store took in."""
    times, every = {}, set()
    for name, path in stores.items():
        with Store(path, durable=False) as store:
            records = store.submaps()
        times[name] = np.sort([r.received for r in records])
        every.update((r.robot, r.seq) for r in records)
    if not every:
        return {}
    start = min(t[0] for t in times.values() if len(t))
    return {n: (t - start, np.arange(1, len(t) + 1) / len(every)) for n, t in times.items()}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_completeness(
    curves: Mapping[str, tuple[np.ndarray, np.ndarray]], path: Path, title: str
) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    for label, (t, share) in curves.items():
        ax.step(np.r_[0.0, t], np.r_[0.0, share], where="post", label=label)
    ax.set(xlabel="time (s)", ylabel="submaps held / all built", ylim=(0, 1.05), title=title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_bytes(reports: Mapping[str, dict], stores: Mapping[str, Path], path: Path) -> Path:
    """Fig. 9 from each robot's report (per-submap sizes) and its store (when each was built)."""
    sizes: list[tuple[float, Sequence[float]]] = []
    for name, report in reports.items():
        with Store(stores[name], durable=False) as store:
            built = {r.seq: r.received for r in store.submaps(name, own=True)}
        for s in report["submaps"]:
            if s["seq"] in built and s["points_float32"] is not None:
                gmm = s["gmm_float32"] + DESCRIPTOR_BYTES
                sizes.append((built[s["seq"]], (s["points_float32"], gmm, s["wire"])))
    sizes.sort()
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4))
    if sizes:
        t = np.array([x[0] for x in sizes]) - sizes[0][0]
        cumulative = np.cumsum([x[1] for x in sizes], axis=0)
        for k, label in enumerate(("points (float32)", "GMM + descriptor", "gmmap")):
            ax.step(t, cumulative[:, k], where="post", label=label)
    ax.set(xlabel="time (s)", ylabel="bytes sent, whole fleet", yscale="log")
    ax.set_title("bytes per submap over time (the paper's Fig. 9)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def write_plots(out: Path, names: list[str], folder: Path) -> list[str]:
    """The demo's bytes over time (the paper's Fig. 9) and each robot's map completeness over
    time, as PNGs in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    stores = {n: out / f"{n}.sqlite" for n in names}
    reports = {n: json.loads((out / f"{n}.json").read_text()) for n in names}
    paths = [
        plot_bytes(reports, stores, folder / "bytes.png"),
        plot_completeness(completeness(stores), folder / "completeness.png", "each robot"),
    ]
    return [str(p) for p in paths]
