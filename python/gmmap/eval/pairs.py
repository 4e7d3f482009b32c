"""Relative pose errors of robot pairs against ground truth, as `gmmap demo` and `gmmap merge`
report them.

Two figures per pair of robots (a, b) in one group, because under drifting odometry they differ:

* ``t_error`` / ``r_error_deg``: the robots' relative pose where they met, the paper's RelPose.
  For each submap pair (a, i)–(b, j) joined by a match the backend kept, the optimised relative
  pose P(a,i)⁻¹·P(b,j) against the true G(a,i)⁻¹·G(b,j) (anchors); the RMS over those pairs.
  Robots joined only through a third one are measured at their two nearest submaps (true anchor
  positions). This is what a merged map needs to be right: the robots' maps agree where they
  overlap.
* ``frame_t_error`` / ``frame_r_error_deg``: the relation of their map frames (where each
  robot's odometry started, the frames ``to_reference`` gives) against the truth. It carries
  the odometry drift both robots accumulated between their start and the place they met, which
  no match can observe: with 2 %/m drift and a meeting 10 m away it is decimetres and degrees.

Pairs in different groups are listed with None errors.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping

import numpy as np

from gmmap.eval.registration import error_summary, pose_errors
from gmmap.math.geometry import invert

Node = tuple[str, int]


def pair_errors(
    groups: Iterable[Iterable[str]],
    robots: Iterable[str],
    poses: Mapping[Node, np.ndarray],
    truth: Mapping[Node, np.ndarray],
    met: Iterable[tuple[Node, Node]],
    to_reference: Mapping[str, np.ndarray],
    map_to_world: Mapping[str, np.ndarray],
) -> list[dict]:
    """One record per robot pair (sorted names): see the module docstring.

    ``poses``: optimised anchors in a group's reference frame; ``truth``: true anchors (world);
    ``met``: the node pairs of the backend's kept matches; ``to_reference``: estimated map frame
    → reference; ``map_to_world``: each robot's true map frame.
    """
    group_of = {r: i for i, g in enumerate(groups) for r in g}
    met = [tuple(sorted(e)) for e in met]
    out = []
    for a, b in itertools.combinations(sorted(robots), 2):
        record = {"a": a, "b": b, "t_error": None, "r_error_deg": None}
        record |= {"frame_t_error": None, "frame_r_error_deg": None, "matches": 0}
        out.append(record)
        if a not in group_of or group_of.get(a) != group_of.get(b):
            continue
        nodes = [e for e in met if (e[0][0], e[1][0]) == (a, b)]
        record["matches"] = len(nodes)
        nodes = nodes or _nearest(a, b, poses, truth)
        errors = np.array(_optimised_errors(nodes, poses, truth))
        if len(errors):
            t, r = np.sqrt(np.mean(errors**2, axis=0))
            record["t_error"], record["r_error_deg"] = float(t), float(r)
        frame = invert(to_reference[a]) @ to_reference[b]
        t, r = pose_errors(frame, invert(map_to_world[a]) @ map_to_world[b])
        record["frame_t_error"], record["frame_r_error_deg"] = t, r
    return out


def match_errors(
    registered: Iterable[tuple[Node, Node, np.ndarray]],
    optimised: Iterable[tuple[Node, Node]],
    poses: Mapping[Node, np.ndarray],
    truth: Mapping[Node, np.ndarray],
) -> dict:
    """Where robots met, against the ground truth of the two anchors (free of the drift the
    frames' errors carry): each kept registration (target, source, transform) as registered,
    and each kept (target, source) as optimised in ``poses``; pairs without truth are skipped.
    An `error_summary` with an ``optimised`` one inside."""
    as_registered = [
        pose_errors(T, invert(truth[t]) @ truth[s])
        for t, s, T in registered
        if t in truth and s in truth
    ]
    return {
        **error_summary(as_registered),
        "optimised": error_summary(_optimised_errors(optimised, poses, truth)),
    }


def _optimised_errors(nodes, poses, truth) -> list[tuple[float, float]]:
    """The optimised relative pose P(i)⁻¹·P(j) of each (i, j) against the truth; pairs missing
    either are skipped."""
    return [
        pose_errors(invert(poses[i]) @ poses[j], invert(truth[i]) @ truth[j])
        for i, j in nodes
        if i in poses and j in poses and i in truth and j in truth
    ]


def _nearest(a: str, b: str, poses, truth) -> list[tuple[Node, Node]]:
    """The (a, i), (b, j) pair with the closest true anchor positions, as a one-item list."""
    A = [n for n in poses if n[0] == a and n in truth]
    B = [n for n in poses if n[0] == b and n in truth]
    if not A or not B:
        return []
    pa = np.array([truth[n][:3, 3] for n in A])
    pb = np.array([truth[n][:3, 3] for n in B])
    d = np.linalg.norm(pa[:, None] - pb[None], axis=2)
    i, j = np.unravel_index(np.argmin(d), d.shape)
    return [(A[i], B[j])]


def describe_pair(p: dict) -> str:
    """One line for a `pair_errors` record."""
    if p["t_error"] is None:
        return f"{p['a']} ↔ {p['b']}: not connected"
    n = p["matches"]
    where = f"{n} kept match{'es' * (n != 1)}" if n else "nearest submaps"
    return (
        f"{p['a']} ↔ {p['b']}: {p['t_error'] * 100:.1f} cm, {p['r_error_deg']:.2f}° where they "
        f"met ({where}); map frames {p['frame_t_error'] * 100:.1f} cm, "
        f"{p['frame_r_error_deg']:.2f}° (with the drift since their starts)"
    )
