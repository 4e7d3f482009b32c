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
        // Integer slices (our [i64; 3] keys) arrive here as raw bytes: mix 8 at a time.
        let mut chunks = bytes.chunks_exact(8);
        for c in &mut chunks {
            self.write_u64(u64::from_le_bytes(c.try_into().expect("8 bytes")));
        }
        for b in chunks.remainder() {
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

/// A float32 point moved by a row-major 3x4 transform.
#[inline(always)]
fn moved(t: &[f64; 12], p: &[f32]) -> [f64; 3] {
    let p = [p[0], p[1], p[2]].map(f64::from);
    [0, 1, 2].map(|r| t[4 * r] * p[0] + t[4 * r + 1] * p[1] + t[4 * r + 2] * p[2] + t[4 * r + 3])
}

/// Adds a run's summed points to its voxel (the first, empty run has no voxel).
fn flush(sums: &mut [([f64; 3], u32)], (slot, sum, n): (u32, [f64; 3], u32)) {
    if let Some((s, count)) = sums.get_mut(slot as usize) {
        for a in 0..3 {
            s[a] += sum[a];
        }
        *count += n;
    }
}

/// Voxel cells of a growing point set (a submap's point buffer): each occupied voxel keeps the
/// sum and count of its points, so its centroid is exact whatever the order of insertion.
pub struct VoxelBuffer {
    inv: f64,
    slots: HashMap<[i64; 3], u32, BuildHasherDefault<VoxelHasher>>,
    sums: Vec<([f64; 3], u32)>,
    /// Per slot, the last offer that touched it (to count a frame's distinct voxels).
    marks: Vec<u32>,
    offers: u32,
    /// Scratch of one offer: each point's voxel key and slot (≥ len: a new voxel, numbered
    /// in `pending` order), and the new voxels' keys.
    keys: Vec<[i64; 3]>,
    point_slots: Vec<u32>,
    pending: HashMap<[i64; 3], u32, BuildHasherDefault<VoxelHasher>>,
}

impl VoxelBuffer {
    pub fn new(voxel_size: f64) -> Result<VoxelBuffer, CoreError> {
        if !(voxel_size.is_finite() && voxel_size > 0.0) {
            return Err(CoreError::InvalidArgument(format!(
                "voxel_size must be positive and finite, got {voxel_size}"
            )));
        }
        Ok(VoxelBuffer {
            inv: 1.0 / voxel_size,
            slots: HashMap::default(),
            sums: Vec::new(),
            marks: Vec::new(),
            offers: 0,
            keys: Vec::new(),
            point_slots: Vec::new(),
            pending: HashMap::default(),
        })
    }

    /// Occupied voxels.
    pub fn len(&self) -> usize {
        self.sums.len()
    }

    pub fn is_empty(&self) -> bool {
        self.sums.is_empty()
    }

    /// Offers a frame: `points` (row-major N x 3) moved by `transform` (row-major 3x4).
    /// Returns the frame's distinct voxels and how many of them are new; the frame is added only
    /// when new ≥ `min_novelty` · distinct (0 adds every frame). Non-finite points are rejected.
    pub fn offer(
        &mut self,
        points: &[f32],
        transform: &[f64; 12],
        min_novelty: f64,
    ) -> Result<(usize, usize, bool), CoreError> {
        self.offers += 1;
        self.point_slots.clear();
        self.pending.clear();
        let (t, base) = (transform, self.sums.len() as u32);
        let mut distinct = 0;
        // Keys first, in a branch-free loop the compiler vectorises; bad points checked once.
        self.keys.clear();
        let inv = self.inv;
        // False for NaN too, which is the point.
        let in_range = |v: f64| v.abs() < MAX_INDEX;
        let mut finite = true;
        self.keys.extend(points.chunks_exact(3).map(|p| {
            let v = moved(t, p).map(|c| (c * inv).floor());
            finite &= in_range(v[0]) && in_range(v[1]) && in_range(v[2]);
            v.map(|c| c as i64)
        }));
        if !finite {
            let bad = |p: &[f32]| moved(t, p).iter().any(|&c| !in_range((c * inv).floor()));
            let row = points.chunks_exact(3).position(bad).unwrap_or(0);
            return Err(CoreError::NonFinite { row });
        }
        // Neighbouring pixels mostly share a voxel: reuse the previous point's slot.
        let keys = std::mem::take(&mut self.keys);
        let mut slot = 0;
        for (i, key) in keys.iter().enumerate() {
            if i == 0 || keys[i - 1] != *key {
                slot = self.lookup(*key, base, &mut distinct);
            }
            self.point_slots.push(slot);
        }
        self.keys = keys;
        let new = self.pending.len();
        let accept = distinct > 0 && new as f64 >= min_novelty * distinct as f64;
        if accept {
            let mut keys: Vec<([i64; 3], u32)> = self.pending.drain().collect();
            keys.sort_unstable_by_key(|&(_, s)| s);
            for (k, s) in keys {
                self.slots.insert(k, s);
                self.sums.push(([0.0; 3], 0));
                self.marks.push(self.offers);
            }
            // Sum runs of points in one voxel in registers: adding to memory point by point
            // would chain every add through a store and a load of the same address.
            let mut run = (u32::MAX, [0.0; 3], 0);
            for (p, &s) in points.chunks_exact(3).zip(&self.point_slots) {
                if s != run.0 {
                    flush(&mut self.sums, run);
                    run = (s, [0.0; 3], 0);
                }
                let x = moved(t, p);
                run.1 = [run.1[0] + x[0], run.1[1] + x[1], run.1[2] + x[2]];
                run.2 += 1;
            }
            flush(&mut self.sums, run);
        }
        Ok((distinct, new, accept))
    }

    /// The slot of `key`: an existing voxel, or a pending new one numbered from `base`.
    fn lookup(&mut self, key: [i64; 3], base: u32, distinct: &mut usize) -> u32 {
        if let Some(&s) = self.slots.get(&key) {
            if self.marks[s as usize] != self.offers {
                self.marks[s as usize] = self.offers;
                *distinct += 1;
            }
            return s;
        }
        let next = base + self.pending.len() as u32;
        *self.pending.entry(key).or_insert_with(|| {
            *distinct += 1;
            next
        })
    }

    /// Centroid of every occupied voxel, in order of first occupation.
    pub fn centroids(&self) -> Vec<[f64; 3]> {
        self.sums
            .iter()
            .map(|(s, n)| s.map(|v| v / *n as f64))
            .collect()
    }
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
    fn buffer_lands_one_point_seen_from_two_poses_in_one_voxel() {
        let mut b = VoxelBuffer::new(0.05).unwrap();
        // The world point (1.025, 2.025, 0.525), a voxel centre: seen from the identity and from a
        // pose shifted by (0.3, 0, 0) and turned 90° about z, where it is (2.025, -0.725, 0.525).
        let id = [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.];
        let turned = [0., -1., 0., 0.3, 1., 0., 0., 0., 0., 0., 1., 0.];
        assert_eq!(
            b.offer(&[1.025, 2.025, 0.525], &id, 0.0).unwrap(),
            (1, 1, true)
        );
        assert_eq!(
            b.offer(&[2.025, -0.725, 0.525], &turned, 0.5).unwrap(),
            (1, 0, false)
        );
        assert_eq!(
            b.offer(&[2.025, -0.725, 0.525], &turned, 0.0).unwrap(),
            (1, 0, true)
        );
        assert_eq!(b.len(), 1);
        let c = b.centroids()[0];
        assert!((c[0] - 1.025).abs() < 1e-6 && (c[1] - 2.025).abs() < 1e-6);
        assert!(b.offer(&[f32::NAN, 0.0, 0.0], &id, 0.0).is_err());
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
