//! Symmetric 3x3 matrices: just what densities and EM need, without a linear-algebra dependency.

/// A symmetric 3x3 matrix stored as its six unique entries.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sym3 {
    pub xx: f64,
    pub yy: f64,
    pub zz: f64,
    pub xy: f64,
    pub xz: f64,
    pub yz: f64,
}

impl Sym3 {
    pub fn diag(x: f64, y: f64, z: f64) -> Self {
        Sym3 {
            xx: x,
            yy: y,
            zz: z,
            ..Default::default()
        }
    }

    /// From a row-major 3x3 matrix; the upper triangle is used.
    pub fn from_rows(m: &[f64]) -> Self {
        Sym3 {
            xx: m[0],
            xy: m[1],
            xz: m[2],
            yy: m[4],
            yz: m[5],
            zz: m[8],
        }
    }

    pub fn to_rows(self) -> [f64; 9] {
        [
            self.xx, self.xy, self.xz, self.xy, self.yy, self.yz, self.xz, self.yz, self.zz,
        ]
    }

    pub fn is_diagonal(&self) -> bool {
        self.xy == 0.0 && self.xz == 0.0 && self.yz == 0.0
    }

    pub fn add_diag(self, v: f64) -> Self {
        Sym3 {
            xx: self.xx + v,
            yy: self.yy + v,
            zz: self.zz + v,
            ..self
        }
    }

    pub fn det(&self) -> f64 {
        self.xx * (self.yy * self.zz - self.yz * self.yz)
            - self.xy * (self.xy * self.zz - self.yz * self.xz)
            + self.xz * (self.xy * self.yz - self.yy * self.xz)
    }

    /// Lower Cholesky factor [l00, l10, l11, l20, l21, l22], or None if not positive-definite.
    pub fn cholesky(&self) -> Option<[f64; 6]> {
        let l00 = positive_sqrt(self.xx)?;
        let l10 = self.xy / l00;
        let l20 = self.xz / l00;
        let l11 = positive_sqrt(self.yy - l10 * l10)?;
        let l21 = (self.yz - l20 * l10) / l11;
        let l22 = positive_sqrt(self.zz - l20 * l20 - l21 * l21)?;
        Some([l00, l10, l11, l20, l21, l22])
    }

    /// Inverse and log-determinant via Cholesky (so it fails loudly on non-PD input).
    pub fn inverse_logdet(&self) -> Option<(Sym3, f64)> {
        let (inv, root) = self.inverse_sqrt_det()?;
        Some((inv, 2.0 * root.ln()))
    }

    /// Inverse and sqrt(det) via Cholesky: densities need 1/sqrt(det), and no logarithm.
    pub fn inverse_sqrt_det(&self) -> Option<(Sym3, f64)> {
        let [a, b, c, d, e, f] = self.cholesky()?;
        // Invert the lower factor L, then Σ⁻¹ = L⁻ᵀ L⁻¹.
        let (i00, i11, i22) = (1.0 / a, 1.0 / c, 1.0 / f);
        let i10 = -b * i00 * i11;
        let i21 = -e * i11 * i22;
        let i20 = -(d * i00 + e * i10) * i22;
        let inv = Sym3 {
            xx: i00 * i00 + i10 * i10 + i20 * i20,
            xy: i10 * i11 + i20 * i21,
            xz: i20 * i22,
            yy: i11 * i11 + i21 * i21,
            yz: i21 * i22,
            zz: i22 * i22,
        };
        Some((inv, a * c * f))
    }

    /// dᵀ M d.
    #[inline(always)]
    pub fn quad(&self, d: [f64; 3]) -> f64 {
        let [x, y, z] = d;
        self.xx * x * x
            + self.yy * y * y
            + self.zz * z * z
            + 2.0 * (self.xy * x * y + self.xz * x * z + self.yz * y * z)
    }

    /// M d.
    #[inline(always)]
    pub fn mul_vec(&self, d: [f64; 3]) -> [f64; 3] {
        let [x, y, z] = d;
        [
            self.xx * x + self.xy * y + self.xz * z,
            self.xy * x + self.yy * y + self.yz * z,
            self.xz * x + self.yz * y + self.zz * z,
        ]
    }
}

impl Sym3 {
    /// Eigen-decomposition by cyclic Jacobi rotations: eigenvalues ascending and the matching
    /// unit eigenvectors (returned as rows). Accurate to rounding for any symmetric input.
    pub fn eigen(&self) -> ([f64; 3], [[f64; 3]; 3]) {
        let mut a = [
            [self.xx, self.xy, self.xz],
            [self.xy, self.yy, self.yz],
            [self.xz, self.yz, self.zz],
        ];
        let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for _ in 0..50 {
            let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
            let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
            if off <= 1e-300 || off <= f64::EPSILON * 1e-3 * scale {
                break;
            }
            for (p, q) in [(0, 1), (0, 2), (1, 2)] {
                if a[p][q] == 0.0 {
                    continue;
                }
                // The rotation that zeroes a[p][q] (Golub & Van Loan, symmetric Schur).
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                // A ← Jᵀ A J: columns p, q first, then rows p, q.
                for row in a.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - s * y;
                    row[q] = s * x + c * y;
                }
                let (rp, rq) = (a[p], a[q]);
                a[p] = [0, 1, 2].map(|k| c * rp[k] - s * rq[k]);
                a[q] = [0, 1, 2].map(|k| s * rp[k] + c * rq[k]);
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
        let mut order = [0, 1, 2];
        order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
        let values = order.map(|i| a[i][i]);
        let vectors = order.map(|i| [v[0][i], v[1][i], v[2][i]]);
        (values, vectors)
    }

    /// tr(A B) of two symmetric matrices.
    pub fn trace_product(&self, b: &Sym3) -> f64 {
        self.xx * b.xx
            + self.yy * b.yy
            + self.zz * b.zz
            + 2.0 * (self.xy * b.xy + self.xz * b.xz + self.yz * b.yz)
    }

    pub fn add(&self, b: &Sym3) -> Sym3 {
        Sym3 {
            xx: self.xx + b.xx,
            yy: self.yy + b.yy,
            zz: self.zz + b.zz,
            xy: self.xy + b.xy,
            xz: self.xz + b.xz,
            yz: self.yz + b.yz,
        }
    }

    pub fn scale(&self, f: f64) -> Sym3 {
        Sym3 {
            xx: self.xx * f,
            yy: self.yy * f,
            zz: self.zz * f,
            xy: self.xy * f,
            xz: self.xz * f,
            yz: self.yz * f,
        }
    }

    /// d dᵀ.
    pub fn outer(d: [f64; 3]) -> Sym3 {
        Sym3 {
            xx: d[0] * d[0],
            yy: d[1] * d[1],
            zz: d[2] * d[2],
            xy: d[0] * d[1],
            xz: d[0] * d[2],
            yz: d[1] * d[2],
        }
    }
}

fn positive_sqrt(v: f64) -> Option<f64> {
    (v > 0.0 && v.is_finite()).then(|| v.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: Sym3 = Sym3 {
        xx: 4.0,
        yy: 3.0,
        zz: 2.0,
        xy: 0.5,
        xz: -0.3,
        yz: 0.2,
    };

    #[test]
    fn inverse_times_matrix_is_identity() {
        let m = SAMPLE;
        let (inv, logdet) = m.inverse_logdet().unwrap();
        let (a, b) = (m.to_rows(), inv.to_rows());
        for i in 0..3 {
            for j in 0..3 {
                let v: f64 = (0..3).map(|k| a[3 * i + k] * b[3 * k + j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
            }
        }
        assert!((logdet - m.det().ln()).abs() < 1e-12);
    }

    #[test]
    fn eigen_reconstructs_the_matrix() {
        let m = SAMPLE;
        let (w, v) = m.eigen();
        assert!(w[0] <= w[1] && w[1] <= w[2]);
        let rows = m.to_rows();
        for k in 0..3 {
            for i in 0..3 {
                let mv: f64 = (0..3).map(|j| rows[3 * i + j] * v[k][j]).sum();
                assert!((mv - w[k] * v[k][i]).abs() < 1e-12);
            }
        }
        let (w, _) = Sym3::diag(3.0, 1.0, 2.0).eigen();
        assert_eq!(w, [1.0, 2.0, 3.0]);
    }

    #[test]
    fn cholesky_rejects_indefinite() {
        assert!(Sym3::diag(1.0, -1.0, 1.0).cholesky().is_none());
        assert!(Sym3::diag(1.0, f64::NAN, 1.0).cholesky().is_none());
    }
}
