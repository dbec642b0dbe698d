//! The least-squares problem of one target, reduced once to the thin QR of its library.
//!
//! For `Theta = Q R` (N x p, Q with orthonormal columns) and any coefficient vector w,
//! `|y - Theta w|^2 = |Q^T y - R w|^2 + |y - Q Q^T y|^2` (Golub & Van Loan, *Matrix
//! Computations*, 4th ed., section 5.3.3). Every ridge solve, threshold and unbiased refit of
//! STLS therefore runs on the p x p factor R at a cost independent of N, and scaling the
//! columns of Theta scales the columns of R the same way (`Theta D^-1 = Q (R D^-1)`).

use nalgebra::{DMatrix, DVector};

use super::error::SindyError;
use super::linalg::tsqr_augmented;

/// How the library columns are scaled before thresholding; the threshold acts on the
/// coefficients of the scaled columns, and the fitted coefficients are returned in physical
/// units (divided back by the scales).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Normalisation {
    /// No scaling: the threshold acts on the physical coefficients (PySINDy's
    /// `normalize_columns=False`).
    None,
    /// Each column divided by its root mean square `sqrt(mean(col^2))`. The normalised
    /// coefficient is `coef * rms(col)`, a contribution in the target's units that does not
    /// depend on the data length, so a threshold means the same at any N. The ridge penalty is
    /// applied as `alpha * N` (mean-squared-error objective `|y - Xw|^2 / N + alpha |w|^2`), so
    /// Rms with `(threshold, alpha)` equals L2 with `(threshold * sqrt(N), alpha)`.
    #[default]
    Rms,
    /// Each column divided by its L2 norm (PySINDy's `normalize_columns=True`; `base.py`
    /// `_normalize_features`). The normalised coefficients grow like `sqrt(N)`.
    L2,
}

/// The QR-reduced least-squares problem of one target over one library.
#[derive(Debug, Clone, PartialEq)]
pub struct QrProblem {
    /// The p x p upper-triangular factor of Theta.
    r: DMatrix<f64>,
    /// `Q^T y` (length p).
    qty: DVector<f64>,
    /// `|y|^2`.
    y_norm_sq: f64,
    /// `|y - Q Q^T y|^2`, the residual of the full-library least-squares fit.
    residual_sq: f64,
    /// The L2 norm of each column of Theta.
    column_norms: Vec<f64>,
    /// The number of samples N.
    n_samples: usize,
}

impl QrProblem {
    /// Factors `[Theta | y]` once (O(N p^2)); rejects empty, mismatched or non-finite data.
    pub fn new(theta: &DMatrix<f64>, y: &[f64]) -> Result<Self, SindyError> {
        check_dense(theta, y)?;
        let r_aug = tsqr_augmented(theta, &[y]);
        Ok(Self::from_factor(theta, &r_aug, column_norms(theta), 0, y))
    }

    /// The problems of several targets over one library (a SINDy fit of every state's
    /// derivative), from one factorisation of `[Theta | y_1 ... y_k]`: O(N (p + k)^2) instead
    /// of k times O(N p^2). Each equals [`QrProblem::new`] of its target up to rounding.
    pub fn for_targets(theta: &DMatrix<f64>, targets: &[&[f64]]) -> Result<Vec<Self>, SindyError> {
        if targets.is_empty() {
            return Err(SindyError::EmptyData { what: "targets" });
        }
        check_library(theta)?;
        for y in targets {
            check_target(theta.nrows(), y)?;
        }
        let r_aug = tsqr_augmented(theta, targets);
        let norms = column_norms(theta);
        Ok(targets.iter().enumerate().map(|(idx, y)| Self::from_factor(theta, &r_aug, norms.clone(), idx, y)).collect())
    }

    /// The problem of target `idx` from the factor `R_aug` of `[Theta | y_1 ... y_k]`: R, the
    /// target's `Q^T y` and, as its residual, the squared norm of the rest of its column.
    fn from_factor(theta: &DMatrix<f64>, r_aug: &DMatrix<f64>, column_norms: Vec<f64>, idx: usize, y: &[f64]) -> Self {
        let (n_samples, n_features) = theta.shape();
        let r = r_aug.view((0, 0), (n_features, n_features)).into_owned();
        let column = r_aug.column(n_features + idx);
        let qty = column.rows(0, n_features).into_owned();
        let residual_sq = column.rows_range(n_features..).iter().map(|value| value.powi(2)).sum();
        let y_norm_sq = y.iter().map(|value| value * value).sum();
        Self { r, qty, y_norm_sq, residual_sq, column_norms, n_samples }
    }

    /// The number of samples N.
    #[must_use]
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// The number of library terms p.
    #[must_use]
    pub fn n_features(&self) -> usize {
        self.column_norms.len()
    }

    /// The upper-triangular factor R of Theta (p x p).
    #[must_use]
    pub fn r(&self) -> &DMatrix<f64> {
        &self.r
    }

    /// `Q^T y`.
    #[must_use]
    pub fn qty(&self) -> &DVector<f64> {
        &self.qty
    }

    /// `|y|^2`.
    #[must_use]
    pub fn y_norm_sq(&self) -> f64 {
        self.y_norm_sq
    }

    /// The root mean square of the target, `sqrt(|y|^2 / N)`.
    #[must_use]
    pub fn target_rms(&self) -> f64 {
        (self.y_norm_sq / self.n_samples as f64).sqrt()
    }

    /// The L2 norm of each column of Theta.
    #[must_use]
    pub fn column_norms(&self) -> &[f64] {
        &self.column_norms
    }

    /// The column scales of a normalisation (a zero column keeps the scale 1).
    #[must_use]
    pub fn scales(&self, normalisation: Normalisation) -> Vec<f64> {
        column_scales(&self.column_norms, self.n_samples, normalisation)
    }

    /// The ridge weight applied in the normalised space for a user `alpha` (see
    /// [`Normalisation::Rms`]).
    #[must_use]
    pub fn ridge_weight(&self, alpha: f64, normalisation: Normalisation) -> f64 {
        ridge_weight(alpha, self.n_samples, normalisation)
    }

    /// The training residual sum of squares `|y - Theta w|^2` of physical coefficients w,
    /// computed on R as `|Q^T y - R w|^2 + |y - Q Q^T y|^2`.
    pub fn rss(&self, coeffs: &[f64]) -> Result<f64, SindyError> {
        if coeffs.len() != self.n_features() {
            return Err(SindyError::DimensionMismatch {
                what: "coefficients",
                expected: self.n_features(),
                found: coeffs.len(),
            });
        }
        let w = DVector::from_column_slice(coeffs);
        Ok((&self.qty - &self.r * w).norm_squared() + self.residual_sq)
    }
}

/// The column scales of a normalisation from the columns' L2 norms; a zero column keeps the
/// scale 1 (its coefficient is zero in every solve).
pub(crate) fn column_scales(column_norms: &[f64], n_samples: usize, normalisation: Normalisation) -> Vec<f64> {
    let root_n = (n_samples as f64).sqrt();
    let scale = |norm: f64| match normalisation {
        Normalisation::None => 1.0,
        Normalisation::Rms => norm / root_n,
        Normalisation::L2 => norm,
    };
    column_norms.iter().map(|&norm| if norm > 0.0 { scale(norm) } else { 1.0 }).collect()
}

/// The ridge weight in normalised coordinates: `alpha * N` for [`Normalisation::Rms`]
/// (mean-squared-error objective), `alpha` otherwise (PySINDy's objective).
pub(crate) fn ridge_weight(alpha: f64, n_samples: usize, normalisation: Normalisation) -> f64 {
    match normalisation {
        Normalisation::Rms => alpha * n_samples as f64,
        Normalisation::None | Normalisation::L2 => alpha,
    }
}

/// The L2 norm of each column of Theta.
fn column_norms(theta: &DMatrix<f64>) -> Vec<f64> {
    theta.column_iter().map(|column| column.norm()).collect()
}

/// Checks a dense problem: non-empty, one target per row, all values finite.
pub(crate) fn check_dense(theta: &DMatrix<f64>, y: &[f64]) -> Result<(), SindyError> {
    check_library(theta)?;
    check_target(theta.nrows(), y)
}

/// Checks a library: at least one sample and one term, all values finite.
fn check_library(theta: &DMatrix<f64>) -> Result<(), SindyError> {
    let (n_samples, n_features) = theta.shape();
    if n_samples == 0 {
        return Err(SindyError::EmptyData { what: "samples" });
    }
    if n_features == 0 {
        return Err(SindyError::EmptyData { what: "library terms" });
    }
    for (col, column) in theta.column_iter().enumerate() {
        if let Some(row) = column.iter().position(|value| !value.is_finite()) {
            return Err(SindyError::NonFinite { name: format!("library column {col}"), row });
        }
    }
    Ok(())
}

/// Checks a target: one value per sample, all finite.
fn check_target(n_samples: usize, y: &[f64]) -> Result<(), SindyError> {
    if y.len() != n_samples {
        return Err(SindyError::DimensionMismatch { what: "target length", expected: n_samples, found: y.len() });
    }
    if let Some(row) = y.iter().position(|value| !value.is_finite()) {
        return Err(SindyError::NonFinite { name: "target".to_owned(), row });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rss_on_r_equals_the_direct_residual() {
        let theta = DMatrix::from_fn(2500, 3, |row, col| ((row as f64) * 0.01).powi(col as i32) + 0.1 * col as f64);
        let y: Vec<f64> = (0..2500).map(|row| (row as f64 * 0.003).sin()).collect();
        let problem = QrProblem::new(&theta, &y).unwrap();
        let w = [0.3, -0.2, 0.05];
        let direct: f64 = (0..2500)
            .map(|row| {
                let fit: f64 = (0..3).map(|col| theta[(row, col)] * w[col]).sum();
                (y[row] - fit).powi(2)
            })
            .sum();
        assert!((problem.rss(&w).unwrap() - direct).abs() < 1e-9 * direct);
        assert!((problem.y_norm_sq() - problem.rss(&[0.0; 3]).unwrap()).abs() < 1e-9 * problem.y_norm_sq());
    }

    #[test]
    fn one_factorisation_of_every_target_gives_each_targets_problem() {
        let theta = DMatrix::from_fn(2500, 4, |row, col| ((row * (col + 2)) as f64 * 0.013).sin() + col as f64);
        let targets: Vec<Vec<f64>> =
            (1..=3).map(|k| (0..2500).map(|row| (row as f64 * 0.002 * k as f64).cos()).collect()).collect();
        let views: Vec<&[f64]> = targets.iter().map(Vec::as_slice).collect();
        let together = QrProblem::for_targets(&theta, &views).unwrap();
        assert_eq!(together.len(), 3);
        for (problem, y) in together.iter().zip(&targets) {
            let alone = QrProblem::new(&theta, y).unwrap();
            // R and Q^T y are unique up to the signs of R's rows, which both factorisations share.
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * alone.r().norm();
            assert!(problem.r().iter().zip(alone.r().iter()).all(|(a, b)| close(*a, *b)));
            assert!(problem.qty().iter().zip(alone.qty().iter()).all(|(a, b)| close(*a, *b)));
            let w = [0.2, -0.1, 0.05, 0.3];
            let (rss, expected) = (problem.rss(&w).unwrap(), alone.rss(&w).unwrap());
            assert!((rss - expected).abs() <= 1e-10 * expected, "{rss} vs {expected}");
        }
        assert!(matches!(QrProblem::for_targets(&theta, &[]), Err(SindyError::EmptyData { what: "targets" })));
        let short = [1.0; 3];
        assert!(matches!(
            QrProblem::for_targets(&theta, &[&targets[0], &short]),
            Err(SindyError::DimensionMismatch { .. })
        ));
    }

    #[test]
    fn bad_input_is_rejected_with_the_column() {
        let mut theta = DMatrix::from_element(4, 2, 1.0);
        assert!(matches!(QrProblem::new(&theta, &[1.0; 3]), Err(SindyError::DimensionMismatch { .. })));
        theta[(2, 1)] = f64::INFINITY;
        let err = QrProblem::new(&theta, &[1.0; 4]).unwrap_err();
        assert_eq!(err, SindyError::NonFinite { name: "library column 1".to_owned(), row: 2 });
        let theta = DMatrix::from_element(4, 2, 1.0);
        let err = QrProblem::new(&theta, &[1.0, f64::NAN, 1.0, 1.0]).unwrap_err();
        assert_eq!(err, SindyError::NonFinite { name: "target".to_owned(), row: 1 });
        assert!(matches!(QrProblem::new(&DMatrix::zeros(0, 2), &[]), Err(SindyError::EmptyData { .. })));
    }
}
