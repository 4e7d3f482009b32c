//! PyO3 bindings of gmmap-core: numpy in, numpy out, the GIL released during the arithmetic.
//! Argument checking with friendly messages lives in the Python layer; errors that reach this
//! far become `ValueError`.

use gmmap_core::{CoreError, CovType, EmOptions, Gmm, InitMethod, Sym3};
use numpy::{
    PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2,
    PyReadonlyArray3, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

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
) -> PyResult<(GmmArrays<'py>, usize, bool, f64)> {
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
    let fit = py
        .detach(|| gmmap_core::fit(&pts, &opts))
        .map_err(value_error)?;
    Ok((
        gmm_to_arrays(py, &fit.gmm)?,
        fit.n_iter,
        fit.converged,
        fit.log_likelihood,
    ))
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
    let out = py.detach(|| g.log_pdf(&pts)).map_err(value_error)?;
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
    let out = py.detach(|| g.gradient(&pts)).map_err(value_error)?;
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
    let out = py
        .detach(|| gmmap_core::voxel_filter(&pts, voxel_size))
        .map_err(value_error)?;
    to_array2(py, &out)
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fit_em, m)?)?;
    m.add_function(wrap_pyfunction!(log_pdf, m)?)?;
    m.add_function(wrap_pyfunction!(gradient, m)?)?;
    m.add_function(wrap_pyfunction!(voxel_filter, m)?)?;
    Ok(())
}
