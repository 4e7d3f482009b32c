"""``gmmap bench``: benchmarks against named baselines (ratios, measured in one run)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gmmap.cli.common import log


@click.group("bench")
def command() -> None:
    """Benchmarks against named baselines (ratios, measured in one run)."""


@command.command("em")
@click.option("--points", "n", default=50_000, show_default=True, help="Points to fit.")
@click.option("--components", "k", default=100, show_default=True)
@click.option("--iterations", default=30, show_default=True, help="Fixed EM iterations (tol=0).")
@click.option(
    "--covariance", type=click.Choice(["diag", "full"]), default="diag", show_default=True
)
@click.option(
    "--data",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    help="TUM RGB-D folder (default: ../shared/data/tum_fr1_xyz, else the bundled slice).",
)
@click.option("--repeats", default=3, show_default=True, help="Best time of this many runs.")
@click.option("--scaling", is_flag=True, help="Also time N = 10k…500k and K = 25…400.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def bench_em(
    n: int,
    k: int,
    iterations: int,
    covariance: str,
    data: Path | None,
    repeats: int,
    scaling: bool,
    as_json: bool,
) -> None:
    """EM speed and log-likelihood against scikit-learn's GaussianMixture."""
    from gmmap.eval import bench as b

    root = data or b.default_scene()
    log(f"scene: {root}")
    pts = b.scene_points(n, root)
    log(f"comparing on {len(pts):,} points, K={k}, {iterations} iterations")
    result = b.em_comparison(pts, k, iterations, covariance, repeats)
    result["scene"] = str(root)
    if scaling:
        big = b.scene_points(500_000, root, voxel=None, frames=80)
        ns = [10_000, 50_000, 100_000, 200_000, 500_000]
        result["scaling_n"] = b.em_scaling(ns, [k], big, progress=log)
        result["scaling_k"] = b.em_scaling([n], [25, 50, 100, 200, 400], pts, progress=log)
    if as_json:
        click.echo(json.dumps(result, indent=2))
        return
    g, s = result["gmmap"], result["sklearn"]
    click.echo(f"gmmap    {g['time_s'] * 1e3:8.1f} ms  log-likelihood {g['log_likelihood']:.4f}")
    if s is None:
        click.echo("sklearn  not installed (pip install scikit-learn): no baseline")
    else:
        click.echo(
            f"sklearn  {s['time_s'] * 1e3:8.1f} ms  log-likelihood {s['log_likelihood']:.4f}"
        )
        click.echo(
            f"speed-up {result['speedup']:.1f}x, log-likelihood difference "
            f"{result['log_likelihood_diff']:+.4f}"
        )
    for key in ("scaling_n", "scaling_k"):
        for row in result.get(key, []):
            click.echo(
                f"N={row['points']:>7,} K={row['components']:>3}: "
                f"{row['time_s'] * 1e3:8.1f} ms, peak +{row['peak_extra_mb']:.1f} MB"
            )
