//! GMM-to-GMM registration (paper V-B, after DESIGN.md): find the rigid T maximising the
//! normalised L2 correlation C(T) = ∫ T(f) g / sqrt(∫f² ∫g²) of a source mixture f and a target
//! mixture g.
//!
//! ∫ T(f) g = Σᵢⱼ πᵢ ρⱼ N(Rμᵢ + t; νⱼ, RΣᵢRᵀ + Λⱼ) in closed form, and the norms do not depend
//! on T, so the optimiser maximises log F(T), F = ∫ T(f) g. The gradient with respect to a left
//! perturbation T ← exp(ξ)·T, ξ = (ω, v), is analytic, including the rotation of the source
//! covariances; the step is Levenberg-Marquardt on a Newton metric, the Gauss-Newton part
//! H = Σ wᵢⱼ Jᵢⱼᵀ Sᵢⱼ⁻¹ Jᵢⱼ / F (Jᵢⱼ = ∂e/∂ξ = [−[p]ₓ, I]) less the covariance of the pairs'
//! gradients (H alone where that is not positive), accepted only when F grows.
//! Coarse to fine: an isotropic variance s² is added to every covariance of both mixtures, for
//! each s of `scales` in turn, which widens the basin of convergence. Without an initial guess,
//! the `search_starts` best maxima of the translation votes over `yaw_starts` rotations about +z
//! (gravity; `crate::search`) are optimised at the coarsest scale; the best `refine_starts`
//! distinct ones are refined and every distinct basin is returned, the highest C first (the
//! next one's C is the `alternative`). C at the end (measured with `confidence_scale` added to all
//! covariances) is the geometric confidence; H (scaled) is the information matrix.

use crate::fastmath::exp_nonpos;
use crate::gmm::Gmm;
use crate::linalg::Sym3;
use crate::search::hypotheses;
use crate::CoreError;
use rayon::prelude::*;

/// (2π)^(-3/2), the normaliser of a 3-D Gaussian without its determinant.
const INV_2PI_15: f64 = 0.063_493_635_934_240_97;

/// Every field is given by the caller: the defaults live in the Python configuration
/// (`gmmap.options.RegisterOptions`), which passes each one.
#[derive(Debug, Clone)]
pub struct RegisterOptions {
    /// Standard deviations (same unit as the means) added to all covariances, coarse to fine.
    pub scales: Vec<f64>,
    /// LM iterations per scale at most.
    pub max_iter: usize,
    /// Stop a scale when the step is smaller than this (radians + units).
    pub tol: f64,
    /// Estimate only x, y, z and yaw (ground robots: roll and pitch come from gravity).
    pub four_dof: bool,
    /// Yaw starts tried when there is no initial guess.
    pub yaw_starts: usize,
    /// Without a guess or a yaw hint: the spacing (units of the means) of the translation votes
    /// the starts come from (`crate::search`), also their blur; 0: each yaw starts with the
    /// centroids aligned.
    pub search_cell: f64,
    /// Without a guess: the votes' best maxima optimised at the coarsest scale.
    pub search_starts: usize,
    /// Without a guess, the distinct coarse solutions refined (the best is returned, the
    /// next best's confidence is the `alternative`).
    pub refine_starts: usize,
    /// Pairs farther apart than this many standard deviations are skipped.
    pub cutoff: f64,
    /// Multiplies the Gauss-Newton metric to give the information matrix.
    pub information_scale: f64,
    /// Standard deviation added to every covariance when the confidence is measured, so that
    /// C reflects the shared geometry rather than how sharply each side was fitted.
    pub confidence_scale: f64,
    /// From a guess, scales of at least `coarse_scale` (but the last) register the mixtures
    /// coarsened in cells of `coarse_cell` times the scale; 0: never.
    pub coarse_cell: f64,
    pub coarse_scale: f64,
}

#[cfg(test)]
impl Default for RegisterOptions {
    fn default() -> Self {
        RegisterOptions {
            scales: vec![0.3, 0.1, 0.03, 0.0],
            max_iter: 10,
            tol: 1e-5,
            four_dof: false,
            yaw_starts: 12,
            search_cell: 0.5,
            search_starts: 24,
            refine_starts: 2,
            cutoff: 4.0,
            information_scale: 1.0,
            confidence_scale: 0.05,
            coarse_cell: 0.0,
            coarse_scale: 0.15,
        }
    }
}

/// A rigid transform: x ↦ R x + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub r: [[f64; 3]; 3],
    pub t: [f64; 3],
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        r: [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        t: [0.; 3],
    };

    /// From a row-major 4x4 matrix.
    pub fn from_matrix(m: &[f64; 16]) -> Pose {
        Pose {
            r: [[m[0], m[1], m[2]], [m[4], m[5], m[6]], [m[8], m[9], m[10]]],
            t: [m[3], m[7], m[11]],
        }
    }

    pub fn to_matrix(&self) -> [f64; 16] {
        let (r, t) = (&self.r, &self.t);
        [
            r[0][0], r[0][1], r[0][2], t[0], r[1][0], r[1][1], r[1][2], t[1], r[2][0], r[2][1],
            r[2][2], t[2], 0., 0., 0., 1.,
        ]
    }

    pub fn apply(&self, x: &[f64; 3]) -> [f64; 3] {
        let m = mat_vec(&self.r, x);
        [m[0] + self.t[0], m[1] + self.t[1], m[2] + self.t[2]]
    }

    /// exp(ξ)·self for ξ = (ω, v): R ← Exp(ω) R, t ← Exp(ω) t + v.
    pub fn perturbed(&self, xi: &[f64; 6]) -> Pose {
        let q = so3_exp([xi[0], xi[1], xi[2]]);
        let t = mat_vec(&q, &self.t);
        Pose {
            r: mat_mul(&q, &self.r),
            t: [t[0] + xi[3], t[1] + xi[4], t[2] + xi[5]],
        }
    }

    pub(crate) fn yaw(angle: f64) -> Pose {
        let (s, c) = angle.sin_cos();
        Pose {
            r: [[c, -s, 0.], [s, c, 0.], [0., 0., 1.]],
            t: [0.; 3],
        }
    }
}

/// The result of a registration.
#[derive(Debug, Clone)]
pub struct Registration {
    /// Maps source coordinates into the target frame.
    pub transform: Pose,
    /// Normalised L2 correlation at the solution, in [0, 1].
    pub confidence: f64,
    /// 6x6 information of ξ = (ω, v) (left perturbation, rotation first).
    pub information: [[f64; 6]; 6],
    pub iterations: usize,
    /// Without an initial guess: the confidence of the best solution distinct from this one
    /// (another basin, 30° or 0.5 m away), 0 when every start ends here. Near `confidence`, the
    /// geometry is ambiguous (a corridor seen end for end, a room one over).
    pub alternative: f64,
    /// Without an initial guess: every distinct refined solution (pose, confidence), best
    /// first (`transform` leads); with a guess just the solution. A caller holding evidence
    /// the correlation lacks (free space seen) may prefer a later one.
    pub basins: Vec<(Pose, f64)>,
}

fn mat_vec(m: &[[f64; 3]; 3], v: &[f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c]))
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Rodrigues' formula.
pub fn so3_exp(w: [f64; 3]) -> [[f64; 3]; 3] {
    let theta2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    let theta = theta2.sqrt();
    let (a, b) = if theta < 1e-8 {
        (1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0)
    } else {
        (theta.sin() / theta, (1.0 - theta.cos()) / theta2)
    };
    let k = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]];
    let k2 = mat_mul(&k, &k);
    [0, 1, 2]
        .map(|r| [0, 1, 2].map(|c| if r == c { 1.0 } else { 0.0 } + a * k[r][c] + b * k2[r][c]))
}

/// R Σ Rᵀ.
pub(crate) fn rotate_cov(r: &[[f64; 3]; 3], s: &Sym3) -> Sym3 {
    let m = s.to_rows();
    let rm =
        [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| r[i][k] * m[3 * k + j]).sum::<f64>()));
    let out = [0, 1, 2].map(|i| [0, 1, 2].map(|j| (0..3).map(|k| rm[i][k] * r[j][k]).sum::<f64>()));
    Sym3 {
        xx: out[0][0],
        yy: out[1][1],
        zz: out[2][2],
        xy: out[0][1],
        xz: out[0][2],
        yz: out[1][2],
    }
}

/// Value of F with, optionally, its gradient (of F) and the weighted Gauss-Newton sum.
#[derive(Clone, Copy)]
struct Eval {
    f: f64,
    grad: [f64; 6],
    /// Σ w Jᵀ P J (upper triangle): the Gauss-Newton part of the curvature.
    h: [[f64; 6]; 6],
    /// Σ w g gᵀ of the pairs' log-gradients (upper triangle): with it the Newton curvature of
    /// log F is h − ggᵀ-terms, whose steps converge in a few iterations where Gauss-Newton alone
    /// (an EM-like fixed point) creeps linearly.
    gg: [[f64; 6]; 6],
}

impl Eval {
    const ZERO: Eval = Eval {
        f: 0.0,
        grad: [0.0; 6],
        h: [[0.0; 6]; 6],
        gg: [[0.0; 6]; 6],
    };

    fn add(mut self, o: &Eval) -> Eval {
        self.f += o.f;
        for a in 0..6 {
            self.grad[a] += o.grad[a];
            for b in 0..6 {
                self.h[a][b] += o.h[a][b];
                self.gg[a][b] += o.gg[a][b];
            }
        }
        self
    }
}

/// Rows of the source processed per parallel task (a fixed split: deterministic sums).
const ROWS: usize = 8;

struct Problem<'a> {
    source: &'a Gmm,
    target: &'a Gmm,
    cutoff2: f64,
    /// Bounds of each covariance's largest eigenvalue (rotation-invariant): with them, |e|² beyond
    /// cutoff² · (λᵢ + λⱼ + 2s²) proves a pair negligible without inverting anything.
    source_reach: Vec<f64>,
    target_reach: Vec<f64>,
}

/// Upper bounds of each covariance's largest eigenvalue (Gershgorin: no decomposition).
fn largest_eigenvalues(g: &Gmm) -> Vec<f64> {
    let bound = |c: &Sym3| {
        let rows = [
            c.xx + c.xy.abs() + c.xz.abs(),
            c.yy + c.xy.abs() + c.yz.abs(),
            c.zz + c.xz.abs() + c.yz.abs(),
        ];
        rows[0].max(rows[1]).max(rows[2])
    };
    g.covariances.iter().map(bound).collect()
}

impl<'a> Problem<'a> {
    fn new(source: &'a Gmm, target: &'a Gmm, cutoff: f64) -> Problem<'a> {
        Problem {
            source,
            target,
            cutoff2: cutoff * cutoff,
            source_reach: largest_eigenvalues(source),
            target_reach: largest_eigenvalues(target),
        }
    }
}

impl Problem<'_> {
    /// F(T) = Σᵢⱼ πᵢ ρⱼ N(Rμᵢ + t − νⱼ; 0, RΣᵢRᵀ + Λⱼ + 2s²I), and derivatives if asked.
    fn evaluate(&self, pose: &Pose, s2: f64, derivs: bool) -> Eval {
        let (src, tgt) = (self.source, self.target);
        let parts: Vec<Eval> = (0..src.len())
            .collect::<Vec<_>>()
            .par_chunks(ROWS)
            .map(|rows| {
                let mut acc = Eval::ZERO;
                for &i in rows {
                    let p = pose.apply(&src.means[i]);
                    let mut rotated = None;
                    let mut row = Row::default();
                    for j in 0..tgt.len() {
                        let nu = &tgt.means[j];
                        let e = [p[0] - nu[0], p[1] - nu[1], p[2] - nu[2]];
                        let e2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
                        if e2
                            > self.cutoff2
                                * (self.source_reach[i] + self.target_reach[j] + 2.0 * s2)
                        {
                            continue;
                        }
                        let sr = *rotated
                            .get_or_insert_with(|| rotate_cov(&pose.r, &src.covariances[i]));
                        let s = sr.add(&tgt.covariances[j]).add_diag(2.0 * s2);
                        // Tighter, still without an inverse: eᵀS⁻¹e ≥ (eᵀe)² / eᵀSe
                        // (Cauchy-Schwarz), sharp along e: it drops the many pairs lying
                        // beside each other's thin axis.
                        if e2 * e2 > self.cutoff2 * s.quad(e) {
                            continue;
                        }
                        let w0 = src.weights[i] * tgt.weights[j];
                        row.pair(w0, e, &sr, &s, self.cutoff2, derivs);
                    }
                    row.add_to(&mut acc, &p);
                }
                acc
            })
            .collect();
        parts.iter().fold(Eval::ZERO, |a, b| a.add(b))
    }
}

/// One source component's pairs, summed before the Jacobian J = [−[p]ₓ, I] (the same for all
/// of them) is applied: each pair's gradient is g = Jᵀu + (c, 0) with u = −S⁻¹e and c the
/// covariance-rotation term, so Σ w JᵀPJ, Σ w g and Σ w g gᵀ need only 3-vectors and 3x3 sums
/// per pair instead of 6x6 products.
#[derive(Default)]
struct Row {
    f: f64,
    u: [f64; 3],
    c: [f64; 3],
    /// Σ w P, Σ w u uᵀ, Σ w c uᵀ and Σ w c cᵀ.
    p: [[f64; 3]; 3],
    uu: [[f64; 3]; 3],
    cu: [[f64; 3]; 3],
    cc: [[f64; 3]; 3],
}

impl Row {
    /// Adds one pair's term (residual `e`, rotated source covariance `sr`, total covariance
    /// `s`) and, if asked, its derivative sums.
    #[inline(always)]
    fn pair(&mut self, w0: f64, e: [f64; 3], sr: &Sym3, s: &Sym3, cutoff2: f64, derivs: bool) {
        let Some((prec, root_det)) = s.inverse_sqrt_det() else {
            return;
        };
        let q = prec.mul_vec(e);
        let m = e[0] * q[0] + e[1] * q[1] + e[2] * q[2];
        if m > cutoff2 {
            return; // exp(-m/2) is negligible: skip the derivative work too
        }
        let w = w0 * INV_2PI_15 / root_det * exp_nonpos(-0.5 * m);
        self.f += w;
        if !derivs {
            return;
        }
        // d log w / dω = q × p + (Σ'q) × q − vee(Σ'P − PΣ')/2 ; d log w / dv = −q.
        let b = cross(&sr.mul_vec(q), &q);
        let sp = sym_mul(sr, &prec);
        let c = [
            b[0] - (sp[1][2] - sp[2][1]),
            b[1] - (sp[2][0] - sp[0][2]),
            b[2] - (sp[0][1] - sp[1][0]),
        ];
        let u = q.map(|v| -v);
        let pm = prec.to_rows();
        for x in 0..3 {
            self.u[x] += w * u[x];
            self.c[x] += w * c[x];
            for y in 0..3 {
                self.p[x][y] += w * pm[3 * x + y];
                self.uu[x][y] += w * u[x] * u[y];
                self.cu[x][y] += w * c[x] * u[y];
                self.cc[x][y] += w * c[x] * c[y];
            }
        }
    }

    /// Adds the row's sums to `acc` with the Jacobian at the moved source mean `p`.
    // x and y address five matrices at once: plain index loops read best.
    #[allow(clippy::needless_range_loop)]
    fn add_to(&self, acc: &mut Eval, p: &[f64; 3]) {
        acc.f += self.f;
        if self.f == 0.0 {
            return;
        }
        let jac = jacobian(p);
        // Jᵀ v = (p × v, v).
        let ju = cross(p, &self.u);
        for k in 0..3 {
            acc.grad[k] += ju[k] + self.c[k];
            acc.grad[k + 3] += self.u[k];
        }
        let jt_m_j = |m: &[[f64; 3]; 3]| {
            let mj: [[f64; 6]; 3] = [0, 1, 2]
                .map(|r| [0, 1, 2, 3, 4, 5].map(|c| (0..3).map(|k| m[r][k] * jac[k][c]).sum()));
            [0, 1, 2, 3, 4, 5].map(|x| {
                [0, 1, 2, 3, 4, 5].map(|y| (0..3).map(|k| jac[k][x] * mj[k][y]).sum::<f64>())
            })
        };
        let h = jt_m_j(&self.p);
        // Σ w g gᵀ = Jᵀ UU J + E CU J + (E CU J)ᵀ + E CC Eᵀ, E = [I; 0].
        let mut gg = jt_m_j(&self.uu);
        for x in 0..3 {
            for y in 0..6 {
                let xj = (0..3).map(|k| self.cu[x][k] * jac[k][y]).sum::<f64>();
                gg[x][y] += xj;
                gg[y][x] += xj;
            }
            for y in 0..3 {
                gg[x][y] += self.cc[x][y];
            }
        }
        for x in 0..6 {
            for y in x..6 {
                acc.h[x][y] += h[x][y];
                acc.gg[x][y] += gg[x][y];
            }
        }
    }
}

/// A B for two symmetric matrices (a general 3x3 result).
fn sym_mul(a: &Sym3, b: &Sym3) -> [[f64; 3]; 3] {
    let (x, y) = (a.to_rows(), b.to_rows());
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| (0..3).map(|k| x[3 * r + k] * y[3 * k + c]).sum()))
}

/// ∂e/∂ξ = [−[p]ₓ, I] for the left perturbation.
fn jacobian(p: &[f64; 3]) -> [[f64; 6]; 3] {
    [
        [0.0, p[2], -p[1], 1.0, 0.0, 0.0],
        [-p[2], 0.0, p[0], 0.0, 1.0, 0.0],
        [p[1], -p[0], 0.0, 0.0, 0.0, 1.0],
    ]
}

/// Solves the symmetric system A x = b (n ≤ 6) by Cholesky; None if not positive-definite.
fn solve_spd(a: &[[f64; 6]; 6], b: &[f64; 6], idx: &[usize]) -> Option<[f64; 6]> {
    let n = idx.len();
    let mut l = [[0.0; 6]; 6];
    for i in 0..n {
        for j in 0..=i {
            let s = a[idx[i]][idx[j]] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = [0.0; 6];
    for i in 0..n {
        y[i] = (b[idx[i]] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0; 6];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    let mut out = [0.0; 6];
    for (i, &k) in idx.iter().enumerate() {
        out[k] = x[i];
    }
    Some(out)
}

/// −∇² log F ≈ (Σ w JᵀPJ − Σ w g gᵀ)/F + ḡ ḡᵀ (ḡ = ∇F/F), the second-order terms of the
/// covariance rotation left out; the Gauss-Newton part alone where that is not positive.
fn newton_metric(e: &Eval) -> [[f64; 6]; 6] {
    let mean = e.grad.map(|g| g / e.f);
    let mut gn = e.h.map(|r| r.map(|v| v / e.f));
    symmetrise(&mut gn);
    let mut gg = e.gg;
    symmetrise(&mut gg);
    let mut newton = gn;
    for x in 0..6 {
        for y in 0..6 {
            newton[x][y] += mean[x] * mean[y] - gg[x][y] / e.f;
        }
    }
    let positive = solve_spd(&newton, &[0.0; 6], &[0, 1, 2, 3, 4, 5]).is_some();
    if positive {
        newton
    } else {
        gn
    }
}

/// Copies the upper triangle (the one accumulated) into the lower.
fn symmetrise(h: &mut [[f64; 6]; 6]) {
    let upper = *h;
    for (x, row) in h.iter_mut().enumerate() {
        for (y, v) in row.iter_mut().enumerate().take(x) {
            *v = upper[y][x];
        }
    }
}

impl Problem<'_> {
    /// Each start optimised at the coarse scale `s2`; the best `refine_starts` distinct
    /// solutions, best first.
    fn best_distinct(
        &self,
        starts: &[Pose],
        s2: f64,
        opts: &RegisterOptions,
        iterations: &mut usize,
    ) -> Vec<Pose> {
        let mut found: Vec<(f64, Pose, usize)> = starts
            .par_iter()
            .map(|&start| {
                let (p, e, it) = self.optimise(start, s2, opts);
                (e.f, p, it)
            })
            .collect();
        *iterations += found.iter().map(|x| x.2).sum::<usize>();
        found.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut picked: Vec<Pose> = Vec::new();
        for (_, p, _) in &found {
            if picked.len() == opts.refine_starts.max(1) {
                break;
            }
            if picked.iter().all(|q| distinct(p, q)) {
                picked.push(*p);
            }
        }
        picked
    }

    /// Down the coarse-to-fine ladder from `start`: the pose, the unwidened evaluation with
    /// derivatives (for the information) and the iterations.
    fn refine(&self, start: Pose, scales: &[f64], opts: &RegisterOptions) -> (Pose, Eval, usize) {
        let (mut pose, mut last, mut iterations) = (start, None, 0);
        for s in scales {
            let (p, e, it) = self.optimise(pose, s * s, opts);
            pose = p;
            iterations += it;
            last = (*s == 0.0).then_some(e);
        }
        // Already at hand when the ladder ends at 0.
        let fin = last.unwrap_or_else(|| self.evaluate(&pose, 0.0, true));
        (pose, fin, iterations)
    }

    /// LM ascent on log F at one scale; returns the pose, its evaluation and the iterations.
    fn optimise(&self, mut pose: Pose, s2: f64, opts: &RegisterOptions) -> (Pose, Eval, usize) {
        let dims: &[usize] = if opts.four_dof {
            &[2, 3, 4, 5]
        } else {
            &[0, 1, 2, 3, 4, 5]
        };
        let mut cur = self.evaluate(&pose, s2, true);
        let mut lambda = 1e-3;
        let mut iters = 0;
        while iters < opts.max_iter && cur.f > 0.0 {
            iters += 1;
            let grad = cur.grad.map(|g| g / cur.f);
            let h = newton_metric(&cur);
            let mut accepted = false;
            for _ in 0..12 {
                let mut damped = h;
                for &d in dims {
                    damped[d][d] += lambda * h[d][d].max(1e-12) + 1e-12;
                }
                let Some(step) = solve_spd(&damped, &grad, dims) else {
                    lambda *= 10.0;
                    continue;
                };
                let next = pose.perturbed(&step);
                // Most trials are accepted: evaluate them with derivatives in the same pass.
                let trial = self.evaluate(&next, s2, true);
                let f = trial.f;
                if f > cur.f {
                    let size = step.iter().map(|v| v * v).sum::<f64>().sqrt();
                    // Done once steps or gains become negligible.
                    accepted = size > opts.tol && f - cur.f > 1e-5 * f;
                    pose = next;
                    cur = trial;
                    lambda = (lambda / 3.0).max(1e-9);
                    break;
                }
                lambda *= 4.0;
            }
            if !accepted {
                break;
            }
        }
        (pose, cur, iters)
    }
}

fn weighted_mean(g: &Gmm) -> [f64; 3] {
    let mut m = [0.0; 3];
    for (w, mu) in g.weights.iter().zip(&g.means) {
        for a in 0..3 {
            m[a] += w * mu[a];
        }
    }
    m
}

fn validate(g: &Gmm, which: &str) -> Result<(), CoreError> {
    if g.is_empty() {
        return Err(CoreError::InvalidArgument(format!(
            "the {which} mixture has no components"
        )));
    }
    let finite = g.weights.iter().all(|w| w.is_finite())
        && g.means.iter().flatten().all(|v| v.is_finite())
        && g.covariances
            .iter()
            .all(|c| c.to_rows().iter().all(|v| v.is_finite()));
    if !finite {
        return Err(CoreError::InvalidArgument(format!(
            "the {which} mixture has non-finite values"
        )));
    }
    g.prepare().map(|_| ())
}

/// Registers `source` onto `target`. With `init` = None, searches from the best maxima of the
/// translation votes over `yaw_starts` yaws about +z (`crate::search`), or, with a `yaw_hint`
/// or no `search_cell`, from yaws (near the hint) with the weighted centroids aligned.
pub fn register(
    source: &Gmm,
    target: &Gmm,
    init: Option<Pose>,
    yaw_hint: Option<f64>,
    opts: &RegisterOptions,
) -> Result<Registration, CoreError> {
    validate(source, "source")?;
    validate(target, "target")?;
    if opts.scales.is_empty() || opts.scales.iter().any(|s| !(s.is_finite() && *s >= 0.0)) {
        return Err(CoreError::InvalidArgument(
            "scales must be finite and >= 0".into(),
        ));
    }
    let problem = Problem::new(source, target, opts.cutoff);
    let coarse = opts.scales[0] * opts.scales[0];
    let mut iterations = 0;
    let mut scales = &opts.scales[..];
    // Coarse solutions, best first: with a guess just the guess.
    let solutions: Vec<Pose> = match init {
        Some(mut pose) => {
            // A wide blur sees merged components as it sees their parts, at a fraction of
            // the pairs, and leads to the same basin.
            while opts.coarse_cell > 0.0 && scales.len() > 1 && scales[0] >= opts.coarse_scale {
                let cell = opts.coarse_cell * scales[0];
                let (f, g) = (source.coarsened(cell)?, target.coarsened(cell)?);
                let (p, _, it) =
                    Problem::new(&f, &g, opts.cutoff).optimise(pose, scales[0] * scales[0], opts);
                (pose, scales) = (p, &scales[1..]);
                iterations += it;
            }
            vec![pose]
        }
        None if yaw_hint.is_none() && opts.search_cell > 0.0 => {
            let cell = opts.search_cell;
            let found = hypotheses(
                source,
                target,
                opts.yaw_starts,
                cell,
                cell,
                opts.search_starts,
            )?;
            let poses: Vec<Pose> = found
                .iter()
                .take(opts.search_starts)
                .map(|h| h.pose)
                .collect();
            problem.best_distinct(&poses, coarse, opts, &mut iterations)
        }
        None => {
            let yaws: Vec<f64> = match yaw_hint {
                Some(y) => vec![y, y - 0.5, y + 0.5],
                None => (0..opts.yaw_starts.max(1))
                    .map(|k| 2.0 * std::f64::consts::PI * k as f64 / opts.yaw_starts.max(1) as f64)
                    .collect(),
            };
            let (ms, mt) = (weighted_mean(source), weighted_mean(target));
            let poses: Vec<Pose> = yaws
                .iter()
                .map(|&yaw| {
                    let mut pose = Pose::yaw(yaw);
                    let rm = mat_vec(&pose.r, &ms);
                    pose.t = [mt[0] - rm[0], mt[1] - rm[1], mt[2] - rm[2]];
                    pose
                })
                .collect();
            problem.best_distinct(&poses, coarse, opts, &mut iterations)
        }
    };
    let c2 = opts.confidence_scale * opts.confidence_scale;
    // ∫f², ∫g² and ∫T(f)g, all widened by c2 and pruned alike (evaluate adds c2 to each side).
    let self_overlap = |g: &Gmm| {
        Problem::new(g, g, opts.cutoff)
            .evaluate(&Pose::IDENTITY, c2, false)
            .f
    };
    let norm = (self_overlap(source) * self_overlap(target)).sqrt();
    let confidence_at = |p: &Pose| (problem.evaluate(p, c2, false).f / norm).clamp(0.0, 1.0);
    // The coarse scale only ranks the starts; the finer scales can reverse the order.
    let mut refined: Vec<(f64, Pose, Eval)> = Vec::with_capacity(solutions.len());
    for start in &solutions {
        let (p, fin, it) = problem.refine(*start, scales, opts);
        iterations += it;
        refined.push((confidence_at(&p), p, fin));
    }
    // Distinct basins, best first: of two starts that refine into one basin the better one's
    // pose stands for it.
    refined.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut basins: Vec<(f64, Pose, Eval)> = Vec::with_capacity(refined.len());
    for r in refined {
        if basins.iter().all(|b| distinct(&r.1, &b.1)) {
            basins.push(r);
        }
    }
    let (confidence, pose, fin) = basins[0];
    let alternative = basins.get(1).map_or(0.0, |b| b.0);
    let mut h = fin.h;
    symmetrise(&mut h);
    let scale = if fin.f > 0.0 {
        opts.information_scale / fin.f
    } else {
        0.0
    };
    Ok(Registration {
        transform: pose,
        confidence,
        information: h.map(|r| r.map(|v| v * scale)),
        iterations,
        alternative,
        basins: basins.iter().map(|b| (b.1, b.0)).collect(),
    })
}

/// Whether two poses lie in different basins: 30° or 0.5 units apart.
fn distinct(a: &Pose, b: &Pose) -> bool {
    let dt = (0..3)
        .map(|k| (a.t[k] - b.t[k]).powi(2))
        .sum::<f64>()
        .sqrt();
    // trace(Raᵀ Rb) = 1 + 2 cos θ
    let trace: f64 = (0..3)
        .map(|k| (0..3).map(|r| a.r[r][k] * b.r[r][k]).sum::<f64>())
        .sum();
    let cos = ((trace - 1.0) / 2.0).clamp(-1.0, 1.0);
    dt > 0.5 || cos < 30f64.to_radians().cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small scene: floor, two walls and a box, as flat Gaussians.
    fn scene() -> Gmm {
        let mut g = Gmm {
            weights: vec![],
            means: vec![],
            covariances: vec![],
        };
        let mut add = |m: [f64; 3], c: Sym3| {
            g.weights.push(1.0);
            g.means.push(m);
            g.covariances.push(c);
        };
        for x in 0..4 {
            for y in 0..3 {
                add(
                    [x as f64 * 0.8, y as f64 * 0.8, 0.0],
                    Sym3::diag(0.06, 0.06, 1e-4),
                );
            }
            add([x as f64 * 0.8, 2.4, 1.0], Sym3::diag(0.06, 1e-4, 0.1));
        }
        for y in 0..3 {
            add([3.0, y as f64 * 0.8, 1.0], Sym3::diag(1e-4, 0.06, 0.1));
        }
        add(
            [1.2, 1.0, 0.4],
            Sym3 {
                xx: 0.02,
                yy: 0.03,
                zz: 0.04,
                xy: 0.01,
                xz: 0.0,
                yz: 0.005,
            },
        );
        let n = g.weights.len() as f64;
        g.weights.iter_mut().for_each(|w| *w /= n);
        g
    }

    fn moved(g: &Gmm, p: &Pose) -> Gmm {
        Gmm {
            weights: g.weights.clone(),
            means: g.means.iter().map(|m| p.apply(m)).collect(),
            covariances: g.covariances.iter().map(|c| rotate_cov(&p.r, c)).collect(),
        }
    }

    fn error(a: &Pose, b: &Pose) -> f64 {
        let (x, y) = (a.to_matrix(), b.to_matrix());
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn recovers_a_known_transform() {
        let target = scene();
        let truth = Pose::IDENTITY.perturbed(&[0.05, -0.04, 0.3, 0.25, -0.15, 0.05]);
        // source = truth⁻¹(target), so registering source onto target must return truth.
        let inv = Pose {
            r: [0, 1, 2].map(|i| [0, 1, 2].map(|j| truth.r[j][i])),
            t: [0.; 3],
        };
        let inv = Pose {
            t: mat_vec(&inv.r, &truth.t).map(|v| -v),
            ..inv
        };
        let source = moved(&target, &inv);
        let r = register(
            &source,
            &target,
            Some(Pose::IDENTITY),
            None,
            &RegisterOptions::default(),
        )
        .unwrap();
        assert!(error(&r.transform, &truth) < 1e-4, "{:?}", r.transform);
        assert!(r.confidence > 0.999);
        // Without a guess: yaw starts find it too.
        let g = register(&source, &target, None, None, &RegisterOptions::default()).unwrap();
        assert!(error(&g.transform, &truth) < 1e-4);
    }

    #[test]
    fn confidence_is_one_for_itself_and_falls_with_misalignment() {
        let g = scene();
        let p = Problem::new(&g, &g, 1e5);
        let norm = g.l2_inner(&g).unwrap();
        let c = |pose: &Pose| p.evaluate(pose, 0.0, false).f / norm;
        assert!((c(&Pose::IDENTITY) - 1.0).abs() < 1e-12);
        let mut last = 1.0;
        for k in 1..5 {
            let now = c(&Pose::IDENTITY.perturbed(&[0.0, 0.0, 0.0, 0.05 * k as f64, 0.0, 0.0]));
            assert!(now < last);
            last = now;
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let g = scene();
        let src = moved(
            &g,
            &Pose::IDENTITY.perturbed(&[0.1, 0.05, -0.2, 0.1, 0.05, 0.0]),
        );
        let p = Problem::new(&src, &g, 1e5);
        let pose = Pose::IDENTITY.perturbed(&[0.02, -0.03, 0.05, 0.01, -0.02, 0.03]);
        for s2 in [0.0, 0.01] {
            let e = p.evaluate(&pose, s2, true);
            for k in 0..6 {
                let mut d = [0.0; 6];
                d[k] = 1e-6;
                let plus = p.evaluate(&pose.perturbed(&d), s2, false).f;
                d[k] = -1e-6;
                let minus = p.evaluate(&pose.perturbed(&d), s2, false).f;
                let fd = (plus - minus) / 2e-6;
                assert!(
                    (fd - e.grad[k]).abs() < 1e-5 * (1.0 + fd.abs()),
                    "k={k}: {fd} vs {}",
                    e.grad[k]
                );
            }
        }
    }

    #[test]
    fn four_dof_keeps_roll_and_pitch() {
        let target = scene();
        let truth = Pose::IDENTITY.perturbed(&[0.0, 0.0, 0.4, 0.2, 0.1, 0.0]);
        let inv = Pose::IDENTITY.perturbed(&[0.0, 0.0, -0.4, 0.0, 0.0, 0.0]);
        let inv = Pose {
            t: mat_vec(&inv.r, &truth.t).map(|v| -v),
            ..inv
        };
        let source = moved(&target, &inv);
        let opts = RegisterOptions {
            four_dof: true,
            ..Default::default()
        };
        let r = register(&source, &target, Some(Pose::IDENTITY), None, &opts).unwrap();
        assert!(error(&r.transform, &truth) < 1e-4);
        assert_eq!(r.transform.r[2], [0.0, 0.0, 1.0]);
    }

    #[test]
    fn a_corridor_end_for_end_is_an_alternative_and_a_room_is_not() {
        // Two parallel walls and a floor, symmetric under a half turn about +z.
        let mut corridor = Gmm {
            weights: vec![],
            means: vec![],
            covariances: vec![],
        };
        for x in -4..=4 {
            for (y, c) in [
                (-1.0, Sym3::diag(0.06, 1e-4, 0.1)),
                (1.0, Sym3::diag(0.06, 1e-4, 0.1)),
                (0.0, Sym3::diag(0.06, 0.06, 1e-4)),
            ] {
                corridor.weights.push(1.0 / 27.0);
                corridor
                    .means
                    .push([x as f64 * 0.8, y, if y == 0.0 { 0.0 } else { 1.0 }]);
                corridor.covariances.push(c);
            }
        }
        let opts = RegisterOptions::default();
        let r = register(&corridor, &corridor, None, None, &opts).unwrap();
        assert!(r.confidence > 0.99 && r.alternative > 0.9 * r.confidence);
        let room = scene();
        let r = register(&room, &room, None, None, &opts).unwrap();
        assert!(r.confidence > 0.99 && r.alternative < 0.8 * r.confidence);
    }

    #[test]
    fn rejects_empty_and_non_finite() {
        let g = scene();
        let empty = Gmm {
            weights: vec![],
            means: vec![],
            covariances: vec![],
        };
        let o = RegisterOptions::default();
        assert!(register(&empty, &g, None, None, &o).is_err());
        let mut bad = g.clone();
        bad.means[0][1] = f64::NAN;
        assert!(register(&bad, &g, None, None, &o).is_err());
    }
}
