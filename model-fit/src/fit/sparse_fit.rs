//! What the plant and coupling fits share: the threshold sweep on a library, scoring on the
//! validation samples (the end of the training part, [`super::split`]), the selection of one
//! model, its refit on the whole training part, and the record of the sweep for the model card.
//!
//! Selection: held-out errors of neighbouring samples are strongly correlated (the errors of a
//! free-running model drift slowly), so counting every sample as independent would make any
//! extra term "significant". The information criterion therefore uses the effective number of
//! samples of an AR(1) error, `n_eff = n (1 - r1) / (1 + r1)` with `r1` the lag-one
//! autocorrelation of the validation error (Bartlett 1946; von Storch & Zwiers, Statistical
//! Analysis in Climate Research, section 17.1).

use serde::Serialize;

use nalgebra::DMatrix;

use super::FitError;
use sindy::{InformationCriterion, Library, Normalisation, ScoredPoint, ScoredSweep, StlsConfig, stls_dense};

/// One distinct model of a sweep, for reports.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepRow {
    /// The smallest swept threshold that gave this support.
    pub threshold: f64,
    /// Number of terms.
    pub n_terms: usize,
    /// Validation one-step RMS error (of the model fitted without the validation samples).
    pub validation_one_step_rms: f64,
    /// Validation free-run RMS error (the plant), when simulated.
    pub validation_free_run_rms: Option<f64>,
    /// Effective number of validation samples behind the criterion.
    pub validation_effective_samples: usize,
    /// Information criterion (BIC with the effective sample size); `None` if not eligible.
    pub criterion: Option<f64>,
    /// On the Pareto front of (terms, validation error).
    pub pareto: bool,
}

/// A fitted sparse model with its sweep.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SparseFit {
    /// `(term name, coefficient)` of the selected model refitted on the whole training part, in
    /// library order.
    pub terms: Vec<(String, f64)>,
    /// The sweep's distinct models.
    pub sweep: Vec<SweepRow>,
    /// Index of the selected model in `sweep`.
    pub selected: usize,
    /// Number of training samples of the refit.
    pub n_train: usize,
}

impl SparseFit {
    /// The selected row.
    #[must_use]
    pub fn selected_row(&self) -> Option<&SweepRow> {
        self.sweep.get(self.selected)
    }
}

/// Lag-one autocorrelation of a sequence (0 for fewer than three values or no variance).
#[must_use]
pub fn lag_one_autocorrelation(values: &[f64]) -> f64 {
    if values.len() < 3 {
        return 0.0;
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let variance: f64 = values.iter().map(|v| (v - mean).powi(2)).sum();
    let covariance: f64 = values.windows(2).map(|pair| (pair[0] - mean) * (pair[1] - mean)).sum();
    if variance > 0.0 { (covariance / variance).clamp(-0.999, 0.999) } else { 0.0 }
}

/// Effective number of independent samples of `n` values with lag-one autocorrelation `r1`.
#[must_use]
pub fn effective_samples(n: usize, r1: f64) -> usize {
    let factor = if r1 > 0.0 { (1.0 - r1) / (1.0 + r1) } else { 1.0 };
    ((n as f64 * factor).round() as usize).clamp(1.min(n), n)
}

/// The validation error measure a selection uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SelectBy {
    /// The one-step error (a static map such as the coupling operator).
    OneStep,
    /// The free-run error (a dynamic model simulated open loop, as the core runs the plant).
    FreeRun,
}

/// BIC of one scored model on the chosen validation error, with the effective sample size
/// carried in `HeldoutScore::n_samples`; `None` when it has more than `max_terms` terms or no
/// finite error.
fn criterion_of(point: &ScoredPoint, by: SelectBy, max_terms: usize) -> Option<f64> {
    let rms = match by {
        SelectBy::OneStep => Some(point.heldout.one_step_rms),
        SelectBy::FreeRun => point.heldout.free_run_rms,
    }?;
    let eligible = point.point.n_terms <= max_terms && rms.is_finite() && point.heldout.n_samples > 0;
    let mse = rms.max(1e-300).powi(2);
    eligible.then(|| InformationCriterion::Bic.value(point.heldout.n_samples, mse, point.point.n_terms))
}

/// Picks the model with the smallest `criterion_of` among those with at most `max_terms` terms
/// (the core holds [`estimator_core::coeffs::MAX_TERMS`]; a model that gains a term after selection must leave room for
/// it); ties go to fewer terms. `None` when no model is eligible.
#[must_use]
pub fn select_index(scored: &ScoredSweep, by: SelectBy, max_terms: usize) -> Option<usize> {
    let candidates =
        scored.points.iter().enumerate().filter_map(|(idx, point)| Some((idx, criterion_of(point, by, max_terms)?)));
    candidates
        .min_by(|a, b| {
            a.1.total_cmp(&b.1).then(scored.points[a.0].point.n_terms.cmp(&scored.points[b.0].point.n_terms))
        })
        .map(|(idx, _)| idx)
}

/// Least squares of `targets` on the columns of `theta` where `support` holds, zero elsewhere:
/// the structure chosen on the validation samples, refitted on the whole training part (the
/// unbiasing step of STLS, which is plain least squares on the support).
///
/// # Errors
/// [`FitError`] when the least-squares problem is invalid (no rows, non-finite values).
pub fn refit_support(theta: &DMatrix<f64>, targets: &[f64], support: &[bool]) -> Result<Vec<f64>, FitError> {
    let columns: Vec<usize> = (0..support.len()).filter(|&idx| support[idx]).collect();
    let mut coefficients = vec![0.0; support.len()];
    if columns.is_empty() {
        return Ok(coefficients);
    }
    let reduced = theta.select_columns(&columns);
    let config =
        StlsConfig { threshold: 0.0, alpha: 0.0, max_iter: 1, unbias: true, normalisation: Normalisation::Rms };
    let fit = stls_dense(&reduced, targets, &config)?;
    for (&idx, &value) in columns.iter().zip(&fit.coefficients) {
        coefficients[idx] = value;
    }
    Ok(coefficients)
}

/// The report of a scored sweep with `selected` chosen.
#[must_use]
pub fn sparse_fit(
    library: &Library,
    scored: &ScoredSweep,
    by: SelectBy,
    max_terms: usize,
    selected: usize,
    coefficients: &[f64],
    n_train: usize,
) -> SparseFit {
    let names = library.term_names();
    let terms = names.into_iter().zip(coefficients).filter(|(_, c)| **c != 0.0).map(|(name, &c)| (name, c)).collect();
    let sweep = scored
        .points
        .iter()
        .map(|point| SweepRow {
            threshold: point.point.threshold,
            n_terms: point.point.n_terms,
            validation_one_step_rms: point.heldout.one_step_rms,
            validation_free_run_rms: point.heldout.free_run_rms,
            validation_effective_samples: point.heldout.n_samples,
            criterion: criterion_of(point, by, max_terms),
            pareto: point.pareto,
        })
        .collect();
    SparseFit { terms, sweep, selected, n_train }
}
