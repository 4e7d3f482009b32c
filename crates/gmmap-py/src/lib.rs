//! PyO3 bindings of gmmap-core: numpy in, numpy out, the GIL released during the arithmetic.
//! Argument checking with friendly messages lives in the Python layer; errors that reach this
//! far become `ValueError`.

use gmmap_core::place::{pair_histogram as pair_histogram_core, PairHistogram};
use gmmap_core::raycast::{Pinhole, Scene, Shape};
use gmmap_core::register::{register, Pose, RegisterOptions};
use gmmap_core::select::{select, SelectOptions};
use gmmap_core::{CoreError, CovType, EmOptions, Gmm, InitMethod, Sym3};
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

/// Runs `f` without the GIL on a rayon worker thread: the core's many short parallel loops
/// (k-means++ runs two per centre) then start inside the pool instead of each waking it from
/// outside, which costs tens of microseconds a time.
fn in_pool<T: Send>(py: Python<'_>, f: impl FnOnce() -> T + Send) -> T {
    py.detach(|| rayon::scope(|_| f()))
}

fn value_error(e: CoreError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn points_of(a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<[f64; 3]>> {
    if a.shape()[1] != 3 {
        return Err(PyValueError::new_err("points must have shape (N, 3)"));
    }
    let flat = a.as_slice()?;
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

fn to_array2<'py>(py: Python<'py>, rows: &[[f64; 3]]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([rows.len(), 3])
}

fn gmm_of(
    weights: PyReadonlyArray1<'_, f64>,
    means: PyReadonlyArray2<'_, f64>,
    covariances: PyReadonlyArray3<'_, f64>,
) -> PyResult<Gmm> {
    let covs = covariances.as_slice()?;
    Ok(Gmm {
        weights: weights.as_slice()?.to_vec(),
        means: points_of(&means)?,
        covariances: covs.chunks_exact(9).map(Sym3::from_rows).collect(),
    })
}

type GmmArrays<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray3<f64>>,
);

fn gmm_to_arrays<'py>(py: Python<'py>, g: &Gmm) -> PyResult<GmmArrays<'py>> {
    let covs: Vec<f64> = g.covariances.iter().flat_map(|c| c.to_rows()).collect();
    Ok((
        PyArray1::from_vec(py, g.weights.clone()),
        to_array2(py, &g.means)?,
        PyArray1::from_vec(py, covs).reshape([g.len(), 3, 3])?,
    ))
}

type FitOutput<'py> = (GmmArrays<'py>, usize, bool, f64);

fn fit_output<'py>(py: Python<'py>, fit: &gmmap_core::EmResult) -> PyResult<FitOutput<'py>> {
    Ok((
        gmm_to_arrays(py, &fit.gmm)?,
        fit.n_iter,
        fit.converged,
        fit.log_likelihood,
    ))
}

/// EM fit. Returns (weights, means, covariances, n_iter, converged, mean log-likelihood).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (points, n_components, full, max_iter, tol, seed, init, reg_covar, truncation))]
fn fit_em<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    n_components: usize,
    full: bool,
    max_iter: usize,
    tol: f64,
    seed: u64,
    init: &str,
    reg_covar: f64,
    truncation: f64,
) -> PyResult<FitOutput<'py>> {
    let init = match init {
        "kmeans++" => InitMethod::KMeansPlusPlus,
        "random" => InitMethod::Random,
        other => return Err(PyValueError::new_err(format!("unknown init {other:?}"))),
    };
    let opts = EmOptions {
        n_components,
        covariance: if full { CovType::Full } else { CovType::Diag },
        max_iter,
        tol,
        seed,
        init,
        reg_covar,
        truncation,
    };
    let pts = points_of(&points)?;
    let fit = in_pool(py, || gmmap_core::fit(&pts, &opts)).map_err(value_error)?;
    fit_output(py, &fit)
}

/// EM continued from a given mixture: (weights, means, covariances, n_iter, converged, ll).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn refine_em<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    weights: PyReadonlyArray1<'py, f64>,
    means: PyReadonlyArray2<'py, f64>,
    covariances: PyReadonlyArray3<'py, f64>,
    full: bool,
    max_iter: usize,
    tol: f64,
    reg_covar: f64,
    truncation: f64,
) -> PyResult<FitOutput<'py>> {
    let start = gmm_of(weights, means, covariances)?;
    let opts = EmOptions {
        n_components: start.len(),
        covariance: if full { CovType::Full } else { CovType::Diag },
        max_iter,
        tol,
        reg_covar,
        truncation,
        ..Default::default()
    };
    let pts = points_of(&points)?;
    let fit = in_pool(py, || gmmap_core::refine(&pts, &start, &opts)).map_err(value_error)?;
    fit_output(py, &fit)
}

/// log p(x) of every point under the mixture.
#[pyfunction]
fn log_pdf<'py>(
    py: Python<'py>,
    weights: PyReadonlyArray1<'py, f64>,
    means: PyReadonlyArray2<'py, f64>,
    covariances: PyReadonlyArray3<'py, f64>,
    points: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let (g, pts) = (gmm_of(weights, means, covariances)?, points_of(&points)?);
    let out = in_pool(py, || g.log_pdf(&pts)).map_err(value_error)?;
    Ok(PyArray1::from_vec(py, out))
}

/// ∇p(x) of every point.
#[pyfunction]
fn gradient<'py>(
    py: Python<'py>,
    weights: PyReadonlyArray1<'py, f64>,
    means: PyReadonlyArray2<'py, f64>,
    covariances: PyReadonlyArray3<'py, f64>,
    points: PyReadonlyArray2<'py, f64>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let (g, pts) = (gmm_of(weights, means, covariances)?, points_of(&points)?);
    let out = in_pool(py, || g.gradient(&pts)).map_err(value_error)?;
    to_array2(py, &out)
}

/// Centroid of each occupied voxel, in order of first occurrence.
#[pyfunction]
fn voxel_filter<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    voxel_size: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let pts = points_of(&points)?;
    let out = in_pool(py, || gmmap_core::voxel_filter(&pts, voxel_size)).map_err(value_error)?;
    to_array2(py, &out)
}

/// Pair histogram of the place descriptor (see gmmap_core::place), flat, distance-major.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn pair_histogram<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<'py, f64>,
    pairs: usize,
    distance_bins: usize,
    max_distance: f64,
    height_bins: usize,
    max_height: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let pts = points_of(&points)?;
    let o = PairHistogram {
        pairs,
        distance_bins,
        max_distance,
        height_bins,
        max_height,
        seed,
    };
    let h = in_pool(py, || pair_histogram_core(&pts, &o)).map_err(value_error)?;
    Ok(PyArray1::from_vec(py, h))
}

/// Model selection: (weights, means, covariances, labels).
#[pyfunction]
fn select_components<'py>(
    py: Python<'py>,
    weights: PyReadonlyArray1<'py, f64>,
    means: PyReadonlyArray2<'py, f64>,
    covariances: PyReadonlyArray3<'py, f64>,
    flat_ratio: f64,
    max_distance: f64,
    kl_threshold: f64,
) -> PyResult<(GmmArrays<'py>, Bound<'py, PyArray1<usize>>)> {
    let g = gmm_of(weights, means, covariances)?;
    let opts = SelectOptions {
        flat_ratio,
        max_distance,
        kl_threshold,
    };
    let s = in_pool(py, || select(&g, &opts)).map_err(value_error)?;
    Ok((gmm_to_arrays(py, &s.gmm)?, PyArray1::from_vec(py, s.labels)))
}

/// ∫ f g dx of two mixtures.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn l2_inner<'py>(
    py: Python<'py>,
    w1: PyReadonlyArray1<'py, f64>,
    m1: PyReadonlyArray2<'py, f64>,
    c1: PyReadonlyArray3<'py, f64>,
    w2: PyReadonlyArray1<'py, f64>,
    m2: PyReadonlyArray2<'py, f64>,
    c2: PyReadonlyArray3<'py, f64>,
) -> PyResult<f64> {
    let (f, g) = (gmm_of(w1, m1, c1)?, gmm_of(w2, m2, c2)?);
    in_pool(py, || f.l2_inner(&g)).map_err(value_error)
}

/// Components sharing a `cell`-sized voxel merged by moment matching.
#[pyfunction]
fn coarsen_gmm<'py>(
    py: Python<'py>,
    weights: PyReadonlyArray1<'py, f64>,
    means: PyReadonlyArray2<'py, f64>,
    covariances: PyReadonlyArray3<'py, f64>,
    cell: f64,
) -> PyResult<GmmArrays<'py>> {
    let g = gmm_of(weights, means, covariances)?;
    gmm_to_arrays(py, &g.coarsened(cell).map_err(value_error)?)
}

type RegisterOutput<'py> = (
    Bound<'py, PyArray2<f64>>,
    f64,
    Bound<'py, PyArray2<f64>>,
    usize,
    f64,
    Vec<(Bound<'py, PyArray2<f64>>, f64)>,
);

/// GMM-to-GMM registration: (transform 4x4, confidence, information 6x6, iterations,
/// the best distinct solution's confidence, every distinct solution as (4x4, confidence)).
#[pyfunction]
#[allow(clippy::too_many_arguments)]
#[pyo3(signature = (source, target, init, yaw_hint, scales, max_iter, four_dof, yaw_starts, search_cell, search_starts, refine_starts, information_scale, confidence_scale, tol, cutoff, coarse_cell, coarse_scale))]
fn register_gmm<'py>(
    py: Python<'py>,
    source: (
        PyReadonlyArray1<'py, f64>,
        PyReadonlyArray2<'py, f64>,
        PyReadonlyArray3<'py, f64>,
    ),
    target: (
        PyReadonlyArray1<'py, f64>,
        PyReadonlyArray2<'py, f64>,
        PyReadonlyArray3<'py, f64>,
    ),
    init: Option<PyReadonlyArray2<'py, f64>>,
    yaw_hint: Option<f64>,
    scales: Vec<f64>,
    max_iter: usize,
    four_dof: bool,
    yaw_starts: usize,
    search_cell: f64,
    search_starts: usize,
    refine_starts: usize,
    information_scale: f64,
    confidence_scale: f64,
    tol: f64,
    cutoff: f64,
    coarse_cell: f64,
    coarse_scale: f64,
) -> PyResult<RegisterOutput<'py>> {
    let (f, g) = (
        gmm_of(source.0, source.1, source.2)?,
        gmm_of(target.0, target.1, target.2)?,
    );
    let init = init
        .map(|m| pose_of(&m).map(|m| Pose::from_matrix(&m)))
        .transpose()?;
    let opts = RegisterOptions {
        scales,
        max_iter,
        four_dof,
        yaw_starts,
        search_cell,
        search_starts,
        refine_starts,
        information_scale,
        confidence_scale,
        tol,
        cutoff,
        coarse_cell,
        coarse_scale,
    };
    let r = in_pool(py, || register(&f, &g, init, yaw_hint, &opts)).map_err(value_error)?;
    let t = PyArray1::from_vec(py, r.transform.to_matrix().to_vec()).reshape([4, 4])?;
    let info = PyArray1::from_vec(py, r.information.iter().flatten().copied().collect())
        .reshape([6, 6])?;
    let basins = r
        .basins
        .iter()
        .map(|(p, c)| {
            Ok((
                PyArray1::from_vec(py, p.to_matrix().to_vec()).reshape([4, 4])?,
                *c,
            ))
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((t, r.confidence, info, r.iterations, r.alternative, basins))
}

/// A submap's point buffer: voxel cells with exact centroids (see gmmap-core).
#[pyclass(module = "gmmap._core")]
struct VoxelBuffer {
    inner: gmmap_core::VoxelBuffer,
}

#[pymethods]
impl VoxelBuffer {
    #[new]
    fn new(voxel_size: f64) -> PyResult<Self> {
        Ok(VoxelBuffer {
            inner: gmmap_core::VoxelBuffer::new(voxel_size).map_err(value_error)?,
        })
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// Offers float32 (N, 3) points moved by the 4x4 `transform`: (distinct, new, accepted).
    fn offer(
        &mut self,
        py: Python<'_>,
        points: PyReadonlyArray2<'_, f32>,
        transform: PyReadonlyArray2<'_, f64>,
        min_novelty: f64,
    ) -> PyResult<(usize, usize, bool)> {
        if points.shape()[1] != 3 {
            return Err(PyValueError::new_err("points must have shape (N, 3)"));
        }
        let t = pose_of(&transform)?;
        let t: [f64; 12] = t[..12].try_into().expect("12 of 16");
        let pts = points.as_slice()?;
        let inner = &mut self.inner;
        in_pool(py, || inner.offer(pts, &t, min_novelty)).map_err(value_error)
    }

    fn centroids<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        to_array2(py, &self.inner.centroids())
    }
}

fn pose_of(pose: &PyReadonlyArray2<'_, f64>) -> PyResult<[f64; 16]> {
    let flat = pose.as_slice()?;
    <[f64; 16]>::try_from(flat).map_err(|_| PyValueError::new_err("pose must be a 4x4 matrix"))
}

/// A world of primitives prepared for ray casting (a BVH over yawed boxes and cylinders).
#[pyclass(frozen, module = "gmmap._core")]
struct RayScene {
    scene: Scene,
}

#[pymethods]
impl RayScene {
    /// boxes: (M, 7) rows cx cy cz hx hy hz yaw; cylinders: (C, 5) rows x y radius z_min z_max.
    #[new]
    fn new(
        boxes: PyReadonlyArray2<'_, f64>,
        cylinders: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Self> {
        let (b, c) = (boxes.as_slice()?, cylinders.as_slice()?);
        if boxes.shape()[1] != 7 || cylinders.shape()[1] != 5 {
            return Err(PyValueError::new_err(
                "boxes must be (M, 7) and cylinders (C, 5)",
            ));
        }
        let mut shapes: Vec<Shape> = b
            .chunks_exact(7)
            .map(|r| Shape::Box {
                centre: [r[0], r[1], r[2]],
                half: [r[3], r[4], r[5]],
                yaw: r[6],
            })
            .collect();
        shapes.extend(c.chunks_exact(5).map(|r| Shape::Cylinder {
            x: r[0],
            y: r[1],
            radius: r[2],
            z_min: r[3],
            z_max: r[4],
        }));
        Ok(RayScene {
            scene: Scene::new(shapes),
        })
    }

    fn __len__(&self) -> usize {
        self.scene.len()
    }

    /// (height, width) float32 z-depth image; 0 where nothing is hit within max_depth.
    #[allow(clippy::too_many_arguments)]
    fn depth_image<'py>(
        &self,
        py: Python<'py>,
        pose: PyReadonlyArray2<'py, f64>,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: usize,
        height: usize,
        max_depth: f64,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let pose = pose_of(&pose)?;
        let cam = Pinhole {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        };
        let img = in_pool(py, || self.scene.depth_image(&pose, &cam, max_depth));
        PyArray1::from_vec(py, img).reshape([height, width])
    }

    /// Range along each sensor-frame unit direction (NaN where nothing is hit).
    fn ranges<'py>(
        &self,
        py: Python<'py>,
        pose: PyReadonlyArray2<'py, f64>,
        dirs: PyReadonlyArray2<'py, f64>,
        max_range: f64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (pose, dirs) = (pose_of(&pose)?, points_of(&dirs)?);
        let out = in_pool(py, || self.scene.ranges(&pose, &dirs, max_range));
        Ok(PyArray1::from_vec(py, out))
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fit_em, m)?)?;
    m.add_function(wrap_pyfunction!(refine_em, m)?)?;
    m.add_function(wrap_pyfunction!(log_pdf, m)?)?;
    m.add_function(wrap_pyfunction!(gradient, m)?)?;
    m.add_function(wrap_pyfunction!(voxel_filter, m)?)?;
    m.add_class::<RayScene>()?;
    m.add_class::<VoxelBuffer>()?;
    m.add_function(wrap_pyfunction!(select_components, m)?)?;
    m.add_function(wrap_pyfunction!(l2_inner, m)?)?;
    m.add_function(wrap_pyfunction!(register_gmm, m)?)?;
    m.add_function(wrap_pyfunction!(coarsen_gmm, m)?)?;
    m.add_function(wrap_pyfunction!(pair_histogram, m)?)?;
    Ok(())
}
