//! Starts for a registration without a guess: where, for each yaw about +z, the translation
//! that lays one mixture's components onto the other's piles up.
//!
//! For a fixed rotation R the correlation ∫ T(f) g = Σᵢⱼ πᵢ ρⱼ N(t; νⱼ − Rμᵢ, Sᵢⱼ) is a mixture
//! over the translation t: each pair of components votes for the translation that lays one on
//! the other. Each vote is cast at its centre with the height of its own kernel,
//! πᵢ ρⱼ / sqrt(det Sᵢⱼ) (Sᵢⱼ = RΣᵢRᵀ + Λⱼ + 2b²I: a flat floor pair, alike in every
//! position, weighs little), and the grid of votes is blurred by b. Its local maxima are the
//! correlation's modes at that blur over every translation at once, where starts with the
//! centroids aligned find only the modes near them: two submaps that overlap in part are
//! aligned far from their centroids.

use crate::gmm::Gmm;
use crate::register::{rotate_cov, Pose};
use crate::CoreError;
use rayon::prelude::*;

/// Cells per axis at most: a wider extent takes coarser cells.
const MAX_CELLS: f64 = 160.0;

/// A start: a pose (source → target) and the blurred vote there.
#[derive(Debug, Clone, Copy)]
pub struct Hypothesis {
    pub pose: Pose,
    pub score: f64,
}

/// The `per_yaw` highest local maxima of the blurred votes for each of `yaws` rotations about
/// +z, all of them best first. `cell`: the grid's spacing (units of the means), `blur`: the
/// standard deviation b of the votes' kernel.
pub fn hypotheses(
    source: &Gmm,
    target: &Gmm,
    yaws: usize,
    cell: f64,
    blur: f64,
    per_yaw: usize,
) -> Result<Vec<Hypothesis>, CoreError> {
    if source.is_empty() || target.is_empty() {
        return Err(CoreError::InvalidArgument("empty mixture".into()));
    }
    if !(cell > 0.0 && blur > 0.0 && cell.is_finite() && blur.is_finite()) {
        return Err(CoreError::InvalidArgument(
            "cell and blur must be finite and > 0".into(),
        ));
    }
    let yaws = yaws.max(1);
    let mut out: Vec<Hypothesis> = (0..yaws)
        .into_par_iter()
        .flat_map_iter(|k| {
            let yaw = 2.0 * std::f64::consts::PI * k as f64 / yaws as f64;
            peaks(source, target, Pose::yaw(yaw), cell, blur, per_yaw)
        })
        .collect();
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    Ok(out)
}

/// The votes for one rotation (`rotation.t` is zero), blurred, and their highest maxima.
fn peaks(
    source: &Gmm,
    target: &Gmm,
    rotation: Pose,
    cell: f64,
    blur: f64,
    per_yaw: usize,
) -> Vec<Hypothesis> {
    let b2 = 2.0 * blur * blur;
    let moved: Vec<([f64; 3], crate::Sym3)> = (0..source.len())
        .map(|i| {
            let s = rotate_cov(&rotation.r, &source.covariances[i]).add_diag(b2);
            (rotation.apply(&source.means[i]), s)
        })
        .collect();
    // The grid spans every pair's translation, with room for the blur.
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for (p, _) in &moved {
        for v in &target.means {
            for a in 0..3 {
                lo[a] = lo[a].min(v[a] - p[a]);
                hi[a] = hi[a].max(v[a] - p[a]);
            }
        }
    }
    let span = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    let cell = cell.max(span / MAX_CELLS);
    let pad = (3.0 * blur / cell).ceil() as usize + 1;
    let dims: [usize; 3] =
        [0, 1, 2].map(|a| ((hi[a] - lo[a]) / cell).ceil() as usize + 2 * pad + 1);
    let origin: [f64; 3] = [0, 1, 2].map(|a| lo[a] - pad as f64 * cell);
    let mut grid = vec![0.0f64; dims[0] * dims[1] * dims[2]];
    let at = |x: usize, y: usize, z: usize| (x * dims[1] + y) * dims[2] + z;
    for (i, (p, s)) in moved.iter().enumerate() {
        for (j, v) in target.means.iter().enumerate() {
            let det = s.add(&target.covariances[j]).det();
            if det <= 0.0 {
                continue;
            }
            let w = source.weights[i] * target.weights[j] / det.sqrt();
            // Trilinear: the vote split between the eight cells about its centre.
            let f: [f64; 3] = [0, 1, 2].map(|a| (v[a] - p[a] - origin[a]) / cell);
            let c = f.map(|x| x.floor());
            let r = [0, 1, 2].map(|a| f[a] - c[a]);
            let c = c.map(|x| x as usize);
            for corner in 0..8 {
                let d = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
                let share: f64 = (0..3)
                    .map(|a| if d[a] == 1 { r[a] } else { 1.0 - r[a] })
                    .product();
                grid[at(c[0] + d[0], c[1] + d[1], c[2] + d[2])] += w * share;
            }
        }
    }
    blur_grid(&mut grid, dims, blur / cell);
    local_maxima(&grid, dims, per_yaw)
        .into_iter()
        .map(|(score, idx)| {
            let mut pose = rotation;
            pose.t = [0, 1, 2].map(|a| origin[a] + idx[a] as f64 * cell);
            Hypothesis { pose, score }
        })
        .collect()
}

/// The `keep` highest cells above all 26 neighbours (ties to the first), best first.
fn local_maxima(grid: &[f64], dims: [usize; 3], keep: usize) -> Vec<(f64, [usize; 3])> {
    let at = |x: usize, y: usize, z: usize| (x * dims[1] + y) * dims[2] + z;
    let mut found: Vec<(f64, [usize; 3])> = Vec::new();
    for x in 1..dims[0] - 1 {
        for y in 1..dims[1] - 1 {
            for z in 1..dims[2] - 1 {
                let v = grid[at(x, y, z)];
                if v <= 0.0 {
                    continue;
                }
                let peak = (0..27).filter(|&n| n != 13).all(|n| {
                    let w = grid[at(x + n / 9 - 1, y + (n / 3) % 3 - 1, z + n % 3 - 1)];
                    w < v || (w == v && n > 13)
                });
                if peak {
                    found.push((v, [x, y, z]));
                }
            }
        }
    }
    found.sort_by(|a, b| b.0.total_cmp(&a.0));
    found.truncate(keep);
    found
}

/// Separable Gaussian blur of standard deviation `sigma` cells, truncated at 3 sigma.
fn blur_grid(grid: &mut [f64], dims: [usize; 3], sigma: f64) {
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius)
        .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
        .collect();
    let strides = [dims[1] * dims[2], dims[2], 1];
    let mut line = Vec::new();
    for axis in 0..3 {
        let n = dims[axis];
        let (o1, o2) = ((axis + 1) % 3, (axis + 2) % 3);
        for u in 0..dims[o1] {
            for w in 0..dims[o2] {
                let base = u * strides[o1] + w * strides[o2];
                line.clear();
                line.extend((0..n).map(|k| grid[base + k * strides[axis]]));
                for k in 0..n {
                    let mut acc = 0.0;
                    for (m, kv) in kernel.iter().enumerate() {
                        let src = k as isize + m as isize - radius;
                        if src >= 0 && (src as usize) < n {
                            acc += kv * line[src as usize];
                        }
                    }
                    grid[base + k * strides[axis]] = acc;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Sym3;

    #[test]
    fn the_best_vote_lies_at_the_translation_of_a_moved_copy() {
        // Scattered flat components over 10 m, then the copy moved by a yaw of 90° and 3 m.
        let mut rng = crate::rng::Rng::new(7);
        let n = 60;
        let means: Vec<[f64; 3]> = (0..n)
            .map(|_| {
                [
                    10.0 * rng.uniform(),
                    10.0 * rng.uniform(),
                    2.0 * rng.uniform(),
                ]
            })
            .collect();
        let covs = vec![Sym3::diag(0.09, 0.02, 0.0004); n];
        let target = Gmm {
            weights: vec![1.0 / n as f64; n],
            means: means.clone(),
            covariances: covs.clone(),
        };
        let mut truth = Pose::yaw(std::f64::consts::FRAC_PI_2);
        truth.t = [3.0, -1.0, 0.2];
        let inverse_moved: Vec<[f64; 3]> = means
            .iter()
            .map(|m| {
                let d = [m[0] - truth.t[0], m[1] - truth.t[1], m[2] - truth.t[2]];
                [d[1], -d[0], d[2]] // Rᵀ d for a yaw of 90°
            })
            .collect();
        let rotated: Vec<Sym3> = covs.iter().map(|c| Sym3::diag(c.yy, c.xx, c.zz)).collect();
        let source = Gmm {
            weights: vec![1.0 / n as f64; n],
            means: inverse_moved,
            covariances: rotated,
        };
        let found = hypotheses(&source, &target, 24, 0.25, 0.25, 3).unwrap();
        let best = found[0].pose;
        let dt: f64 = (0..3)
            .map(|a| (best.t[a] - truth.t[a]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(dt < 0.3, "best vote {:?} vs {:?}", best.t, truth.t);
        assert!((best.r[1][0] - 1.0).abs() < 1e-9, "yaw of the best vote");
        assert!(found.windows(2).all(|w| w[0].score >= w[1].score));
        assert!(hypotheses(&source, &target, 24, 0.0, 0.25, 3).is_err());
    }
}
