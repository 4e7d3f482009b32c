//! Hash-grid voxel filter: one point per occupied voxel, the centroid of the points inside.

use crate::{check_finite, CoreError};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// FxHash-style mixing: integer voxel keys need speed, not DoS resistance.
#[derive(Default)]
struct VoxelHasher(u64);

impl Hasher for VoxelHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(*b as u64);
        }
    }
    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

/// Voxel indices beyond this would overflow `i64` arithmetic downstream; reject instead.
const MAX_INDEX: f64 = (1u64 << 62) as f64;

/// Centroids of the occupied voxels of edge `voxel_size`, in order of first occurrence.
pub fn voxel_filter(points: &[[f64; 3]], voxel_size: f64) -> Result<Vec<[f64; 3]>, CoreError> {
    if !(voxel_size.is_finite() && voxel_size > 0.0) {
        return Err(CoreError::InvalidArgument(format!(
            "voxel_size must be positive and finite, got {voxel_size}"
        )));
    }
    check_finite(points)?;
    let inv = 1.0 / voxel_size;
    let mut slots: HashMap<[i64; 3], usize, BuildHasherDefault<VoxelHasher>> =
        HashMap::with_capacity_and_hasher(points.len() / 4, Default::default());
    let mut sums: Vec<([f64; 3], u32)> = Vec::new();
    for p in points {
        let mut key = [0i64; 3];
        for a in 0..3 {
            let v = (p[a] * inv).floor();
            if v.abs() > MAX_INDEX {
                return Err(CoreError::InvalidArgument(format!(
                    "coordinate {} is too large for voxel size {voxel_size}",
                    p[a]
                )));
            }
            key[a] = v as i64;
        }
        let slot = *slots.entry(key).or_insert_with(|| {
            sums.push(([0.0; 3], 0));
            sums.len() - 1
        });
        let (s, n) = &mut sums[slot];
        for a in 0..3 {
            s[a] += p[a];
        }
        *n += 1;
    }
    Ok(sums
        .into_iter()
        .map(|(s, n)| s.map(|v| v / n as f64))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_centroid_per_voxel_in_first_seen_order() {
        let pts = [
            [0.01, 0.01, 0.01],
            [0.5, 0.5, 0.5],
            [0.03, 0.05, 0.07],
            [-0.01, 0.0, 0.0],
        ];
        let out = voxel_filter(&pts, 0.1).unwrap();
        assert_eq!(out.len(), 3);
        assert!((out[0][0] - 0.02).abs() < 1e-12 && (out[0][2] - 0.04).abs() < 1e-12);
        assert_eq!(out[1], [0.5, 0.5, 0.5]);
        assert_eq!(out[2], [-0.01, 0.0, 0.0]);
    }

    #[test]
    fn rejects_bad_input() {
        assert!(voxel_filter(&[[0.0; 3]], 0.0).is_err());
        assert!(voxel_filter(&[[0.0; 3]], f64::NAN).is_err());
        assert_eq!(
            voxel_filter(&[[0.0, f64::NAN, 0.0]], 0.1),
            Err(CoreError::NonFinite { row: 0 })
        );
        assert!(voxel_filter(&[[1e300, 0.0, 0.0]], 1e-3).is_err());
        assert!(voxel_filter(&[], 0.1).unwrap().is_empty());
    }
}
