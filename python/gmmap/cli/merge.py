"""``gmmap merge``: submap folders of several robots → frames between them and global maps."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from gmmap.cli.common import (
    DESCRIPTOR,
    MIN_CONFIDENCE,
    MIN_MATCHES,
    anchor_stamps,
    as_json_option,
    config_option,
    log,
    odometry_drift_option,
    save_trajectories,
    setting,
)
from gmmap.config import Config


@click.command("merge")
@click.argument(
    "folders",
    nargs=-1,
    required=True,
    type=click.Path(exists=True, file_okay=False, path_type=Path),
)
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), help="Write maps here.")
@setting("--top-k", "place.top_k", "Candidates verified per submap.", type=int)
@DESCRIPTOR
@MIN_CONFIDENCE
@MIN_MATCHES
@odometry_drift_option
@click.option(
    "--wrong-matches",
    default=0.0,
    show_default=True,
    help="Robustness test: replace this fraction of verified matches by wrong ones.",
)
@click.option("--seed", default=0, show_default=True, help="Seeds --wrong-matches.")
@config_option
@as_json_option
def command(
    folders: tuple[Path, ...],
    out: Path | None,
    wrong_matches: float,
    seed: int,
    config: Config,
    as_json: bool,
) -> None:
    """Merge submap folders of several robots (from `gmmap build`): place recognition,
    registration, the robust pose graph and a global map per connected group.

    With --out: the global maps (npz, ply, png, rrd), each robot's optimised anchor trajectory
    in its reference robot's frame as TUM text (trajectory_<robot>.txt; with ground truth,
    truth_<robot>.txt beside it, for evo_ape), merge.json and config.yaml."""
    from gmmap.eval.merge import merge

    submaps = read_folders(folders)
    mapper, report = merge(submaps, config, log, wrong_matches, seed)
    if out:
        save_maps(mapper.global_maps(log), out)
        save_trajectories(mapper, out)
        save_truth(mapper, submaps, out)
        (out / "merge.json").write_text(json.dumps(report, indent=1))
        config.save(out)
        log(f"wrote the global map(s), trajectories, merge.json and config.yaml to {out}")
    click.echo(json.dumps(report) if as_json else describe(report, len(submaps)))


def read_folders(folders: tuple[Path, ...]) -> dict:
    from gmmap.mapping.submap import read_submaps

    submaps: dict = {}
    for folder in folders:
        subs = read_submaps(folder)
        if not subs:
            raise click.BadParameter(f"{folder} holds no submaps", param_hint="FOLDERS")
        if subs[0].robot in submaps:
            raise click.BadParameter(
                f"two folders of robot {subs[0].robot!r}: name them with gmmap build --robot",
                param_hint="FOLDERS",
            )
        submaps[subs[0].robot] = subs
    return submaps


def save_truth(mapper, submaps: dict, out: Path) -> None:
    """Beside each ``trajectory_<robot>.txt``, ``truth_<robot>.txt``: the anchors' ground truth
    in the reference robot's true map frame, where every submap of both carries it (then
    ``evo_ape tum truth_b.txt trajectory_b.txt`` compares them as they are)."""
    from gmmap.eval.merge import truth_in_reference
    from gmmap.io.datasets.trajectory import write_trajectory

    for robot, subs in sorted(submaps.items()):
        ref = mapper.frames.reference(robot)
        if any(s.gt_anchor is None for s in (*subs, *submaps[ref])):
            continue
        ordered = sorted(subs, key=lambda s: s.seq)
        truth = truth_in_reference(ordered, submaps[ref])
        header = f"ground truth of {robot}'s anchors in {ref}'s true map frame"
        write_trajectory(out / f"truth_{robot}.txt", anchor_stamps(ordered), truth, header=header)


def save_maps(maps: dict, out: Path) -> None:
    from gmmap.io import viz
    from gmmap.io.datasets.ply import write_ply

    out.mkdir(parents=True, exist_ok=True)
    for ref, gmap in maps.items():
        gmap.save(out / f"globalmap_{ref}.npz")
        points = gmap.sample(200_000, seed=0)
        write_ply(out / f"globalmap_{ref}.ply", points, comment=f"gmmap global map of {ref}")
        gmap.save_png(out / f"globalmap_{ref}.png")
        if viz.available():
            viz.save_rerun(gmap, out / f"globalmap_{ref}.rrd")


def describe(report: dict, robots: int) -> str:
    from gmmap.eval.pairs import describe_pair
    from gmmap.eval.registration import describe_match_errors

    lines = [
        f"{robots} robots, {report['candidates']} candidates, {report['verified']} verified; "
        f"{report['accepted_edges']} edges accepted, {report['rejected_edges']} rejected "
        f"{report['rejected_by']}",
        f"groups: {report['groups']} (reference {report['reference']})",
    ]
    for r in report["robots"]:
        t = np.array(r["to_reference"])
        yaw = np.degrees(np.arctan2(t[1, 0], t[0, 0]))
        lines.append(
            f"{r['name']:>12} → {r['reference']:<12} t = {np.round(t[:3, 3], 3).tolist()} m, "
            f"yaw {yaw:.2f}°, {r['submaps']} submaps"
        )
    lines += [f"error {describe_pair(p)}" for p in report.get("pairs", [])]
    if "ate_before_m" in report:
        ate = {k: _metres(report[f"ate_{k}_m"]) for k in ("before", "after", "aligned_before",
                                                          "aligned_after")}  # fmt: skip
        lines.append(
            f"ATE of the anchors: {ate['before']} before, {ate['after']} after optimisation; "
            f"rigidly aligned {ate['aligned_before']} and {ate['aligned_after']}"
        )
    lines += describe_match_errors(report.get("match_errors", {}))
    if "injected_wrong" in report:
        w = report["injected_wrong"]
        lines.append(f"injected wrong matches: {w['rejected']} of {w['n']} rejected")
    return "\n".join(lines)


def _metres(value: float | None) -> str:
    """A distance to the millimetre, or why there is none (too few anchors to align)."""
    return "–" if value is None else f"{value:.3f} m"
