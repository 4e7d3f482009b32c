//! gmmap-core: the arithmetic of gmmap that scales with points or components.
//!
//! Nothing here knows about files, networks, robots or Python; the `gmmap-py` crate binds it.
//! Points are `[f64; 3]`; covariances are symmetric 3x3 matrices stored as [`Sym3`].

pub mod em;
mod error;
mod fastmath;
pub mod gmm;
mod init;
pub mod linalg;
pub mod place;
pub mod raycast;
pub mod register;
pub mod rng;
pub mod search;
pub mod select;
pub mod voxel;

pub use em::{fit, refine, CovType, EmOptions, EmResult, InitMethod};
pub use error::CoreError;
pub use gmm::Gmm;
pub use linalg::Sym3;
pub use voxel::{voxel_filter, VoxelBuffer};

/// Rejects NaN or infinite coordinates, naming the first offending row.
pub fn check_finite(points: &[[f64; 3]]) -> Result<(), CoreError> {
    match points.iter().position(|p| !p.iter().all(|v| v.is_finite())) {
        Some(row) => Err(CoreError::NonFinite { row }),
        None => Ok(()),
    }
}
