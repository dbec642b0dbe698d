//! Model selection along a sweep: held-out scores, the Pareto front of (terms, error) and an
//! information criterion on held-out data (Mangan, Kutz, Brunton & Proctor, "Model selection
//! for dynamical systems via sparse regression and information criteria", Proc. R. Soc. A
//! 473:20170009, 2017), with user overrides.

use estimator_core::coeffs::MAX_TERMS;
use rayon::prelude::*;

use super::error::SindyError;
use super::sweep::{Sweep, SweepPoint};

/// The held-out errors of one candidate model, computed by the caller (who knows how to
/// simulate the system).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldoutScore {
    /// Root mean square of the one-step prediction error.
    pub one_step_rms: f64,
    /// Root mean square of the free-run (recursive simulation) error, when computed.
    pub free_run_rms: Option<f64>,
    /// The number of held-out samples behind `one_step_rms`.
    pub n_samples: usize,
}

/// An information criterion on the held-out one-step mean squared error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InformationCriterion {
    /// Bayesian: `n ln(MSE) + k ln(n)`.
    #[default]
    Bic,
    /// Akaike: `n ln(MSE) + 2 k`.
    Aic,
}

impl InformationCriterion {
    /// The criterion of a model with `k` terms and mean squared error `mse` on `n` samples
    /// (Mangan et al. 2017, eqs. 2.5 and 2.7, with the Gaussian likelihood up to a constant).
    #[must_use]
    pub fn value(self, n: usize, mse: f64, k: usize) -> f64 {
        let n = n as f64;
        let penalty = match self {
            Self::Bic => k as f64 * n.ln(),
            Self::Aic => 2.0 * k as f64,
        };
        n * mse.ln() + penalty
    }
}

/// Which model of the sweep to pick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SelectionRule {
    /// The smallest information criterion (ties: fewer terms, then earlier in the sweep).
    Criterion(InformationCriterion),
    /// The model of the swept threshold nearest (in logarithm) to this value.
    Threshold(f64),
    /// The model with this many terms and the smallest held-out one-step error.
    NTerms(usize),
}

/// The selection settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectionConfig {
    /// The rule.
    pub rule: SelectionRule,
    /// No model with more terms is selected (the core holds [`MAX_TERMS`]).
    pub max_terms: usize,
    /// One-step errors below this fraction of the training target's RMS count as this
    /// fraction: round-off, so that on noise-free data the sparsest exact model wins rather
    /// than the one whose round-off happens to be smallest.
    pub error_floor: f64,
}

impl Default for SelectionConfig {
    /// BIC, at most [`MAX_TERMS`] terms, an error floor of 1e-8 of the target's RMS.
    fn default() -> Self {
        Self { rule: SelectionRule::Criterion(InformationCriterion::Bic), max_terms: MAX_TERMS, error_floor: 1e-8 }
    }
}

/// A sweep point with its held-out score.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoredPoint {
    /// The model.
    pub point: SweepPoint,
    /// Its held-out errors.
    pub heldout: HeldoutScore,
    /// Its information criterion under the configured rule's criterion (BIC for the
    /// overrides); `None` when it has too many terms or no finite error.
    pub criterion: Option<f64>,
    /// Whether no other model has both fewer-or-equal terms and a lower-or-equal held-out
    /// one-step error (raised to the error floor), one of them strictly.
    pub pareto: bool,
}

/// The scored sweep and the selected model.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoredSweep {
    /// Every distinct model of the sweep, in sweep order.
    pub points: Vec<ScoredPoint>,
    /// The index of the selected model in [`ScoredSweep::points`].
    pub selected: usize,
}

impl ScoredSweep {
    /// The selected model.
    #[must_use]
    pub fn selected(&self) -> &ScoredPoint {
        &self.points[self.selected]
    }
}

impl Sweep {
    /// Scores every distinct model with the caller's held-out evaluation (called once per
    /// model with its physical coefficients, in parallel, results in sweep order), marks the
    /// Pareto front and selects a model.
    pub fn select<F>(&self, heldout: F, config: &SelectionConfig) -> Result<ScoredSweep, SindyError>
    where
        F: Fn(&[f64]) -> HeldoutScore + Sync,
    {
        let scores: Vec<HeldoutScore> = self.points.par_iter().map(|point| heldout(&point.coefficients)).collect();
        let n_terms: Vec<usize> = self.points.iter().map(|point| point.n_terms).collect();
        let floor = config.error_floor * self.target_rms;
        // Errors below the floor are round-off: they tie on the front as in the criterion.
        let errors: Vec<f64> = scores.iter().map(|score| floored(score.one_step_rms, floor)).collect();
        let pareto = pareto_front(&n_terms, &errors);
        let criterion = match config.rule {
            SelectionRule::Criterion(criterion) => criterion,
            SelectionRule::Threshold(_) | SelectionRule::NTerms(_) => InformationCriterion::Bic,
        };
        let points: Vec<ScoredPoint> = self
            .points
            .iter()
            .zip(scores)
            .zip(pareto)
            .map(|((point, heldout), pareto)| {
                let value = criterion_of(criterion, point, &heldout, floor, config.max_terms);
                ScoredPoint { point: point.clone(), heldout, criterion: value, pareto }
            })
            .collect();
        let selected = self.choose(&points, config)?;
        Ok(ScoredSweep { points, selected })
    }

    /// Applies the selection rule to scored points.
    fn choose(&self, points: &[ScoredPoint], config: &SelectionConfig) -> Result<usize, SindyError> {
        let selected = match config.rule {
            SelectionRule::Criterion(_) => best_criterion(points),
            SelectionRule::Threshold(threshold) => self.nearest_threshold(threshold),
            SelectionRule::NTerms(n_terms) => best_with_terms(points, n_terms),
        }
        .ok_or_else(|| SindyError::NoEligibleModel(format!("{:?}", config.rule)))?;
        let n_terms = points[selected].point.n_terms;
        if n_terms > config.max_terms {
            return Err(SindyError::NoEligibleModel(format!("{n_terms} terms, more than {}", config.max_terms)));
        }
        Ok(selected)
    }

    /// The point of the swept threshold nearest to `threshold` in logarithm.
    fn nearest_threshold(&self, threshold: f64) -> Option<usize> {
        let distance = |swept: f64| (swept.ln() - threshold.ln()).abs();
        let nearest = (0..self.thresholds.len())
            .filter(|&idx| distance(self.thresholds[idx]).is_finite())
            .min_by(|&a, &b| distance(self.thresholds[a]).total_cmp(&distance(self.thresholds[b])))?;
        self.point_of_threshold.get(nearest).copied()
    }
}

/// The information criterion of a point, or `None` when it is not eligible.
fn criterion_of(
    criterion: InformationCriterion,
    point: &SweepPoint,
    heldout: &HeldoutScore,
    floor: f64,
    max_terms: usize,
) -> Option<f64> {
    let eligible = point.n_terms <= max_terms && heldout.one_step_rms.is_finite() && heldout.n_samples > 0;
    let rms = floored(heldout.one_step_rms, floor);
    eligible.then(|| criterion.value(heldout.n_samples, rms * rms, point.n_terms))
}

/// An error raised to the floor (and above zero, so that its logarithm is finite); NaN stays NaN.
fn floored(error: f64, floor: f64) -> f64 {
    if error.is_nan() { error } else { error.max(floor).max(f64::MIN_POSITIVE) }
}

/// The eligible point with the smallest criterion; ties go to fewer terms, then to the first.
fn best_criterion(points: &[ScoredPoint]) -> Option<usize> {
    let key = |idx: usize| (points[idx].criterion, points[idx].point.n_terms);
    (0..points.len()).filter(|&idx| points[idx].criterion.is_some()).min_by(|&a, &b| {
        let ((ca, ka), (cb, kb)) = (key(a), key(b));
        let ordering = ca.unwrap_or(f64::INFINITY).total_cmp(&cb.unwrap_or(f64::INFINITY));
        ordering.then(ka.cmp(&kb)).then(a.cmp(&b))
    })
}

/// The point with `n_terms` terms and the smallest finite held-out one-step error.
fn best_with_terms(points: &[ScoredPoint], n_terms: usize) -> Option<usize> {
    (0..points.len())
        .filter(|&idx| points[idx].point.n_terms == n_terms && points[idx].heldout.one_step_rms.is_finite())
        .min_by(|&a, &b| points[a].heldout.one_step_rms.total_cmp(&points[b].heldout.one_step_rms))
}

/// Pareto optimality on (terms, error), both minimised: a point is on the front when no other
/// point has fewer-or-equal terms and a lower-or-equal error with one of them strict. Points
/// with a non-finite error are never on the front and dominate nothing.
#[must_use]
pub fn pareto_front(n_terms: &[usize], errors: &[f64]) -> Vec<bool> {
    let dominates = |a: usize, b: usize| {
        n_terms[a] <= n_terms[b] && errors[a] <= errors[b] && (n_terms[a] < n_terms[b] || errors[a] < errors[b])
    };
    (0..n_terms.len())
        .map(|idx| {
            errors[idx].is_finite()
                && !(0..n_terms.len()).any(|other| other != idx && errors[other].is_finite() && dominates(other, idx))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_the_non_dominated_points() {
        let n_terms = [1, 2, 2, 3, 4, 5];
        let errors = [1.0, 0.5, 0.6, 0.5, 0.1, f64::NAN];
        assert_eq!(pareto_front(&n_terms, &errors), [true, true, false, false, true, false]);
    }

    #[test]
    fn criteria_follow_their_formulas() {
        let n = 100;
        let mse: f64 = 0.25;
        assert!((InformationCriterion::Bic.value(n, mse, 3) - (100.0 * mse.ln() + 3.0 * 100f64.ln())).abs() < 1e-12);
        assert!((InformationCriterion::Aic.value(n, mse, 3) - (100.0 * mse.ln() + 6.0)).abs() < 1e-12);
    }
}
