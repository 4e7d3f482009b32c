//! Seeding for EM: greedy k-means++ (as scikit-learn does it) or distinct random points, then a
//! hard nearest-centre assignment that gives EM its first means, covariances and weights.

use crate::rng::Rng;
use rayon::prelude::*;

/// k-means++ works on at most this many points: enough to place the seeds well, bounded cost.
const MAX_SEED_POINTS: usize = 20_000;
const CHUNK: usize = 4096;

#[inline(always)]
fn dist2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
}

/// A deterministic subsample (partial Fisher-Yates) when there are more points than needed.
fn subsample(points: &[[f64; 3]], limit: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    if points.len() <= limit {
        return points.to_vec();
    }
    let mut idx: Vec<usize> = (0..points.len()).collect();
    for i in 0..limit {
        let j = i + rng.below(points.len() - i);
        idx.swap(i, j);
    }
    idx[..limit].iter().map(|&i| points[i]).collect()
}

/// Greedy k-means++: each new centre is the best of 2 + ln k candidates drawn ∝ D².
/// Returns fewer than `k` centres when there are fewer distinct points.
pub(crate) fn kmeans_pp(points: &[[f64; 3]], k: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    let pts = subsample(points, MAX_SEED_POINTS.max(50 * k), rng);
    let trials = 2 + (k as f64).ln() as usize;
    let mut centres = vec![pts[rng.below(pts.len())]];
    let mut closest: Vec<f64> = pts.par_iter().map(|p| dist2(p, &centres[0])).collect();
    let mut cumulative = vec![0.0; pts.len()];
    while centres.len() < k {
        let mut total = 0.0;
        for (c, d) in cumulative.iter_mut().zip(&closest) {
            total += d;
            *c = total;
        }
        if total <= 0.0 {
            break; // every point coincides with a centre
        }
        let candidates: Vec<[f64; 3]> = (0..trials)
            .map(|_| {
                let target = rng.uniform() * total;
                let i = cumulative
                    .partition_point(|&c| c <= target)
                    .min(pts.len() - 1);
                pts[i]
            })
            .collect();
        // Potential of each candidate, summed chunk by chunk in a fixed order (deterministic).
        let partial: Vec<Vec<f64>> = pts
            .par_chunks(CHUNK)
            .zip(closest.par_chunks(CHUNK))
            .map(|(p, d)| {
                candidates
                    .iter()
                    .map(|c| p.iter().zip(d).map(|(x, &dx)| dx.min(dist2(x, c))).sum())
                    .collect()
            })
            .collect();
        let potential = |t: usize| partial.iter().map(|v| v[t]).sum::<f64>();
        let best = (0..trials)
            .map(|t| (potential(t), t))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, t)| candidates[t])
            .expect("at least two trials");
        if best_is_new(&centres, &best) {
            closest
                .par_iter_mut()
                .zip(&pts)
                .for_each(|(d, p)| *d = d.min(dist2(p, &best)));
            centres.push(best);
        } else {
            break;
        }
    }
    centres
}

fn best_is_new(centres: &[[f64; 3]], c: &[f64; 3]) -> bool {
    !centres.iter().any(|x| x == c)
}

/// `k` random points, duplicates of an earlier pick skipped (so fewer when points repeat).
pub(crate) fn random_points(points: &[[f64; 3]], k: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    let mut picked = subsample(points, k, rng);
    let mut seen = Vec::with_capacity(picked.len());
    picked.retain(|p| {
        let new = best_is_new(&seen, p);
        if new {
            seen.push(*p);
        }
        new
    });
    picked
}

/// Index of the nearest centre of each point (ties go to the lower index).
pub(crate) fn nearest(points: &[[f64; 3]], centres: &[[f64; 3]]) -> Vec<usize> {
    points
        .par_iter()
        .map(|p| {
            let mut best = (f64::INFINITY, 0);
            for (j, c) in centres.iter().enumerate() {
                let d = dist2(p, c);
                if d < best.0 {
                    best = (d, j);
                }
            }
            best.1
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kmeans_pp_stops_at_distinct_points() {
        let pts = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ];
        let c = kmeans_pp(&pts, 10, &mut Rng::new(0));
        assert_eq!(c.len(), 2);
        assert_eq!(random_points(&pts, 10, &mut Rng::new(0)).len(), 2);
    }

    #[test]
    fn kmeans_pp_finds_separated_clusters() {
        let mut rng = Rng::new(3);
        let blobs = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]];
        let pts: Vec<[f64; 3]> = (0..300)
            .map(|i| {
                let b = blobs[i % 3];
                [
                    b[0] + rng.uniform(),
                    b[1] + rng.uniform(),
                    b[2] + rng.uniform(),
                ]
            })
            .collect();
        let c = kmeans_pp(&pts, 3, &mut Rng::new(1));
        let labels = nearest(&blobs, &c);
        let mut sorted = labels.clone();
        sorted.sort();
        assert_eq!(sorted, vec![0, 1, 2], "one centre per blob");
    }
}
