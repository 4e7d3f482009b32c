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
///
/// Two parallel passes per centre over fixed chunks (so sums, and the result, do not depend on
/// the thread count): one updates the nearest-centre distances and totals them per chunk, one
/// scores all candidates. Candidates are drawn chunk first, then within the chunk.
pub(crate) fn kmeans_pp(points: &[[f64; 3]], k: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    let pts = subsample(points, MAX_SEED_POINTS.max(50 * k), rng);
    let trials = 2 + (k as f64).ln() as usize;
    let mut centres = vec![pts[rng.below(pts.len())]];
    let mut closest = vec![f64::INFINITY; pts.len()];
    while centres.len() < k {
        let newest = *centres.last().expect("one centre at least");
        let totals: Vec<f64> = closest
            .par_chunks_mut(CHUNK)
            .zip(pts.par_chunks(CHUNK))
            .map(|(d, p)| {
                let mut lanes = [0.0; 4];
                for (i, (di, x)) in d.iter_mut().zip(p).enumerate() {
                    *di = di.min(dist2(x, &newest));
                    lanes[i % 4] += *di;
                }
                (lanes[0] + lanes[1]) + (lanes[2] + lanes[3])
            })
            .collect();
        let total: f64 = totals.iter().sum();
        if total <= 0.0 {
            break; // every point coincides with a centre
        }
        let candidates: Vec<[f64; 3]> = (0..trials)
            .map(|_| pts[draw(&closest, &totals, rng.uniform() * total)])
            .collect();
        let scores: Vec<Vec<f64>> = closest
            .par_chunks(CHUNK)
            .zip(pts.par_chunks(CHUNK))
            .map(|(d, p)| candidates.iter().map(|c| potential(d, p, c)).collect())
            .collect();
        let score = |t: usize| scores.iter().map(|s| s[t]).sum::<f64>();
        let best = (0..trials)
            .map(|t| (score(t), t))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, t)| candidates[t])
            .expect("at least two trials");
        if !best_is_new(&centres, &best) {
            break;
        }
        centres.push(best);
    }
    centres
}

/// The index where the running sum of `weights` passes `target`, found chunk by chunk.
fn draw(weights: &[f64], chunk_totals: &[f64], mut target: f64) -> usize {
    for (c, &t) in chunk_totals.iter().enumerate() {
        if target < t {
            for (i, &w) in weights[c * CHUNK..].iter().enumerate() {
                target -= w;
                if target < 0.0 {
                    return c * CHUNK + i;
                }
            }
        }
        target -= t;
    }
    // Rounding left the target past the end: take the last point with weight.
    weights.iter().rposition(|&w| w > 0.0).unwrap_or(0)
}

/// Σᵢ min(dᵢ, |xᵢ − c|²): the k-means potential of a chunk if `c` became a centre.
fn potential(d: &[f64], p: &[[f64; 3]], c: &[f64; 3]) -> f64 {
    let mut lanes = [0.0; 4];
    for (i, (&di, x)) in d.iter().zip(p).enumerate() {
        lanes[i % 4] += di.min(dist2(x, c));
    }
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3])
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
