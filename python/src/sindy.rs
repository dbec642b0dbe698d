//! `stlsq`: PySINDy's sequentially thresholded least squares on the workspace's SINDy engine, the
//! engine of the Python package's `rollest.sindy.STLSQ` optimizer.
//!
//! STLS is the sparse regression of SINDy (Brunton, Proctor & Kutz, PNAS 113(15), 2016); its
//! reference implementation is PySINDy's `STLSQ` (de Silva et al., JOSS 5(49), 2020; Kaptanoglu
//! et al., JOSS 7(69), 2022). The `sindy` crate reproduces PySINDy 2.1.0's iteration, stopping
//! and unbias rules (`StlsConfig::pysindy`, checked against PySINDy's own fits by
//! `tests/tests/sindy.rs`); this function only adapts NumPy arrays to it, one QR-reduced problem
//! per target (column of `y`), as the crate fits them.

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rayon::prelude::*;
use sindy::{DMatrix, QrProblem, SindyError, StlsConfig, StlsFit, stls};

use crate::error::{RollestError, other_error};

/// What `stlsq` returns: the coefficients (n_targets x n_features, physical units), the ridge
/// solves each target took, and whether each target's support settled within `max_iter`.
type Fitted<'py> = (Bound<'py, PyArray2<f64>>, Vec<usize>, Vec<bool>);

/// Fits every column of `y` (n_samples x n_targets) on the library `theta` (n_samples x
/// n_features) with PySINDy's `STLSQ(threshold, alpha, max_iter, normalize_columns=...,
/// unbias=...)`, without the GIL; both arrays C-contiguous float64.
///
/// One factorisation of `[theta | y]` gives every target its QR-reduced problem
/// (`sindy::QrProblem::for_targets`, O(N (p + k)^2)); each target's iterations then run on the
/// p x p factor, the targets in parallel. PySINDy iterates the targets jointly and stops when
/// all have settled, but a target whose support has settled is a fixed point of the iteration
/// (the same ridge problem again), so its coefficients do not depend on when the others settle.
#[pyfunction]
#[pyo3(signature = (theta, y, *, threshold, alpha, max_iter, normalize_columns, unbias))]
#[allow(clippy::too_many_arguments)] // PySINDy's STLSQ parameters, by name, as the Python call reads.
pub fn stlsq<'py>(
    py: Python<'py>,
    theta: PyReadonlyArray2<'py, f64>,
    y: PyReadonlyArray2<'py, f64>,
    threshold: f64,
    alpha: f64,
    max_iter: i64,
    normalize_columns: bool,
    unbias: bool,
) -> PyResult<Fitted<'py>> {
    let max_iter = usize::try_from(max_iter)
        .ok()
        .filter(|&max_iter| max_iter > 0)
        .ok_or_else(|| RollestError::new_err(format!("max_iter must be a positive integer, found {max_iter}")))?;
    let config = StlsConfig::pysindy(threshold, alpha, max_iter, normalize_columns, unbias);
    config.validate().map_err(|error| other_error(&error))?;
    let (n_samples, n_features) = (theta.shape()[0], theta.shape()[1]);
    let (y_rows, n_targets) = (y.shape()[0], y.shape()[1]);
    if y_rows != n_samples {
        return Err(RollestError::new_err(format!(
            "y has {y_rows} rows and theta {n_samples}: expected one row of y per sample (row of theta)"
        )));
    }
    for (count, what) in [(n_samples, "samples (rows)"), (n_features, "library terms (columns of theta)")] {
        if count == 0 {
            return Err(RollestError::new_err(format!("theta has no {what}: expected at least one")));
        }
    }
    if n_targets == 0 {
        return Err(RollestError::new_err("y has no targets (columns): expected at least one"));
    }
    let theta = contiguous(&theta, "theta")?;
    let y = contiguous(&y, "y")?;
    let fits: Vec<StlsFit> = py.detach(|| {
        check_finite(theta, n_features, "theta")?;
        check_finite(y, n_targets, "y")?;
        let library = DMatrix::from_row_slice(n_samples, n_features, theta);
        let columns: Vec<Vec<f64>> =
            (0..n_targets).map(|target| y.iter().skip(target).step_by(n_targets).copied().collect()).collect();
        let targets: Vec<&[f64]> = columns.iter().map(Vec::as_slice).collect();
        QrProblem::for_targets(&library, &targets)
            .and_then(|problems| problems.par_iter().map(|problem| stls(problem, &config)).collect())
            .map_err(|error: SindyError| other_error(&error))
    })?;
    let coefficients = Array2::from_shape_fn((n_targets, n_features), |(target, term)| fits[target].coefficients[term]);
    let iterations = fits.iter().map(|fit| fit.iterations).collect();
    let converged = fits.iter().map(|fit| fit.converged).collect();
    Ok((coefficients.into_pyarray(py), iterations, converged))
}

/// A C-contiguous array's values in row order, or an error naming the argument.
fn contiguous<'a>(array: &'a PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<&'a [f64]> {
    array.as_slice().map_err(|_| RollestError::new_err(format!("{name}: expected a C-contiguous float64 array")))
}

/// An error naming the first NaN or infinity of a row-major matrix by row and column.
fn check_finite(values: &[f64], n_columns: usize, name: &str) -> PyResult<()> {
    match values.iter().position(|value| !value.is_finite()) {
        None => Ok(()),
        Some(at) => Err(RollestError::new_err(format!(
            "{name} has the value {} at row {}, column {}: expected finite values",
            values[at],
            at / n_columns,
            at % n_columns
        ))),
    }
}
