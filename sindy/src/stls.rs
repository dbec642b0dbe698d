//! Sequentially thresholded least squares (STLS; Brunton, Proctor & Kutz, PNAS 113(15), 2016,
//! with the ridge variant STRidge of Rudy et al., Sci. Adv. 3, 2017) with the exact iteration,
//! stopping and unbias semantics of PySINDy 2.1.0's `STLSQ` (`pysindy/optimizers/stlsq.py`
//! `_reduce`, `pysindy/optimizers/base.py` `fit`), for one target.
//!
//! The same algorithm runs on the QR-reduced problem ([`stls`], O(p^3) per iteration) and on
//! the full N x p library ([`stls_dense`], O(N p^2) per iteration, as PySINDy does).

use nalgebra::{DMatrix, DVector};

use super::error::SindyError;
use super::linalg::solve_columns;
use super::qr::{Normalisation, QrProblem, check_dense, column_scales, ridge_weight};

/// PySINDy's cut below which a normalised coefficient is left out of the unbiased refit
/// (`base.py` `fit`: `self.ind_ = np.abs(self.coef_) > 1e-14`).
const UNBIAS_SUPPORT_CUT: f64 = 1e-14;

/// The settings of one STLS fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StlsConfig {
    /// Coefficients of the normalised columns with `|c| < threshold` are set to zero.
    pub threshold: f64,
    /// Ridge weight of the thresholding iterations (`|y - Xw|^2 + alpha |w|^2` on the
    /// normalised columns; see [`Normalisation::Rms`] for its scaling with N).
    pub alpha: f64,
    /// The maximum number of ridge solves (PySINDy's `max_iter`).
    pub max_iter: usize,
    /// Refit the final support by ordinary least squares (no ridge).
    pub unbias: bool,
    /// Column scaling before thresholding.
    pub normalisation: Normalisation,
}

impl Default for StlsConfig {
    /// PySINDy's `threshold=0.1, max_iter=20, unbias=True` with RMS column normalisation and
    /// `alpha = 1e-5`. With RMS columns the ridge weight is relative to the unit-diagonal Gram
    /// matrix `X^T X / N`, so PySINDy's default `alpha = 0.05` would shrink every coefficient
    /// by about 5 % and leak weight into correlated spurious terms; 1e-5 only damps
    /// near-collinear directions.
    fn default() -> Self {
        Self { threshold: 0.1, alpha: 1e-5, max_iter: 20, unbias: true, normalisation: Normalisation::Rms }
    }
}

impl StlsConfig {
    /// The configuration that reproduces `pysindy.STLSQ(threshold, alpha, max_iter,
    /// normalize_columns, unbias=unbias)`.
    #[must_use]
    pub fn pysindy(threshold: f64, alpha: f64, max_iter: usize, normalize_columns: bool, unbias: bool) -> Self {
        let normalisation = if normalize_columns { Normalisation::L2 } else { Normalisation::None };
        Self { threshold, alpha, max_iter, unbias, normalisation }
    }

    /// Rejects a negative or non-finite threshold or alpha and `max_iter == 0`, as PySINDy does.
    pub fn validate(&self) -> Result<(), SindyError> {
        if !(self.threshold.is_finite() && self.threshold >= 0.0) {
            return Err(SindyError::InvalidConfig("threshold must be finite and non-negative"));
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return Err(SindyError::InvalidConfig("alpha must be finite and non-negative"));
        }
        if self.max_iter == 0 {
            return Err(SindyError::InvalidConfig("max_iter must be positive"));
        }
        Ok(())
    }
}

/// The result of one STLS fit.
#[derive(Debug, Clone, PartialEq)]
pub struct StlsFit {
    /// Coefficients in physical units (one per library term; zero outside the support).
    pub coefficients: Vec<f64>,
    /// Coefficients of the normalised columns (what the threshold acted on).
    pub normalised: Vec<f64>,
    /// Which terms have a non-zero coefficient.
    pub support: Vec<bool>,
    /// The number of ridge solves done.
    pub iterations: usize,
    /// False when `max_iter` was reached with a still-changing support (PySINDy's
    /// `ConvergenceWarning`).
    pub converged: bool,
}

impl StlsFit {
    /// The number of non-zero terms.
    #[must_use]
    pub fn n_terms(&self) -> usize {
        self.support.iter().filter(|&&kept| kept).count()
    }

    /// The indices of the non-zero terms.
    #[must_use]
    pub fn support_indices(&self) -> Vec<usize> {
        indices(&self.support)
    }
}

/// A least-squares system in normalised coordinates: `min |b - a w|`, with `w = scale * coef`.
/// For the QR path `a = R D^-1`, `b = Q^T y`; for the dense path `a = Theta D^-1`, `b = y`.
#[derive(Debug, Clone)]
pub(crate) struct System {
    /// The normalised matrix.
    a: DMatrix<f64>,
    /// The right-hand side.
    b: DVector<f64>,
    /// The column scales D.
    scales: Vec<f64>,
    /// The ridge weight in normalised coordinates.
    ridge: f64,
}

impl System {
    /// The normalised system of a QR problem.
    pub(crate) fn from_qr(problem: &QrProblem, normalisation: Normalisation, alpha: f64) -> Self {
        let scales = problem.scales(normalisation);
        Self {
            a: scaled_columns(problem.r(), &scales),
            b: problem.qty().clone(),
            ridge: problem.ridge_weight(alpha, normalisation),
            scales,
        }
    }

    /// The normalised least-squares coefficients of the full library (PySINDy's initial
    /// guess, `np.linalg.lstsq(x_normed, y)` in `base.py` `fit`).
    pub(crate) fn least_squares(&self) -> Result<Vec<f64>, SindyError> {
        let all: Vec<usize> = (0..self.scales.len()).collect();
        solve_columns(&self.a, &self.b, &all, 0.0)
    }
}

/// STLS on the QR-reduced problem: every iteration costs O(p^3), independent of N.
pub fn stls(problem: &QrProblem, config: &StlsConfig) -> Result<StlsFit, SindyError> {
    config.validate()?;
    let system = System::from_qr(problem, config.normalisation, config.alpha);
    run(&system, config)
}

/// The same algorithm on the full N x p library (each iteration O(N p^2)); a cross-check of
/// [`stls`] and the baseline of the benchmark.
pub fn stls_dense(theta: &DMatrix<f64>, y: &[f64], config: &StlsConfig) -> Result<StlsFit, SindyError> {
    config.validate()?;
    check_dense(theta, y)?;
    let norms: Vec<f64> = theta.column_iter().map(|column| column.norm()).collect();
    let scales = column_scales(&norms, theta.nrows(), config.normalisation);
    let ridge = ridge_weight(config.alpha, theta.nrows(), config.normalisation);
    let system = System { a: scaled_columns(theta, &scales), b: DVector::from_column_slice(y), scales, ridge };
    run(&system, config)
}

/// The STLS iterations of PySINDy's `STLSQ._reduce` followed by `BaseOptimizer.fit`'s unbias
/// step and rescaling, on a normalised system.
pub(crate) fn run(system: &System, config: &StlsConfig) -> Result<StlsFit, SindyError> {
    let n_features = system.scales.len();
    // `history_[0]` is the least-squares initial guess; only its non-zero pattern matters, for
    // the `_no_change` test of the first iteration.
    let mut previous_pattern: Vec<bool> = system.least_squares()?.iter().map(|&c| c != 0.0).collect();
    let mut support = vec![true; n_features];
    let mut coef = vec![0.0; n_features];
    let mut iterations = 0;
    let mut converged = false;
    while iterations < config.max_iter {
        if !support.contains(&true) {
            // "Sparsity parameter is too big": PySINDy stops with all coefficients zero.
            coef = vec![0.0; n_features];
            converged = true;
            break;
        }
        let active = indices(&support);
        let ridge_coef = solve_columns(&system.a, &system.b, &active, system.ridge)?;
        iterations += 1;
        (coef, support) = threshold_coefficients(n_features, &active, &ridge_coef, config.threshold);
        // `_reduce` stops when no term was removed from the full library
        // (`np.sum(ind) == n_features_selected`) or when the non-zero pattern is unchanged
        // (`_no_change`, which compares `bool(c)` of the last two history entries).
        let pattern: Vec<bool> = coef.iter().map(|&c| c != 0.0).collect();
        let all_kept = !support.contains(&false);
        let unchanged = pattern == previous_pattern;
        previous_pattern = pattern;
        if all_kept || unchanged {
            converged = true;
            break;
        }
    }
    finish(system, config, coef, iterations, converged)
}

/// `_sparse_coefficients`: scatters the ridge coefficients of the active columns into a
/// full vector and keeps `|c| >= threshold` over all features (an inactive feature has
/// `c = 0`, so it comes back only when the threshold is 0, exactly as in PySINDy).
fn threshold_coefficients(
    n_features: usize,
    active: &[usize],
    values: &[f64],
    threshold: f64,
) -> (Vec<f64>, Vec<bool>) {
    let mut coef = vec![0.0; n_features];
    for (&col, &value) in active.iter().zip(values) {
        coef[col] = value;
    }
    let support: Vec<bool> = coef.iter().map(|c| c.abs() >= threshold).collect();
    for (value, &kept) in coef.iter_mut().zip(&support) {
        if !kept {
            *value = 0.0;
        }
    }
    (coef, support)
}

/// `base.py` `fit` after `_reduce`: the unbias support is `|c| > 1e-14`, refitted by ordinary
/// least squares (`LinearRegression(fit_intercept=False)`, minimum norm) on the normalised
/// columns, and the coefficients are divided by the column scales.
fn finish(
    system: &System,
    config: &StlsConfig,
    mut coef: Vec<f64>,
    iterations: usize,
    converged: bool,
) -> Result<StlsFit, SindyError> {
    let unbias_support: Vec<bool> = coef.iter().map(|c| c.abs() > UNBIAS_SUPPORT_CUT).collect();
    if config.unbias {
        let active = indices(&unbias_support);
        let refit = solve_columns(&system.a, &system.b, &active, 0.0)?;
        coef = vec![0.0; coef.len()];
        for (&col, &value) in active.iter().zip(&refit) {
            coef[col] = value;
        }
    }
    let coefficients: Vec<f64> = coef.iter().zip(&system.scales).map(|(c, scale)| c / scale).collect();
    let support = coefficients.iter().map(|&c| c != 0.0).collect();
    Ok(StlsFit { coefficients, normalised: coef, support, iterations, converged })
}

/// `matrix * diag(1 / scales)`.
fn scaled_columns(matrix: &DMatrix<f64>, scales: &[f64]) -> DMatrix<f64> {
    let mut scaled = matrix.clone();
    for (mut column, &scale) in scaled.column_iter_mut().zip(scales) {
        column /= scale;
    }
    scaled
}

/// The indices of the true entries.
fn indices(mask: &[bool]) -> Vec<usize> {
    mask.iter().enumerate().filter(|&(_, &kept)| kept).map(|(idx, _)| idx).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::library::Library;
    use crate::testdata::static_regression;

    fn problem(n: usize, noise: f64) -> (DMatrix<f64>, Vec<f64>) {
        let (samples, y) = static_regression(n, noise, 7);
        let library = Library::polynomial(&["x0", "x1"], 2, true).unwrap();
        (library.theta(&samples).unwrap(), y)
    }

    fn max_relative_difference(ours: &[f64], reference: &[f64]) -> f64 {
        let scale = reference.iter().fold(0.0f64, |acc, c| acc.max(c.abs()));
        ours.iter().zip(reference).fold(0.0f64, |acc, (a, b)| acc.max((a - b).abs())) / scale
    }

    #[test]
    fn qr_path_equals_the_dense_path() {
        let (theta, y) = problem(3000, 0.3);
        let qr = QrProblem::new(&theta, &y).unwrap();
        for normalisation in [Normalisation::None, Normalisation::Rms, Normalisation::L2] {
            for (threshold, alpha, max_iter, unbias) in
                [(0.05, 0.05, 20, true), (0.02, 1e-3, 1, false), (0.5, 0.0, 3, true)]
            {
                let threshold = if normalisation == Normalisation::L2 { threshold * 3000f64.sqrt() } else { threshold };
                let config = StlsConfig { threshold, alpha, max_iter, unbias, normalisation };
                let ours = stls(&qr, &config).unwrap();
                let dense = stls_dense(&theta, &y, &config).unwrap();
                assert_eq!(ours.support, dense.support, "{config:?}");
                assert_eq!(ours.iterations, dense.iterations);
                let difference = max_relative_difference(&ours.coefficients, &dense.coefficients);
                assert!(difference < 1e-10, "{config:?}: {difference:e}");
            }
        }
    }

    #[test]
    fn rank_deficient_libraries_do_not_panic() {
        let (theta, y) = problem(200, 0.01);
        // A repeated column and an all-zero column (a gate that never opens).
        let mut columns: Vec<_> = theta.column_iter().map(|column| column.into_owned()).collect();
        columns.push(theta.column(1).into_owned());
        columns.push(theta.column(0) * 0.0);
        let deficient = DMatrix::from_columns(&columns);
        let qr = QrProblem::new(&deficient, &y).unwrap();
        for normalisation in [Normalisation::None, Normalisation::Rms, Normalisation::L2] {
            for alpha in [0.0, 0.05] {
                let config = StlsConfig { threshold: 1e-3, alpha, normalisation, ..StlsConfig::default() };
                for fit in [stls(&qr, &config).unwrap(), stls_dense(&deficient, &y, &config).unwrap()] {
                    assert!(fit.coefficients.iter().all(|c| c.is_finite()), "{config:?}");
                    assert_eq!(fit.coefficients[7], 0.0, "the zero column stays out");
                    // The duplicated x0 column shares the weight 2 of x0.
                    assert!((fit.coefficients[1] + fit.coefficients[6] - 2.0).abs() < 0.01, "{fit:?}");
                }
            }
        }
    }

    #[test]
    fn rms_normalisation_makes_the_support_independent_of_the_data_length() {
        // The x1^2 term contributes 0.05 * rms(x1^2) = 0.022 to the target at any N.
        let (short, y_short) = problem(1000, 1e-3);
        let (long, y_long) = problem(4000, 1e-3);
        let short_qr = QrProblem::new(&short, &y_short).unwrap();
        let long_qr = QrProblem::new(&long, &y_long).unwrap();
        let rms = StlsConfig { threshold: 0.01, ..StlsConfig::default() };
        let short_fit = stls(&short_qr, &rms).unwrap();
        let long_fit = stls(&long_qr, &rms).unwrap();
        assert_eq!(short_fit.support, long_fit.support);
        assert_eq!(short_fit.support_indices(), [0, 1, 5], "1, x0, x1^2");
        // PySINDy's L2 normalisation with one threshold keeps the term at 4N but not at N.
        let l2 = StlsConfig { threshold: 1.0, normalisation: Normalisation::L2, ..rms };
        let short_l2 = stls(&short_qr, &l2).unwrap();
        let long_l2 = stls(&long_qr, &l2).unwrap();
        assert_ne!(short_l2.support, long_l2.support);
    }

    #[test]
    fn configuration_errors_and_empty_support() {
        let (theta, y) = problem(100, 0.0);
        let qr = QrProblem::new(&theta, &y).unwrap();
        for bad in [
            StlsConfig { threshold: -1.0, ..StlsConfig::default() },
            StlsConfig { alpha: f64::NAN, ..StlsConfig::default() },
            StlsConfig { max_iter: 0, ..StlsConfig::default() },
        ] {
            assert!(matches!(stls(&qr, &bad), Err(SindyError::InvalidConfig(_))));
        }
        let everything_removed = stls(&qr, &StlsConfig { threshold: 1e6, ..StlsConfig::default() }).unwrap();
        assert_eq!(everything_removed.n_terms(), 0);
        assert!(everything_removed.converged);
    }
}
