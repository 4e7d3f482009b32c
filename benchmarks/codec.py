"""Wire codec: bytes per submap, and registration accuracy on decoded submaps (Table I).

Prints one JSON object. The submaps and pairs are the Table I harness' own
(``gmmap.eval.registration.build_pairs``: TUM fr1_xyz at pixel stride 2, as in
benchmarks/registration.py, 5-frame Point-to-GMM submaps, full covariances, consecutive pairs
from the identity). Every submap goes through ``gmmap.encode`` and ``gmmap.decode``; reported:

- bytes per submap (mean, max, per 100 components, and submap by submap in ``series``) against
  the mixture as float32 (4 bytes per weight, mean and covariance entry), the paper's
  5,099-byte message, and the voxelised point cloud as float32 (12 bytes per point, what a
  point-based system would send);
- Table I (t/r error mean and RMSE, success rate) of Point-to-GMM registration on the same
  pairs with the float64 mixtures and with the decoded ones, and the relative change; also the
  change over the pairs float64 registers successfully and the mean per-pair change, which a
  failed pair (whose error moves by centimetres under any perturbation, and dominates the
  RMSE) cannot swing;
- encode and decode time per submap;
- a sweep of the distortion D: bytes against accuracy.

    .venv/bin/python benchmarks/codec.py [--quick]
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import gmmap
from gmmap.eval.registration import (
    SUCCESS_DEG,
    SUCCESS_M,
    Pair,
    build_pairs,
    pose_errors,
    run_method,
    summarise,
)
from gmmap.fleet.wire.codec import DEFAULT_DISTORTION, KIND_SUBMAP
from gmmap.io import datasets
from gmmap.mapping.submap import BuildOptions, Submap

DATA = Path(
    os.environ.get("GMMAP_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
PAPER_BYTES = 5099  # the paper's (MR-GMMapping) message for a submap
SWEEP = (1e-4, 3e-4, 1e-3, 3e-3, 1e-2)
METHOD = "points"  # Point-to-GMM


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def unique_submaps(pairs: list[Pair]) -> dict[int, Submap]:
    out = {}
    for p in pairs:
        for s in (p.source[METHOD], p.target[METHOD]):
            out[s.seq] = s
    return out


def round_trip(submaps: dict[int, Submap], distortion: float) -> tuple[dict, dict]:
    """Decoded submaps by seq, and the message of each."""
    messages = {seq: gmmap.encode(s, distortion=distortion) for seq, s in submaps.items()}
    return {seq: gmmap.decode(m) for seq, m in messages.items()}, messages


def table_one(pairs: list[Pair], decoded: dict[int, Submap] | None) -> tuple[dict, np.ndarray]:
    """Table I of Point-to-GMM on the pairs, with the decoded submaps substituted if given."""
    errors, times = [], []
    for p in pairs:
        if decoded is not None:
            src, tgt = p.source[METHOD], p.target[METHOD]
            p = copy.copy(p)
            p.source = {METHOD: decoded[src.seq]}
            p.target = {METHOD: decoded[tgt.seq]}
        estimate, elapsed, _ = run_method(METHOD, p, False, 0.05, None)
        errors.append(pose_errors(estimate, p.truth))
        times.append(elapsed)
    return summarise(errors, times), np.array(errors)


def size_figures(submaps: dict[int, Submap], messages: dict[int, bytes]) -> dict:
    seqs = sorted(submaps)
    size = np.array([len(messages[s]) for s in seqs], dtype=float)
    k = np.array([len(submaps[s].gmm) for s in seqs], dtype=float)
    f32 = np.array([submaps[s].gmm.float32_bytes for s in seqs], dtype=float)
    cloud = np.array([12 * submaps[s].n_points for s in seqs], dtype=float)
    full = k == 100
    return {
        "submaps": len(seqs),
        "components_mean": float(k.mean()),
        "bytes_mean": float(size.mean()),
        "bytes_max": int(size.max()),
        "bytes_per_100_components": float((size / k * 100).mean()),
        "bytes_max_100_component_submaps": int(size[full].max()) if full.any() else None,
        "float32_gmm_bytes_mean": float(f32.mean()),
        "reduction_vs_float32_gmm": float((f32 / size).mean()),
        "reduction_vs_paper_5099": float(PAPER_BYTES / size.mean()),
        "float32_points_bytes_mean": float(cloud.mean()),
        "reduction_vs_float32_points": float((cloud / size).mean()),
        "zstd_chosen": int(sum(messages[s][6] == 1 for s in seqs)),
        "kind_submap": all(messages[s][5] == KIND_SUBMAP for s in seqs),
        # Submap by submap, in the order built: the paper's Fig. 9.
        "series": {
            "bytes": size.astype(int).tolist(),
            "float32_gmm_bytes": f32.astype(int).tolist(),
            "float32_points_bytes": cloud.astype(int).tolist(),
        },
    }


def timings(submaps: dict[int, Submap], messages: dict[int, bytes], repeats: int) -> dict:
    """Median time per submap of encode and decode (best of ``repeats`` per submap)."""
    enc, dec = [], []
    for seq, s in submaps.items():
        best_e = best_d = np.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            gmmap.encode(s)
            t1 = time.perf_counter()
            gmmap.decode(messages[seq])
            t2 = time.perf_counter()
            best_e, best_d = min(best_e, t1 - t0), min(best_d, t2 - t1)
        enc.append(best_e)
        dec.append(best_d)
    return {
        "encode_ms_median": 1e3 * float(np.median(enc)),
        "decode_ms_median": 1e3 * float(np.median(dec)),
    }


def relative(decoded: dict, base: dict) -> dict:
    keys = ("t_error_mean", "t_rmse", "r_error_mean", "r_rmse", "success_rate")
    return {k: decoded[k] / base[k] - 1 for k in keys}


def robust(dec_errors: np.ndarray, base_errors: np.ndarray) -> dict:
    """Changes that one failed pair cannot dominate: over the pairs that float64 registers
    successfully, the relative change of Table I and the mean per-pair change."""
    ok = (base_errors[:, 0] <= SUCCESS_M) & (base_errors[:, 1] <= SUCCESS_DEG)
    zero = [0.0] * int(ok.sum())
    base = summarise(list(map(tuple, base_errors[ok])), zero)
    dec = summarise(list(map(tuple, dec_errors[ok])), zero)
    change = np.abs(dec_errors - base_errors)[ok]
    return {
        "successful_pairs": int(ok.sum()),
        "relative_change_on_successful_pairs": relative(dec, base),
        "per_pair_abs_change_mean_t_mm": 1e3 * float(change[:, 0].mean()),
        "per_pair_abs_change_mean_r_deg": float(change[:, 1].mean()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="20 pairs, no sweep")
    quick = parser.parse_args().quick
    folder = DATA / "tum_fr1_xyz"
    if not folder.exists():
        print(json.dumps({"skipped": f"{folder} not found"}))
        return
    start = time.perf_counter()
    frames = datasets.open(folder, stride=2)
    if quick:
        frames = frames[: 21 * 5]
    log("building submaps (Table I harness)")
    options = BuildOptions(covariance="full")
    pairs = build_pairs(frames, 5, (METHOD,), options, False, seed=0)
    submaps = unique_submaps(pairs)
    log(f"{len(pairs)} pairs, {len(submaps)} submaps; registering float64 and decoded")
    base, base_errors = table_one(pairs, None)
    decoded, messages = round_trip(submaps, DEFAULT_DISTORTION)
    dec, dec_errors = table_one(pairs, decoded)
    out = {
        "data": "TUM fr1_xyz (pixel stride 2), 5-frame Point-to-GMM submaps, full covariances",
        "distortion": DEFAULT_DISTORTION,
        "pairs": len(pairs),
        "size": size_figures(submaps, messages),
        "time": timings(submaps, messages, repeats=3 if quick else 5),
        "table_one_float64": base,
        "table_one_decoded": dec,
        "table_one_relative_change": relative(dec, base),
        "robust": robust(dec_errors, base_errors),
    }
    if not quick:
        sweep = []
        for d in SWEEP:
            log(f"sweep: distortion {d:g}")
            dd, mm = round_trip(submaps, d)
            res, errors = table_one(pairs, dd)
            sizes = np.array([len(m) for m in mm.values()], dtype=float)
            k = np.array([len(submaps[s].gmm) for s in mm], dtype=float)
            sweep.append(
                {
                    "distortion": d,
                    "bytes_mean": float(sizes.mean()),
                    "bytes_per_100_components": float((sizes / k * 100).mean()),
                    "relative_change": relative(res, base),
                    "robust": robust(errors, base_errors),
                }
            )
        out["sweep"] = sweep
    out["elapsed_s"] = time.perf_counter() - start
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
