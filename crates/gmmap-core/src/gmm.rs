//! Exact evaluation of a Gaussian mixture: log-density and the gradient of the density.

use crate::{fastmath::exp_nonpos, linalg::Sym3, CoreError};
use rayon::prelude::*;

/// A 3-D Gaussian mixture with full covariances.
#[derive(Debug, Clone, PartialEq)]
pub struct Gmm {
    pub weights: Vec<f64>,
    pub means: Vec<[f64; 3]>,
    pub covariances: Vec<Sym3>,
}

/// What evaluating one component needs: mean, precision and log(weight * normaliser).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Prepared {
    pub mean: [f64; 3],
    pub precision: Sym3,
    pub log_coef: f64,
}

pub(crate) const LOG_2PI_3: f64 = 3.0 * 1.837_877_066_409_345_5; // 3 ln(2π)

impl Prepared {
    pub fn new(weight: f64, mean: [f64; 3], cov: &Sym3) -> Option<Self> {
        let (precision, logdet) = cov.inverse_logdet()?;
        Some(Prepared {
            mean,
            precision,
            log_coef: weight.ln() - 0.5 * (LOG_2PI_3 + logdet),
        })
    }

    /// log(weight * N(x; mean, cov)).
    #[inline(always)]
    pub fn log_term(&self, x: &[f64; 3]) -> f64 {
        let d = sub(x, &self.mean);
        self.log_coef - 0.5 * self.precision.quad(d)
    }
}

#[inline(always)]
pub(crate) fn sub(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Points per parallel task: large enough to amortise scheduling, small enough to balance.
const CHUNK: usize = 2048;

impl Gmm {
    pub fn len(&self) -> usize {
        self.weights.len()
    }

    pub fn is_empty(&self) -> bool {
        self.weights.is_empty()
    }

    pub(crate) fn prepare(&self) -> Result<Vec<Prepared>, CoreError> {
        if self.is_empty() {
            return Err(CoreError::InvalidArgument(
                "the mixture has no components".into(),
            ));
        }
        (0..self.len())
            .map(|k| {
                Prepared::new(self.weights[k], self.means[k], &self.covariances[k])
                    .ok_or(CoreError::NotPositiveDefinite { component: k })
            })
            .collect()
    }

    /// log p(x) for every point, using all components (no truncation).
    pub fn log_pdf(&self, points: &[[f64; 3]]) -> Result<Vec<f64>, CoreError> {
        let comps = self.prepare()?;
        let mut out = vec![0.0; points.len()];
        out.par_chunks_mut(CHUNK)
            .zip(points.par_chunks(CHUNK))
            .for_each(|(out, pts)| {
                let mut terms = vec![0.0; comps.len()];
                for (o, x) in out.iter_mut().zip(pts) {
                    *o = log_sum_exp(&comps, x, &mut terms);
                }
            });
        Ok(out)
    }

    /// ∇p(x) = Σₖ πₖ N(x; μₖ, Σₖ) · (−Σₖ⁻¹ (x − μₖ)) for every point.
    pub fn gradient(&self, points: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, CoreError> {
        let comps = self.prepare()?;
        let mut out = vec![[0.0; 3]; points.len()];
        out.par_chunks_mut(CHUNK)
            .zip(points.par_chunks(CHUNK))
            .for_each(|(out, pts)| {
                for (o, x) in out.iter_mut().zip(pts) {
                    *o = comps.iter().fold([0.0; 3], |acc, c| {
                        let d = sub(x, &c.mean);
                        let density = (c.log_coef - 0.5 * c.precision.quad(d)).exp();
                        let g = c.precision.mul_vec(d);
                        [
                            acc[0] - density * g[0],
                            acc[1] - density * g[1],
                            acc[2] - density * g[2],
                        ]
                    });
                }
            });
        Ok(out)
    }
}

impl Gmm {
    /// ∫ f(x) g(x) dx in closed form: Σᵢⱼ πᵢ ρⱼ N(μᵢ; νⱼ, Σᵢ + Λⱼ).
    pub fn l2_inner(&self, other: &Gmm) -> Result<f64, CoreError> {
        if self.is_empty() || other.is_empty() {
            return Err(CoreError::InvalidArgument(
                "the mixture has no components".into(),
            ));
        }
        let rows: Vec<f64> = (0..self.len())
            .into_par_iter()
            .map(|i| {
                (0..other.len())
                    .map(|j| {
                        let cov = self.covariances[i].add(&other.covariances[j]);
                        let e = sub(&self.means[i], &other.means[j]);
                        let e2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
                        // eᵀS⁻¹e ≥ (eᵀe)²/eᵀSe: beyond 8σ the term is below e⁻³² of its peak.
                        if e2 * e2 > 64.0 * cov.quad(e) {
                            return 0.0;
                        }
                        let w = self.weights[i] * other.weights[j];
                        Prepared::new(w, other.means[j], &cov)
                            .map_or(0.0, |p| p.log_term(&self.means[i]).exp())
                    })
                    .sum()
            })
            .collect();
        Ok(rows.iter().sum())
    }

    /// The normalised L2 correlation ∫fg / sqrt(∫f² ∫g²), in [0, 1]; 1 only for f = g.
    pub fn l2_correlation(&self, other: &Gmm) -> Result<f64, CoreError> {
        let fg = self.l2_inner(other)?;
        Ok(fg / (self.l2_inner(self)? * other.l2_inner(other)?).sqrt())
    }
}

impl Gmm {
    /// Components whose means share a `cell`-sized voxel merged into one with the same
    /// weight, mean and covariance (moment matching): the mixture as seen at that scale.
    /// Cells come out in lexicographic order of their indices.
    pub fn coarsened(&self, cell: f64) -> Result<Gmm, CoreError> {
        if !(cell > 0.0 && cell.is_finite()) {
            return Err(CoreError::InvalidArgument(format!(
                "cell must be finite and > 0, got {cell}"
            )));
        }
        let key = |m: &[f64; 3]| m.map(|v| (v / cell).floor() as i64);
        // Cells numbered in key order, so that the result does not depend on the input order.
        let mut cells: std::collections::BTreeMap<[i64; 3], usize> =
            self.means.iter().map(|m| (key(m), 0)).collect();
        for (k, index) in cells.values_mut().enumerate() {
            *index = k;
        }
        let group: Vec<usize> = self.means.iter().map(|m| cells[&key(m)]).collect();
        let n = cells.len();
        let (mut w, mut wm) = (vec![0.0; n], vec![[0.0; 3]; n]);
        for ((&g, &wi), m) in group.iter().zip(&self.weights).zip(&self.means) {
            w[g] += wi;
            for a in 0..3 {
                wm[g][a] += wi * m[a];
            }
        }
        let means: Vec<[f64; 3]> = wm
            .iter()
            .zip(&w)
            .map(|(s, &wg)| s.map(|v| v / wg))
            .collect();
        let mut spread = vec![Sym3::default(); n];
        for (i, &g) in group.iter().enumerate() {
            let d = sub(&self.means[i], &means[g]);
            let term = self.covariances[i]
                .add(&Sym3::outer(d))
                .scale(self.weights[i]);
            spread[g] = spread[g].add(&term);
        }
        let covariances = spread
            .iter()
            .zip(&w)
            .map(|(c, &wg)| c.scale(1.0 / wg))
            .collect();
        Ok(Gmm {
            weights: w,
            means,
            covariances,
        })
    }
}

/// log Σₖ exp(log_termₖ(x)), stable for any spread of terms.
pub(crate) fn log_sum_exp(comps: &[Prepared], x: &[f64; 3], terms: &mut [f64]) -> f64 {
    let mut max = f64::NEG_INFINITY;
    for (t, c) in terms.iter_mut().zip(comps) {
        *t = c.log_term(x);
        max = max.max(*t);
    }
    if max == f64::NEG_INFINITY {
        return max;
    }
    let sum: f64 = terms.iter().map(|t| exp_nonpos(t - max)).sum();
    max + sum.ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn log_normaliser(cov: &Sym3) -> f64 {
        -0.5 * (3.0 * (2.0 * PI).ln() + cov.det().ln())
    }

    fn two_component() -> Gmm {
        Gmm {
            weights: vec![0.3, 0.7],
            means: vec![[0.0, 0.0, 0.0], [1.0, 2.0, -1.0]],
            covariances: vec![
                Sym3::diag(0.5, 1.0, 2.0),
                Sym3 {
                    xx: 1.0,
                    yy: 2.0,
                    zz: 1.5,
                    xy: 0.3,
                    xz: -0.2,
                    yz: 0.4,
                },
            ],
        }
    }

    #[test]
    fn single_gaussian_log_pdf_at_mean_is_normaliser() {
        let cov = Sym3::diag(0.5, 1.0, 2.0);
        let g = Gmm {
            weights: vec![1.0],
            means: vec![[1.0, 2.0, 3.0]],
            covariances: vec![cov],
        };
        let lp = g.log_pdf(&[[1.0, 2.0, 3.0]]).unwrap()[0];
        assert!((lp - log_normaliser(&cov)).abs() < 1e-12);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let g = two_component();
        let x = [0.4, 0.9, -0.3];
        let grad = g.gradient(&[x]).unwrap()[0];
        let h = 1e-6;
        for axis in 0..3 {
            let (mut a, mut b) = (x, x);
            a[axis] += h;
            b[axis] -= h;
            let p = g.log_pdf(&[a, b]).unwrap();
            let fd = (p[0].exp() - p[1].exp()) / (2.0 * h);
            assert!(
                (fd - grad[axis]).abs() < 1e-8,
                "axis {axis}: {fd} vs {}",
                grad[axis]
            );
        }
    }

    #[test]
    fn l2_inner_matches_numeric_integral_and_correlation_is_one_for_itself() {
        let g = two_component();
        // ∫ g² by summing p(x)² over a fine grid.
        let h = 0.1;
        let mut grid = Vec::new();
        for i in -60..80 {
            for j in -60..90 {
                for k in -70..60 {
                    grid.push([i as f64 * h, j as f64 * h, k as f64 * h]);
                }
            }
        }
        let numeric: f64 = g
            .log_pdf(&grid)
            .unwrap()
            .iter()
            .map(|l| (2.0 * l).exp())
            .sum::<f64>()
            * h
            * h
            * h;
        let closed = g.l2_inner(&g).unwrap();
        assert!(
            (numeric - closed).abs() < 1e-4 * closed,
            "{numeric} vs {closed}"
        );
        assert!((g.l2_correlation(&g).unwrap() - 1.0).abs() < 1e-12);
        let mut moved = g.clone();
        moved.means[0][0] += 0.5;
        let c = g.l2_correlation(&moved).unwrap();
        assert!(c < 1.0 && c > 0.5);
    }

    #[test]
    fn rejects_indefinite_covariance() {
        let mut g = two_component();
        g.covariances[1] = Sym3::diag(1.0, 0.0, 1.0);
        assert_eq!(
            g.log_pdf(&[[0.0; 3]]),
            Err(CoreError::NotPositiveDefinite { component: 1 })
        );
    }
}
