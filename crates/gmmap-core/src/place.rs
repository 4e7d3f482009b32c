//! The heavy part of place recognition's shape descriptor: a joint histogram of (horizontal
//! distance, |height difference|) over point pairs drawn independently at random. Independent
//! pairs make its noise fall as 1/sqrt(pairs), unlike all pairs of a small subsample, whose
//! noise is that of the subsample however many pairs it has.

use crate::rng::Rng;
use crate::{check_finite, CoreError};
use rayon::prelude::*;

#[derive(Debug, Clone)]
pub struct PairHistogram {
    pub pairs: usize,
    pub distance_bins: usize,
    pub max_distance: f64,
    pub height_bins: usize,
    pub max_height: f64,
    pub seed: u64,
}

/// Pairs per parallel task; each task has its own generator, seeded from one drawn from `seed`,
/// so the result does not depend on the thread count.
const CHUNK: usize = 1 << 16;

/// Counts (distance-major: bin = d · height_bins + h) of the pairs that fall inside the grid.
pub fn pair_histogram(points: &[[f64; 3]], o: &PairHistogram) -> Result<Vec<f64>, CoreError> {
    if points.len() < 2 {
        return Err(CoreError::InvalidArgument(format!(
            "a pair histogram needs at least 2 points, got {}",
            points.len()
        )));
    }
    let ok = |v: f64| v.is_finite() && v > 0.0;
    if o.distance_bins == 0 || o.height_bins == 0 || !ok(o.max_distance) || !ok(o.max_height) {
        return Err(CoreError::InvalidArgument(
            "bins must be >= 1 and the ranges positive".into(),
        ));
    }
    check_finite(points)?;
    let n = points.len();
    let (db, hb) = (o.distance_bins, o.height_bins);
    let (sd, sh) = (db as f64 / o.max_distance, hb as f64 / o.max_height);
    let mut master = Rng::new(o.seed);
    let seeds: Vec<u64> = (0..o.pairs.div_ceil(CHUNK))
        .map(|_| master.next_u64())
        .collect();
    let counts = seeds
        .par_iter()
        .enumerate()
        .map(|(c, &seed)| {
            let mut rng = Rng::new(seed);
            let mut h = vec![0u64; db * hb];
            for _ in 0..CHUNK.min(o.pairs - c * CHUNK) {
                let i = rng.below(n);
                let j = rng.below(n - 1);
                let j = if j >= i { j + 1 } else { j }; // uniform over the other points
                let (a, b) = (points[i], points[j]);
                let (dx, dy) = (a[0] - b[0], a[1] - b[1]);
                let d = (dx * dx + dy * dy).sqrt() * sd;
                let v = (a[2] - b[2]).abs() * sh;
                if d < db as f64 && v < hb as f64 {
                    h[d as usize * hb + v as usize] += 1;
                }
            }
            h
        })
        .reduce(
            || vec![0u64; db * hb],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    Ok(counts.into_iter().map(|c| c as f64).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(pairs: usize) -> PairHistogram {
        PairHistogram {
            pairs,
            distance_bins: 4,
            max_distance: 4.0,
            height_bins: 2,
            max_height: 2.0,
            seed: 1,
        }
    }

    #[test]
    fn counts_pairs_by_distance_and_height() {
        // Two points 1.5 m apart horizontally and 0.5 m in height: every pair lands in (1, 0).
        let h = pair_histogram(&[[0.0, 0.0, 0.0], [1.5, 0.0, 0.5]], &options(1000)).unwrap();
        assert_eq!(h[2], 1000.0);
        assert_eq!(h.iter().sum::<f64>(), 1000.0);
        // Out of range pairs are not counted.
        let far = pair_histogram(&[[0.0, 0.0, 0.0], [9.0, 0.0, 0.0]], &options(10)).unwrap();
        assert_eq!(far.iter().sum::<f64>(), 0.0);
    }

    #[test]
    fn seeded_and_proportional_to_the_pair_distances() {
        // Three collinear points 1 m apart: pair distances 1, 1, 2 (bins 1, 1, 2) in 2:1.
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        let h = pair_histogram(&pts, &options(300_000)).unwrap();
        assert_eq!(h, pair_histogram(&pts, &options(300_000)).unwrap());
        let (near, far) = (h[2], h[4]);
        assert!((near / far - 2.0).abs() < 0.05, "{near} {far}");
    }

    #[test]
    fn rejects_bad_input() {
        assert!(pair_histogram(&[[0.0; 3]], &options(10)).is_err());
        assert!(pair_histogram(&[[0.0; 3], [f64::NAN, 0.0, 0.0]], &options(10)).is_err());
        let mut o = options(10);
        o.height_bins = 0;
        assert!(pair_histogram(&[[0.0; 3], [1.0; 3]], &o).is_err());
    }
}
