//! Expectation-maximisation for 3-D Gaussian mixtures, truncated on a uniform grid.
//!
//! A component contributes nothing measurable to points many standard deviations away, so the
//! points are bucketed once into grid cells and, each iteration, a cell only evaluates the
//! components whose `truncation`-sigma ellipsoid can reach it. Inside a cell the work is done in
//! blocks of points × components with contiguous, branch-free loops that LLVM vectorises
//! (including `exp`, see `fastmath`). Cells are split into a fixed number of chunks processed in
//! parallel and reduced in a fixed order, so a seed gives bit-identical fits on any thread count.
//! `truncation = ∞` evaluates every pair: plain EM.

use crate::fastmath::exp_nonpos;
use crate::gmm::{Gmm, Prepared};
use crate::init::{kmeans_pp, nearest, random_points};
use crate::{check_finite, linalg::Sym3, rng::Rng, CoreError};
use rayon::prelude::*;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CovType {
    Diag,
    Full,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitMethod {
    KMeansPlusPlus,
    Random,
}

#[derive(Debug, Clone)]
pub struct EmOptions {
    pub n_components: usize,
    pub covariance: CovType,
    pub max_iter: usize,
    /// Stop when the mean log-likelihood per point changes by less than this.
    pub tol: f64,
    pub seed: u64,
    pub init: InitMethod,
    /// Added to every variance after each M-step (the variance floor), in squared units.
    pub reg_covar: f64,
    /// Mahalanobis radius (in standard deviations) beyond which a component is not evaluated.
    pub truncation: f64,
}

impl Default for EmOptions {
    fn default() -> Self {
        EmOptions {
            n_components: 100,
            covariance: CovType::Diag,
            max_iter: 100,
            tol: 1e-3,
            seed: 0,
            init: InitMethod::KMeansPlusPlus,
            reg_covar: 1e-6,
            truncation: 5.0,
        }
    }
}

#[derive(Debug, Clone)]
pub struct EmResult {
    /// The fitted mixture; components that lost all their points are dropped.
    pub gmm: Gmm,
    pub n_iter: usize,
    pub converged: bool,
    /// Mean log-likelihood per point from the last E-step (truncated evaluation).
    pub log_likelihood: f64,
}

/// Sufficient statistics per component: mass, Σr·d (3), Σr·d·dᵀ (xx, yy, zz, xy, xz, yz),
/// with d = x − μ_old so the update does not lose precision to cancellation.
const NSTAT: usize = 10;
/// A component with less total responsibility than this has no data left: it is dropped.
const MIN_MASS: f64 = 1e-6;

/// Fits a mixture to `points` by EM. Deterministic for a seed.
pub fn fit(points: &[[f64; 3]], opts: &EmOptions) -> Result<EmResult, CoreError> {
    validate(points, opts)?;
    let (pts, centre) = centred(points);
    let mut rng = Rng::new(opts.seed);
    let seeds = match opts.init {
        InitMethod::KMeansPlusPlus => kmeans_pp(&pts, opts.n_components, &mut rng),
        InitMethod::Random => random_points(&pts, opts.n_components, &mut rng),
    };
    let model = Model::from_seeds(&pts, &seeds, opts);
    iterate(&pts, centre, model, opts)
}

/// Continues EM on `points` from the mixture `start` (its size replaces `n_components`;
/// `init` and `seed` are unused). Used to re-fit a submap after its components were merged.
pub fn refine(points: &[[f64; 3]], start: &Gmm, opts: &EmOptions) -> Result<EmResult, CoreError> {
    validate(points, opts)?;
    start.prepare()?; // every covariance positive-definite
    let (pts, centre) = centred(points);
    let model = Model {
        weights: start.weights.clone(),
        means: start
            .means
            .iter()
            .map(|m| [m[0] - centre[0], m[1] - centre[1], m[2] - centre[2]])
            .collect(),
        covs: start.covariances.clone(),
        alive: start.weights.iter().map(|&w| w > 0.0).collect(),
    };
    iterate(&pts, centre, model, opts)
}

/// The points around their centroid (keeps squares small and the grid well-conditioned).
fn centred(points: &[[f64; 3]]) -> (Vec<[f64; 3]>, [f64; 3]) {
    let c = centroid(points);
    (
        points
            .iter()
            .map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]])
            .collect(),
        c,
    )
}

/// The EM iterations from `model` until convergence or `max_iter`.
fn iterate(
    pts: &[[f64; 3]],
    centre: [f64; 3],
    mut model: Model,
    opts: &EmOptions,
) -> Result<EmResult, CoreError> {
    let grid = Grid::new(pts, model.alive.len());
    let (mut prev, mut log_likelihood) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    let (mut n_iter, mut converged) = (0, false);
    while n_iter < opts.max_iter {
        n_iter += 1;
        let (stats, ll_sum) = grid.e_step(&model, opts)?;
        log_likelihood = ll_sum / pts.len() as f64;
        model.m_step(&stats, opts);
        if (log_likelihood - prev).abs() < opts.tol {
            converged = true;
            break;
        }
        prev = log_likelihood;
    }
    Ok(EmResult {
        gmm: model.into_gmm(centre),
        n_iter,
        converged,
        log_likelihood,
    })
}

fn validate(points: &[[f64; 3]], opts: &EmOptions) -> Result<(), CoreError> {
    let bad = |msg: String| Err(CoreError::InvalidArgument(msg));
    if points.is_empty() {
        return Err(CoreError::Empty);
    }
    if opts.n_components == 0 {
        return bad("n_components must be at least 1".into());
    }
    if !(opts.tol.is_finite() && opts.tol >= 0.0) {
        return bad(format!("tol must be finite and >= 0, got {}", opts.tol));
    }
    if !(opts.reg_covar.is_finite() && opts.reg_covar > 0.0) {
        return bad(format!(
            "reg_covar must be finite and > 0, got {}",
            opts.reg_covar
        ));
    }
    if opts.truncation.is_nan() || opts.truncation <= 0.0 {
        return bad(format!("truncation must be > 0, got {}", opts.truncation));
    }
    check_finite(points)
}

fn centroid(points: &[[f64; 3]]) -> [f64; 3] {
    let n = points.len() as f64;
    let s = points
        .iter()
        .fold([0.0; 3], |a, p| [a[0] + p[0], a[1] + p[1], a[2] + p[2]]);
    [s[0] / n, s[1] / n, s[2] / n]
}

/// Parameters during EM, in centred coordinates; dead components stay in place, skipped.
struct Model {
    weights: Vec<f64>,
    means: Vec<[f64; 3]>,
    covs: Vec<Sym3>,
    alive: Vec<bool>,
}

impl Model {
    /// Hard-assigns each point to its nearest seed and takes the clusters' moments.
    fn from_seeds(pts: &[[f64; 3]], seeds: &[[f64; 3]], opts: &EmOptions) -> Model {
        let k = seeds.len();
        let mut model = Model {
            weights: vec![1.0 / k as f64; k],
            means: seeds.to_vec(),
            covs: vec![Sym3::diag(1.0, 1.0, 1.0); k],
            alive: vec![true; k],
        };
        let mut stats = vec![0.0; k * NSTAT];
        for (p, j) in pts.iter().zip(nearest(pts, seeds)) {
            let d = [p[0] - seeds[j][0], p[1] - seeds[j][1], p[2] - seeds[j][2]];
            add_weighted(&mut stats[j * NSTAT..(j + 1) * NSTAT], 1.0, d);
        }
        model.m_step(&stats, opts);
        model
    }

    fn m_step(&mut self, stats: &[f64], opts: &EmOptions) {
        let total: f64 = (0..self.alive.len())
            .filter(|&k| self.alive[k])
            .map(|k| stats[k * NSTAT])
            .sum();
        for k in 0..self.alive.len() {
            let s = &stats[k * NSTAT..(k + 1) * NSTAT];
            if !self.alive[k] || s[0] < MIN_MASS {
                self.alive[k] = false;
                self.weights[k] = 0.0;
                continue;
            }
            let n = s[0];
            let d = [s[1] / n, s[2] / n, s[3] / n];
            let m = &mut self.means[k];
            *m = [m[0] + d[0], m[1] + d[1], m[2] + d[2]];
            // Variances floored at zero against rounding, then regularised.
            let var = |i: usize, a: usize| (s[i] / n - d[a] * d[a]).max(0.0) + opts.reg_covar;
            let diag = Sym3::diag(var(4, 0), var(5, 1), var(6, 2));
            self.covs[k] = match opts.covariance {
                CovType::Diag => diag,
                CovType::Full => {
                    let full = Sym3 {
                        xy: s[7] / n - d[0] * d[1],
                        xz: s[8] / n - d[0] * d[2],
                        yz: s[9] / n - d[1] * d[2],
                        ..diag
                    };
                    if full.cholesky().is_some() {
                        full
                    } else {
                        diag
                    }
                }
            };
            self.weights[k] = n / total;
        }
    }

    fn into_gmm(self, centre: [f64; 3]) -> Gmm {
        let live: Vec<usize> = (0..self.alive.len()).filter(|&k| self.alive[k]).collect();
        let total: f64 = live.iter().map(|&k| self.weights[k]).sum();
        Gmm {
            weights: live.iter().map(|&k| self.weights[k] / total).collect(),
            means: live
                .iter()
                .map(|&k| {
                    let m = self.means[k];
                    [m[0] + centre[0], m[1] + centre[1], m[2] + centre[2]]
                })
                .collect(),
            covariances: live.iter().map(|&k| self.covs[k]).collect(),
        }
    }
}

#[inline(always)]
fn add_weighted(s: &mut [f64], r: f64, d: [f64; 3]) {
    let [x, y, z] = d;
    let v = [
        r,
        r * x,
        r * y,
        r * z,
        r * x * x,
        r * y * y,
        r * z * z,
        r * x * y,
        r * x * z,
        r * y * z,
    ];
    for (a, b) in s.iter_mut().zip(v) {
        *a += b;
    }
}

/// Target points per occupied cell: more cells prune better, fewer cost less bookkeeping.
const POINTS_PER_CELL: usize = 32;
const MAX_CELLS: usize = 1 << 21;
/// Fixed number of parallel work chunks: the reduction order must not depend on thread count.
const CHUNKS: usize = 64;
/// Points evaluated together against a cell's components.
const BLOCK: usize = 64;

struct Cell {
    lo: [f64; 3],
    start: usize,
    end: usize,
}

/// Points sorted by a uniform grid's cells, with the occupied cells and their work chunks.
struct Grid {
    cell: f64,
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    cells: Vec<Cell>,
    chunks: Vec<(usize, usize)>,
}

impl Grid {
    fn new(pts: &[[f64; 3]], k: usize) -> Grid {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in pts {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let extent = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
        let target = (pts.len() / POINTS_PER_CELL).max(2 * k).max(1);
        let cell = choose_cell_size(pts, lo, extent, target);
        let dims = dims_for(lo, hi, cell);
        let index = |p: &[f64; 3]| -> u64 {
            let i = |a: usize| (((p[a] - lo[a]) / cell) as u64).min(dims[a] - 1);
            (i(0) * dims[1] + i(1)) * dims[2] + i(2)
        };
        let mut order: Vec<(u64, u32)> = pts
            .par_iter()
            .enumerate()
            .map(|(i, p)| (index(p), i as u32))
            .collect();
        order.par_sort_unstable();

        let mut cells: Vec<Cell> = Vec::new();
        for (pos, &(id, _)) in order.iter().enumerate() {
            if pos == 0 || order[pos - 1].0 != id {
                let (ix, iy, iz) = (
                    id / (dims[1] * dims[2]),
                    (id / dims[2]) % dims[1],
                    id % dims[2],
                );
                let corner = [ix as f64, iy as f64, iz as f64];
                let lo = [
                    lo[0] + corner[0] * cell,
                    lo[1] + corner[1] * cell,
                    lo[2] + corner[2] * cell,
                ];
                cells.push(Cell {
                    lo,
                    start: pos,
                    end: pos,
                });
            }
            cells.last_mut().expect("pushed above").end = pos + 1;
        }
        let gather = |a: usize| order.iter().map(|&(_, i)| pts[i as usize][a]).collect();
        let chunks = split_by_points(&cells, pts.len());
        Grid {
            cell,
            xs: gather(0),
            ys: gather(1),
            zs: gather(2),
            cells,
            chunks,
        }
    }

    /// One E-step: sufficient statistics per component and the summed log-likelihood.
    fn e_step(&self, model: &Model, opts: &EmOptions) -> Result<(Vec<f64>, f64), CoreError> {
        let comps = Components::new(model, opts)?;
        let k = model.alive.len();
        let partial: Vec<(Vec<f64>, f64)> = self
            .chunks
            .par_iter()
            .map(|&(a, b)| {
                let mut work = Work::new(k);
                let mut ll = 0.0;
                for cell in &self.cells[a..b] {
                    comps.select(cell, self.cell, &mut work);
                    for s in (cell.start..cell.end).step_by(BLOCK) {
                        let e = (s + BLOCK).min(cell.end);
                        let block = [&self.xs[s..e], &self.ys[s..e], &self.zs[s..e]];
                        ll += match opts.covariance {
                            CovType::Diag => work.block::<false>(block),
                            CovType::Full => work.block::<true>(block),
                        };
                    }
                }
                (work.stats, ll)
            })
            .collect();
        let mut stats = vec![0.0; k * NSTAT];
        let mut ll = 0.0;
        for (s, l) in partial {
            stats.iter_mut().zip(&s).for_each(|(a, b)| *a += b);
            ll += l;
        }
        Ok((stats, ll))
    }
}

fn dims_for(lo: [f64; 3], hi: [f64; 3], cell: f64) -> [u64; 3] {
    [0, 1, 2].map(|a| ((hi[a] - lo[a]) / cell).floor() as u64 + 1)
}

/// The cell edge at which about `target` cells are occupied. Occupancy grows as cell^-D with
/// the scene's dimension D (about 2 for the surfaces sensors see), measured at two sizes.
fn choose_cell_size(pts: &[[f64; 3]], lo: [f64; 3], extent: f64, target: usize) -> f64 {
    if extent <= 0.0 {
        return 1.0;
    }
    let coarse = extent / 8.0;
    let fine = coarse / 2.0;
    let (a, b) = (
        occupied(pts, lo, coarse) as f64,
        occupied(pts, lo, fine) as f64,
    );
    let dim = (b / a).log2().clamp(1.0, 3.0);
    let cell = fine * (b / target as f64).powf(1.0 / dim);
    // At most cbrt(MAX_CELLS) cells along any axis, so dense cell ids stay small.
    cell.max(extent / (MAX_CELLS as f64).cbrt())
}

/// Occupied cells of edge `cell`, counted in a hashed bitmap (collisions undercount a little).
fn occupied(pts: &[[f64; 3]], lo: [f64; 3], cell: f64) -> usize {
    let bits = (8 * pts.len()).next_power_of_two().clamp(1 << 16, 1 << 24);
    let mut map = vec![0u64; bits / 64];
    let mut count = 0;
    for p in pts {
        let i = |a: usize| ((p[a] - lo[a]) / cell) as u64;
        let h = (i(0).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ i(1).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
            ^ i(2).wrapping_mul(0x1656_67B1_9E37_79F9);
        let h = (h >> 20) as usize & (bits - 1);
        let (w, b) = (h / 64, 1u64 << (h % 64));
        count += (map[w] & b == 0) as usize;
        map[w] |= b;
    }
    count
}

/// Contiguous cell ranges holding about equal numbers of points.
fn split_by_points(cells: &[Cell], n: usize) -> Vec<(usize, usize)> {
    let per = n.div_ceil(CHUNKS).max(1);
    let mut chunks = Vec::new();
    let mut start = 0;
    for (i, c) in cells.iter().enumerate() {
        if c.end - cells[start].start >= per || i + 1 == cells.len() {
            chunks.push((start, i + 1));
            start = i + 1;
        }
    }
    chunks
}

/// Per-component data for one E-step: evaluation terms and the reach of each ellipsoid.
struct Components {
    prepared: Vec<Option<Prepared>>,
    /// Squared reach per axis: truncation² · Σ_aa (full) or the precisions (diagonal test).
    reach2: Vec<[f64; 3]>,
    diag: bool,
    tau: f64,
}

impl Components {
    fn new(model: &Model, opts: &EmOptions) -> Result<Components, CoreError> {
        let tau = opts.truncation * opts.truncation;
        let mut prepared = Vec::with_capacity(model.alive.len());
        let mut reach2 = Vec::with_capacity(model.alive.len());
        for k in 0..model.alive.len() {
            let c = &model.covs[k];
            prepared.push(if model.alive[k] {
                let p = Prepared::new(model.weights[k], model.means[k], c)
                    .ok_or(CoreError::NotPositiveDefinite { component: k })?;
                Some(p)
            } else {
                None
            });
            reach2.push([tau * c.xx, tau * c.yy, tau * c.zz]);
        }
        Ok(Components {
            prepared,
            reach2,
            diag: opts.covariance == CovType::Diag,
            tau,
        })
    }

    /// Packs into `work` the components that can reach `cell` (all of them if none can).
    fn select(&self, cell: &Cell, size: f64, work: &mut Work) {
        work.clear();
        for (k, p) in self.prepared.iter().enumerate() {
            let Some(p) = p else { continue };
            let gap = |a: usize| {
                (cell.lo[a] - p.mean[a])
                    .max(p.mean[a] - cell.lo[a] - size)
                    .max(0.0)
            };
            let g = [gap(0), gap(1), gap(2)];
            let reaches = if self.diag {
                // Exact: the smallest Mahalanobis distance from the mean to the cell.
                let pr = &p.precision;
                pr.xx * g[0] * g[0] + pr.yy * g[1] * g[1] + pr.zz * g[2] * g[2] <= self.tau
            } else {
                // The ellipsoid's bounding box touches the cell.
                (0..3).all(|a| g[a] * g[a] <= self.reach2[k][a])
            };
            if reaches {
                work.push(k, p);
            }
        }
        if work.comp.is_empty() {
            for (k, p) in self.prepared.iter().enumerate() {
                if let Some(p) = p {
                    work.push(k, p);
                }
            }
        }
    }
}

/// A chunk's scratch space: the cell's packed components (structure of arrays), the block of
/// log-terms, and the chunk's statistics.
struct Work {
    comp: Vec<usize>,
    /// mean x, y, z; precision xx, yy, zz, xy, xz, yz; log coefficient — one Vec per field.
    par: [Vec<f64>; 10],
    terms: Vec<f64>,
    stats: Vec<f64>,
}

impl Work {
    fn new(k: usize) -> Work {
        Work {
            comp: Vec::new(),
            par: Default::default(),
            terms: Vec::new(),
            stats: vec![0.0; k * NSTAT],
        }
    }

    fn clear(&mut self) {
        self.comp.clear();
        self.par.iter_mut().for_each(Vec::clear);
    }

    fn push(&mut self, k: usize, p: &Prepared) {
        self.comp.push(k);
        let pr = &p.precision;
        let v = [
            p.mean[0], p.mean[1], p.mean[2], pr.xx, pr.yy, pr.zz, pr.xy, pr.xz, pr.yz, p.log_coef,
        ];
        for (f, x) in self.par.iter_mut().zip(v) {
            f.push(x);
        }
    }

    /// E-step for up to BLOCK points against the packed components; returns Σ log p(x).
    fn block<const FULL: bool>(&mut self, pts: [&[f64]; 3]) -> f64 {
        let n = pts[0].len();
        // Pad to a multiple of 4 lanes by repeating the last point; padded lanes get zero weight.
        let width = n.div_ceil(4) * 4;
        let mut xyz = [[0.0; BLOCK]; 3];
        for a in 0..3 {
            xyz[a][..n].copy_from_slice(pts[a]);
            let last = pts[a][n - 1];
            xyz[a][n..width].fill(last);
        }
        let [xs, ys, zs] = [&xyz[0][..width], &xyz[1][..width], &xyz[2][..width]];
        let m = self.comp.len();
        self.terms.resize(m * width, 0.0);
        let [mx, my, mz, pxx, pyy, pzz, pxy, pxz, pyz, lc] = &self.par;

        // Log-terms, one row of points per component.
        for j in 0..m {
            let row = &mut self.terms[j * width..(j + 1) * width];
            let (cx, cy, cz) = (mx[j], my[j], mz[j]);
            for (((t, &x), &y), &z) in row.iter_mut().zip(xs).zip(ys).zip(zs) {
                let (dx, dy, dz) = (x - cx, y - cy, z - cz);
                let mut q = pxx[j] * dx * dx + pyy[j] * dy * dy + pzz[j] * dz * dz;
                if FULL {
                    q += 2.0 * (pxy[j] * dx * dy + pxz[j] * dx * dz + pyz[j] * dy * dz);
                }
                *t = lc[j] - 0.5 * q;
            }
        }
        // Per-point maximum, then exp and sum (all across points: vectorisable).
        let mut max = [f64::NEG_INFINITY; BLOCK];
        for j in 0..m {
            for (a, &t) in max[..width]
                .iter_mut()
                .zip(&self.terms[j * width..(j + 1) * width])
            {
                *a = if t > *a { t } else { *a };
            }
        }
        let mut sum = [0.0; BLOCK];
        for j in 0..m {
            let row = &mut self.terms[j * width..(j + 1) * width];
            for ((t, s), &mx) in row.iter_mut().zip(&mut sum[..width]).zip(&max[..width]) {
                *t = exp_nonpos(*t - mx);
                *s += *t;
            }
        }
        let mut inv = [0.0; BLOCK];
        let mut ll = 0.0;
        for i in 0..n {
            inv[i] = 1.0 / sum[i];
            ll += max[i] + sum[i].ln();
        }
        // Responsibilities times moments, reduced over points in 4 lanes.
        for j in 0..m {
            let row = &self.terms[j * width..(j + 1) * width];
            let c = [mx[j], my[j], mz[j]];
            let mut lanes = [[0.0; 4]; NSTAT];
            for i0 in (0..width).step_by(4) {
                // Lane-indexed on purpose: four independent sums that LLVM packs into vectors.
                #[allow(clippy::needless_range_loop)]
                for l in 0..4 {
                    let i = i0 + l;
                    let r = row[i] * inv[i];
                    let (dx, dy, dz) = (xs[i] - c[0], ys[i] - c[1], zs[i] - c[2]);
                    let (rx, ry, rz) = (r * dx, r * dy, r * dz);
                    lanes[0][l] += r;
                    lanes[1][l] += rx;
                    lanes[2][l] += ry;
                    lanes[3][l] += rz;
                    lanes[4][l] += rx * dx;
                    lanes[5][l] += ry * dy;
                    lanes[6][l] += rz * dz;
                    if FULL {
                        lanes[7][l] += rx * dy;
                        lanes[8][l] += rx * dz;
                        lanes[9][l] += ry * dz;
                    }
                }
            }
            let out = &mut self.stats[self.comp[j] * NSTAT..(self.comp[j] + 1) * NSTAT];
            for (o, l) in out.iter_mut().zip(&lanes) {
                *o += (l[0] + l[1]) + (l[2] + l[3]);
            }
        }
        ll
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points from a known 3-component mixture (box-Muller on our own generator).
    fn sample_known(n: usize, seed: u64) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let means = vec![[0.0, 0.0, 0.0], [4.0, 0.0, 1.0], [0.0, 5.0, -2.0]];
        let sd = [[0.3, 0.5, 0.2], [0.6, 0.2, 0.4], [0.2, 0.2, 0.7]];
        let mut rng = Rng::new(seed);
        let mut normal = || {
            let (u, v) = (rng.uniform().max(1e-300), rng.uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        };
        let pts = (0..n)
            .map(|i| {
                let k = i % 3;
                [0, 1, 2].map(|a| means[k][a] + sd[k][a] * normal())
            })
            .collect();
        (pts, means)
    }

    #[test]
    fn recovers_known_means() {
        let (pts, truth) = sample_known(6000, 1);
        for cov in [CovType::Diag, CovType::Full] {
            let opts = EmOptions {
                n_components: 3,
                covariance: cov,
                ..Default::default()
            };
            let fit = fit(&pts, &opts).unwrap();
            assert_eq!(fit.gmm.len(), 3);
            for m in &truth {
                let closest = fit
                    .gmm
                    .means
                    .iter()
                    .map(|g| {
                        ((g[0] - m[0]).powi(2) + (g[1] - m[1]).powi(2) + (g[2] - m[2]).powi(2))
                            .sqrt()
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(closest < 0.05, "{cov:?}: mean {m:?} missed by {closest}");
            }
            assert!(fit.gmm.weights.iter().all(|w| (w - 1.0 / 3.0).abs() < 0.02));
        }
    }

    #[test]
    fn truncation_barely_changes_the_fit() {
        let (pts, _) = sample_known(3000, 2);
        let base = EmOptions {
            n_components: 12,
            max_iter: 20,
            tol: 0.0,
            ..Default::default()
        };
        let exact = fit(
            &pts,
            &EmOptions {
                truncation: f64::INFINITY,
                ..base.clone()
            },
        )
        .unwrap();
        let pruned = fit(&pts, &base).unwrap();
        let score = |g: &Gmm| g.log_pdf(&pts).unwrap().iter().sum::<f64>() / pts.len() as f64;
        assert!((score(&exact.gmm) - score(&pruned.gmm)).abs() < 1e-3);
    }

    #[test]
    fn same_seed_same_fit_other_seed_differs() {
        let (pts, _) = sample_known(2000, 3);
        let opts = EmOptions {
            n_components: 8,
            ..Default::default()
        };
        let a = fit(&pts, &opts).unwrap();
        let b = fit(&pts, &opts).unwrap();
        assert_eq!(a.gmm, b.gmm);
        let c = fit(&pts, &EmOptions { seed: 9, ..opts }).unwrap();
        assert_ne!(a.gmm, c.gmm);
    }

    #[test]
    fn refine_from_a_fit_improves_or_keeps_the_likelihood() {
        let (pts, _) = sample_known(3000, 4);
        let base = EmOptions {
            n_components: 6,
            max_iter: 3,
            tol: 0.0,
            ..Default::default()
        };
        let rough = fit(&pts, &base).unwrap();
        let more = refine(
            &pts,
            &rough.gmm,
            &EmOptions {
                max_iter: 20,
                covariance: CovType::Full,
                ..base
            },
        )
        .unwrap();
        let score = |g: &Gmm| g.log_pdf(&pts).unwrap().iter().sum::<f64>() / pts.len() as f64;
        assert_eq!(more.gmm.len(), 6);
        assert!(score(&more.gmm) > score(&rough.gmm));
    }

    #[test]
    fn degenerate_inputs() {
        // Fewer distinct points than components, all on a plane: floor keeps covariances PD.
        let pts = vec![
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [0.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let f = fit(
            &pts,
            &EmOptions {
                n_components: 10,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(f.gmm.len(), 3);
        assert!(f.gmm.covariances.iter().all(|c| c.cholesky().is_some()));
        assert!((f.gmm.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let one = fit(&[[1.0, 2.0, 3.0]], &EmOptions::default()).unwrap();
        assert_eq!(one.gmm.means, vec![[1.0, 2.0, 3.0]]);
    }

    #[test]
    fn rejects_bad_input() {
        let o = EmOptions::default();
        assert_eq!(fit(&[], &o).unwrap_err(), CoreError::Empty);
        assert_eq!(
            fit(&[[0.0, f64::INFINITY, 0.0]], &o).unwrap_err(),
            CoreError::NonFinite { row: 0 }
        );
        assert!(fit(
            &[[0.0; 3]],
            &EmOptions {
                n_components: 0,
                ..o.clone()
            }
        )
        .is_err());
        assert!(fit(
            &[[0.0; 3]],
            &EmOptions {
                reg_covar: 0.0,
                ..o.clone()
            }
        )
        .is_err());
        assert!(fit(&[[0.0; 3]], &EmOptions { tol: f64::NAN, ..o }).is_err());
    }
}
