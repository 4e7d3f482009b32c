//! Adaptive model selection (paper IV-B): merge redundant components.
//!
//! Components are classified by shape: a flat one (smallest variance below `flat_ratio` of the
//! middle one) by the direction of its smallest axis, the plane normal, quantised to 13
//! directions of the half-sphere; the rest form one volumetric class. Within a class only
//! components whose means lie within `max_distance` are compared (a spatial hash groups them by
//! position), and pairs whose symmetric Kullback-Leibler divergence is below `kl_threshold`
//! merge, most similar first, by exact moment matching:
//! π = Σπₖ, μ = Σπₖμₖ/π, Σ = Σπₖ(Σₖ + (μₖ−μ)(μₖ−μ)ᵀ)/π. A merged component is re-classified
//! and may merge again. The same routine merges components across submaps of a global map.

use crate::gmm::sub;
use crate::{linalg::Sym3, CoreError, Gmm};
use std::cmp::{Ordering, Reverse};
use std::collections::{BinaryHeap, HashMap};

#[derive(Debug, Clone)]
pub struct SelectOptions {
    /// Smallest/middle variance ratio under which a component counts as flat.
    pub flat_ratio: f64,
    /// Means farther apart than this are never compared (same unit as the means).
    pub max_distance: f64,
    /// Pairs with a symmetric KL divergence below this merge.
    pub kl_threshold: f64,
}

impl Default for SelectOptions {
    fn default() -> Self {
        SelectOptions {
            flat_ratio: 0.1,
            max_distance: 2.0,
            kl_threshold: 16.0,
        }
    }
}

/// The selected mixture and, for each input component, the index of the output component that
/// absorbed it.
#[derive(Debug, Clone)]
pub struct Selection {
    pub gmm: Gmm,
    pub labels: Vec<usize>,
}

/// The volumetric class index (after the 13 normal directions).
const VOLUMETRIC: usize = 13;

/// 13 directions of the half-sphere: 3 axes, 6 face diagonals, 4 body diagonals.
fn directions() -> [[f64; 3]; 13] {
    let raw = [
        [1., 0., 0.],
        [0., 1., 0.],
        [0., 0., 1.],
        [1., 1., 0.],
        [1., -1., 0.],
        [1., 0., 1.],
        [1., 0., -1.],
        [0., 1., 1.],
        [0., 1., -1.],
        [1., 1., 1.],
        [1., 1., -1.],
        [1., -1., 1.],
        [-1., 1., 1.],
    ];
    raw.map(|d: [f64; 3]| {
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        d.map(|v| v / n)
    })
}

/// The shape class of a covariance (see the module docs).
pub fn class_of(cov: &Sym3, flat_ratio: f64) -> usize {
    let (w, v) = cov.eigen();
    if w[0] > flat_ratio * w[1] {
        return VOLUMETRIC;
    }
    let n = v[0];
    let dirs = directions();
    (0..dirs.len())
        .max_by(|&a, &b| {
            let dot = |k: usize| (n[0] * dirs[k][0] + n[1] * dirs[k][1] + n[2] * dirs[k][2]).abs();
            dot(a).total_cmp(&dot(b))
        })
        .expect("13 directions")
}

struct Comp {
    weight: f64,
    mean: [f64; 3],
    cov: Sym3,
    precision: Sym3,
    class: usize,
    cell: [i64; 3],
}

/// KL(p‖q) + KL(q‖p) of two Gaussians (the log-determinants cancel).
fn symmetric_kl(p: &Comp, q: &Comp) -> f64 {
    let d = sub(&p.mean, &q.mean);
    0.5 * (q.precision.trace_product(&p.cov)
        + p.precision.trace_product(&q.cov)
        + p.precision.add(&q.precision).quad(d))
        - 3.0
}

/// Moment matching of two weighted Gaussians (exact for the pair's mixture).
pub fn moment_match(w: [f64; 2], m: [[f64; 3]; 2], c: [Sym3; 2]) -> (f64, [f64; 3], Sym3) {
    let total = w[0] + w[1];
    let mean = [0, 1, 2].map(|a| (w[0] * m[0][a] + w[1] * m[1][a]) / total);
    let part = |k: usize| {
        c[k].add(&Sym3::outer(sub(&m[k], &mean)))
            .scale(w[k] / total)
    };
    (total, mean, part(0).add(&part(1)))
}

/// A candidate merge, ordered by divergence then indices (deterministic).
#[derive(PartialEq)]
struct Candidate(f64, usize, usize);

impl Eq for Candidate {}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0
            .total_cmp(&other.0)
            .then(self.1.cmp(&other.1))
            .then(self.2.cmp(&other.2))
    }
}

struct Merger<'a> {
    opts: &'a SelectOptions,
    comps: Vec<Comp>,
    alive: Vec<bool>,
    /// Components by (class, cell of the mean): the position groups.
    groups: HashMap<(usize, [i64; 3]), Vec<usize>>,
    heap: BinaryHeap<Reverse<Candidate>>,
}

impl<'a> Merger<'a> {
    fn add(&mut self, weight: f64, mean: [f64; 3], cov: Sym3) -> Result<usize, CoreError> {
        let index = self.comps.len();
        let (precision, _) = cov
            .inverse_logdet()
            .ok_or(CoreError::NotPositiveDefinite { component: index })?;
        let class = class_of(&cov, self.opts.flat_ratio);
        let cell = mean.map(|v| (v / self.opts.max_distance).floor() as i64);
        self.comps.push(Comp {
            weight,
            mean,
            cov,
            precision,
            class,
            cell,
        });
        self.alive.push(true);
        self.groups.entry((class, cell)).or_default().push(index);
        Ok(index)
    }

    /// Queues every close, similar, live partner of component `i` of the same class.
    fn queue_partners(&mut self, i: usize, only_lower: bool) {
        let c = &self.comps[i];
        let max2 = self.opts.max_distance * self.opts.max_distance;
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let cell = [c.cell[0] + dx, c.cell[1] + dy, c.cell[2] + dz];
                    let Some(members) = self.groups.get(&(c.class, cell)) else {
                        continue;
                    };
                    for &j in members {
                        if j == i || !self.alive[j] || (only_lower && j > i) {
                            continue;
                        }
                        let o = &self.comps[j];
                        let d = sub(&c.mean, &o.mean);
                        if d[0] * d[0] + d[1] * d[1] + d[2] * d[2] > max2 {
                            continue;
                        }
                        let kl = symmetric_kl(c, o);
                        if kl < self.opts.kl_threshold {
                            self.heap.push(Reverse(Candidate(kl, j.min(i), j.max(i))));
                        }
                    }
                }
            }
        }
    }
}

/// Merges redundant components of `g` (see the module docs).
pub fn select(g: &Gmm, opts: &SelectOptions) -> Result<Selection, CoreError> {
    if !(opts.max_distance > 0.0 && opts.max_distance.is_finite()) {
        return Err(CoreError::InvalidArgument(
            "max_distance must be positive and finite".into(),
        ));
    }
    if !(opts.flat_ratio >= 0.0 && opts.kl_threshold >= 0.0) {
        return Err(CoreError::InvalidArgument(
            "flat_ratio and kl_threshold must be >= 0".into(),
        ));
    }
    let mut m = Merger {
        opts,
        comps: Vec::new(),
        alive: Vec::new(),
        groups: HashMap::new(),
        heap: BinaryHeap::new(),
    };
    for k in 0..g.len() {
        m.add(g.weights[k], g.means[k], g.covariances[k])
            .map_err(|_| CoreError::NotPositiveDefinite { component: k })?;
    }
    for i in 0..g.len() {
        m.queue_partners(i, true);
    }
    // parent[k]: the component that absorbed k (itself while alive).
    let mut parent: Vec<usize> = (0..g.len()).collect();
    while let Some(Reverse(Candidate(_, i, j))) = m.heap.pop() {
        if !(m.alive[i] && m.alive[j]) {
            continue;
        }
        let (a, b) = (&m.comps[i], &m.comps[j]);
        let (w, mu, cov) = moment_match([a.weight, b.weight], [a.mean, b.mean], [a.cov, b.cov]);
        let k = m.add(w, mu, cov)?;
        m.alive[i] = false;
        m.alive[j] = false;
        parent.push(k);
        parent[i] = k;
        parent[j] = k;
        m.queue_partners(k, false);
    }
    let live: Vec<usize> = (0..m.comps.len()).filter(|&k| m.alive[k]).collect();
    let mut out_index = vec![usize::MAX; m.comps.len()];
    for (o, &k) in live.iter().enumerate() {
        out_index[k] = o;
    }
    let root = |mut k: usize| {
        while parent[k] != k {
            k = parent[k];
        }
        k
    };
    let labels = (0..g.len()).map(|k| out_index[root(k)]).collect();
    let gmm = Gmm {
        weights: live.iter().map(|&k| m.comps[k].weight).collect(),
        means: live.iter().map(|&k| m.comps[k].mean).collect(),
        covariances: live.iter().map(|&k| m.comps[k].cov).collect(),
    };
    Ok(Selection { gmm, labels })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(z: f64, x: f64) -> ([f64; 3], Sym3) {
        ([x, 0.0, z], Sym3::diag(0.04, 0.04, 1e-4))
    }

    #[test]
    fn moment_matching_preserves_mass_mean_and_covariance() {
        let (w, m) = ([0.3, 0.1], [[0.0, 1.0, 2.0], [1.0, -1.0, 0.5]]);
        let c = [
            Sym3::diag(0.1, 0.2, 0.3),
            Sym3 {
                xx: 0.2,
                yy: 0.1,
                zz: 0.4,
                xy: 0.05,
                xz: 0.0,
                yz: -0.02,
            },
        ];
        let (tw, tm, tc) = moment_match(w, m, c);
        assert!((tw - 0.4).abs() < 1e-15);
        // Mixture mean and covariance about the origin, computed directly.
        for a in 0..3 {
            assert!((tw * tm[a] - (w[0] * m[0][a] + w[1] * m[1][a])).abs() < 1e-14);
        }
        let second = |k: usize| c[k].add(&Sym3::outer(m[k])).scale(w[k]);
        let want = second(0)
            .add(&second(1))
            .scale(1.0 / tw)
            .add(&Sym3::outer(tm).scale(-1.0));
        for (x, y) in tc.to_rows().iter().zip(want.to_rows()) {
            assert!((x - y).abs() < 1e-14);
        }
    }

    #[test]
    fn copies_of_one_component_merge_into_it() {
        let (mean, cov) = plane(1.0, 0.0);
        let g = Gmm {
            weights: vec![0.25; 4],
            means: vec![mean; 4],
            covariances: vec![cov; 4],
        };
        let s = select(&g, &SelectOptions::default()).unwrap();
        assert_eq!(s.gmm.len(), 1);
        assert!((s.gmm.weights[0] - 1.0).abs() < 1e-15);
        assert_eq!(s.gmm.means[0], mean);
        for (x, y) in s.gmm.covariances[0].to_rows().iter().zip(cov.to_rows()) {
            assert!((x - y).abs() < 1e-15);
        }
        assert_eq!(s.labels, vec![0; 4]);
    }

    #[test]
    fn nothing_merges_across_classes() {
        // A floor patch and a wall patch at the same place: different normals.
        let floor = Sym3::diag(0.04, 0.04, 1e-4);
        let wall = Sym3::diag(1e-4, 0.04, 0.04);
        let g = Gmm {
            weights: vec![0.5, 0.5],
            means: vec![[0.0; 3]; 2],
            covariances: vec![floor, wall],
        };
        let s = select(
            &g,
            &SelectOptions {
                kl_threshold: 1e9,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(s.gmm.len(), 2);
        assert_ne!(class_of(&floor, 0.1), class_of(&wall, 0.1));
    }

    #[test]
    fn near_duplicates_merge_distant_ones_do_not() {
        let (a, ca) = plane(1.0, 0.0);
        let (b, cb) = plane(1.0, 0.02);
        let (c, cc) = plane(1.0, 5.0);
        let g = Gmm {
            weights: vec![0.4, 0.4, 0.2],
            means: vec![a, b, c],
            covariances: vec![ca, cb, cc],
        };
        let s = select(&g, &SelectOptions::default()).unwrap();
        assert_eq!(s.gmm.len(), 2);
        assert_eq!(s.labels, vec![1, 1, 0]);
        assert!((s.gmm.weights.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }
}
