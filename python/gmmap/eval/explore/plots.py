"""Coverage over time of exploration runs (the optional ``eval`` extra: matplotlib)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def plot_coverage(runs: dict, path: str | Path) -> Path:
    """Surface coverage (solid) and the floor (or, flying, the space) known free (dashed) over
    simulated time, one colour per run; the legend gives each run's bytes sent."""
    fig, ax = plt.subplots(figsize=(7, 4))
    for i, (name, r) in enumerate(runs.items()):
        if not r.curve:
            continue
        t, surface, area = zip(*r.curve, strict=True)
        kb = sum(r.bytes_per_robot) / 1e3
        ax.plot(t, surface, color=f"C{i}", label=f"{name} ({r.robots} robots, {kb:.0f} kB)")
        ax.plot(t, area, color=f"C{i}", linestyle="--", alpha=0.6)
    ax.axhline(0.9, color="grey", linewidth=0.5)
    ax.set(xlabel="simulated time (s)", ylabel="coverage", ylim=(0, 1))
    ax.set_title(f"{next(iter(runs.values())).world}: surface (solid), known free (dashed)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
