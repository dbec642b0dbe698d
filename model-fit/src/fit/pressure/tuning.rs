//! The noise and the steady-state filter (steps 6-7 of [`super`]): the taps' noise, the
//! `Q` factor chosen by the filter's one-step error, and the steps the filter needs to settle.

use estimator_core::coeffs::N_TAPS;
use estimator_core::pressure::PressureFilter;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::*;
use crate::fit::dare::solve_filter_dare;
use stats::{MAD_TO_STD, median_high};

/// Smallest per-tap noise variance (`R` must be positive definite; below a quantisation of
/// 1e-5 the data carry no information on it anyway).
pub(super) const MIN_NOISE_VARIANCE: f64 = 1e-12;

/// Variance of the second difference of unit white noise, `1 + 4 + 1`.
pub(super) const SECOND_DIFFERENCE_GAIN: f64 = 6.0;

/// Steps the filter needs to settle from its start at the mean pressures (zero modes) before
/// its innovation gate is armed (`estimator_core::coeffs::PressureModel::settle_steps`).
///
/// Started at zero while the flow's state is `e0`, the steady-state filter's error after `n`
/// updates is `M^n e0` with `M = (I - K C) A`, and the next innovation carries `C A M^n e0`
/// besides its noise (Anderson & Moore, Optimal Filtering, ch. 4). The gate is armed at the
/// first `n` where a start three standard deviations of the state from the mean, in any
/// direction (`e0 = 3 L z`, `|z| <= 1`, `L L^T` the state's covariance over the training
/// samples), adds at most one steady-state innovation standard deviation to any tap: a good
/// channel then fails a gate of five with the odds of a four-sigma excursion. It depends on
/// the model only, not on any recording's start.
///
/// # Errors
///
/// [`PressureFitError::InvalidModel`] when the error does not decay that far within
/// `u16::MAX` steps (an unstable `M`, which a DARE solution does not give).
pub fn settle_steps(table: &PressureTable, state_cov: &DMatrix<f64>) -> Result<u16, PressureFitError> {
    let rank = table.rank();
    if rank == 0 || state_cov.shape() != (rank, rank) {
        return Ok(0);
    }
    let eigen = state_cov.clone().symmetric_eigen();
    let sqrt_values = eigen.eigenvalues.map(|value| value.max(0.0).sqrt());
    let spread = &eigen.eigenvectors * DMatrix::from_diagonal(&sqrt_values) * 3.0;
    let (a, c, gain) = table.matrices();
    let closed_loop = (DMatrix::identity(rank, rank) - &gain * &c) * &a;
    let innovation_of_error = &c * &a;
    // `M^n L`, advanced one step at a time.
    let mut error = spread;
    for steps in 0..=u16::MAX {
        let innovation = &innovation_of_error * &error;
        let within = (0..N_TAPS).all(|tap| innovation.row(tap).norm() <= table.model.innovation_std[tap]);
        if within {
            return Ok(steps);
        }
        error = &closed_loop * error;
    }
    Err(PressureFitError::InvalidModel("the pressure filter does not settle from its start within u16::MAX steps"))
}

/// Per-tap measurement noise variance (step 6): `(1.4826 MAD(d))^2 / 6` over the second
/// differences `d_k = x_k - 2 x_{k-1} + x_{k-2}` of consecutive finite samples of every run
/// (white noise of variance `sigma^2` gives `var(d) = 6 sigma^2`, while a signal at `omega`
/// keeps only `(omega dt)^4` of its variance: the pseudo-residuals of Gasser, Sroka &
/// Jennen-Steinmetz, Biometrika 73, 1986); the plain `mean(d^2) / 6` when more than half the
/// differences are equal (a quantised, nearly constant tap).
pub(super) fn noise_variance(runs: &[PressureRun<'_>]) -> Result<[f64; N_TAPS], PressureFitError> {
    let mut variance = [0.0; N_TAPS];
    for (tap, out) in variance.iter_mut().enumerate() {
        let mut differences: Vec<f64> = runs
            .iter()
            .flat_map(|run| run.cp[tap].windows(3).map(|triple| triple[2] - 2.0 * triple[1] + triple[0]))
            .filter(|difference| difference.is_finite())
            .collect();
        if differences.len() < 2 {
            return Err(PressureFitError::TooFewSamples {
                stage: "noise estimate",
                found: differences.len(),
                needed: 2,
            });
        }
        let mean_square = differences.iter().map(|d| d * d).sum::<f64>() / differences.len() as f64;
        let centre = median_high(&mut differences).unwrap_or(0.0);
        let mut deviations: Vec<f64> = differences.iter().map(|d| (d - centre).abs()).collect();
        let robust = (MAD_TO_STD * median_high(&mut deviations).unwrap_or(0.0)).powi(2) / SECOND_DIFFERENCE_GAIN;
        let estimate = if robust > 0.0 { robust } else { mean_square / SECOND_DIFFERENCE_GAIN };
        *out = estimate.max(MIN_NOISE_VARIANCE);
    }
    Ok(variance)
}

/// Taps with finite readings in fewer than half of the runs' samples.
pub(super) fn dead_taps(runs: &[PressureRun<'_>]) -> [bool; N_TAPS] {
    let total: usize = runs.iter().map(PressureRun::len).sum();
    std::array::from_fn(|tap| {
        let finite: usize = runs.iter().map(|run| run.cp[tap].iter().filter(|value| value.is_finite()).count()).sum();
        2 * finite < total
    })
}

/// The filter tuned on the training data (steps 6-7).
#[derive(Debug, Clone)]
pub(super) struct TunedFilter {
    pub(super) table: PressureTable,
    pub(super) q_scale: f64,
    pub(super) dare_iterations: usize,
    pub(super) dare_residual: f64,
    pub(super) scores: CpScores,
}

/// Solves the DARE for every `Q` factor, runs each filter over the training runs and keeps the
/// one with the smallest `R`-weighted mean squared innovation.
pub(super) fn tune_filter(
    runs: &[PressureRun<'_>],
    base: PressureTable,
    residual_cov: &DMatrix<f64>,
    noise_variance: &[f64; N_TAPS],
    config: &PressureFitConfig,
) -> Result<TunedFilter, PressureFitError> {
    let r = DMatrix::from_diagonal(&DVector::from_row_slice(noise_variance));
    let (a, c, _) = base.matrices();
    let candidates: Result<Vec<TunedFilter>, PressureFitError> = config
        .q_scales
        .par_iter()
        .map(|&q_scale| {
            let solution = solve_filter_dare(&a, &c, &(residual_cov * q_scale), &r, &config.dare)?;
            let mut table = base.clone();
            for (mode, row) in table.model.gain.iter_mut().enumerate().take(solution.gain.nrows()) {
                *row = std::array::from_fn(|tap| solution.gain[(mode, tap)]);
            }
            table.model.innovation_std = std::array::from_fn(|tap| solution.innovation_cov[(tap, tap)].max(0.0).sqrt());
            let scores = score_cp(runs, &table, noise_variance, config.warmup_samples);
            let (dare_iterations, dare_residual) = (solution.iterations, solution.relative_residual);
            Ok(TunedFilter { table, q_scale, dare_iterations, dare_residual, scores })
        })
        .collect();
    candidates?
        .into_iter()
        .filter(|candidate| candidate.scores.weighted_innovation().is_finite())
        .min_by(|x, y| x.scores.weighted_innovation().total_cmp(&y.scores.weighted_innovation()))
        .ok_or(PressureFitError::NonFinite("innovation score of every Q factor"))
}

/// Sums of squared pressure errors of a filter run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct CpScores {
    /// `sum (Cp - Cp_pred)^2 / R_tap`.
    pub(super) weighted_innovation_sq: f64,
    /// `sum (Cp - Cp_pred)^2`.
    pub(super) innovation_sq: f64,
    /// `sum (Cp - Cp_filtered)^2`.
    pub(super) filtered_sq: f64,
    /// Finite tap samples summed.
    pub(super) count: usize,
}

impl CpScores {
    pub(super) fn add(self, other: Self) -> Self {
        Self {
            weighted_innovation_sq: self.weighted_innovation_sq + other.weighted_innovation_sq,
            innovation_sq: self.innovation_sq + other.innovation_sq,
            filtered_sq: self.filtered_sq + other.filtered_sq,
            count: self.count + other.count,
        }
    }

    pub(super) fn weighted_innovation(&self) -> f64 {
        self.weighted_innovation_sq / self.count.max(1) as f64
    }

    pub(super) fn prediction_rms(&self) -> f64 {
        (self.innovation_sq / self.count.max(1) as f64).sqrt()
    }

    pub(super) fn filtered_rms(&self) -> f64 {
        (self.filtered_sq / self.count.max(1) as f64).sqrt()
    }
}

/// Runs the filter over every run and sums the pressure errors after the warm-up.
pub(super) fn score_cp(
    runs: &[PressureRun<'_>],
    table: &PressureTable,
    noise_variance: &[f64; N_TAPS],
    warmup: usize,
) -> CpScores {
    let mut total = CpScores::default();
    for run in runs {
        let mut filter = PressureFilter::at_start(&table.model);
        let mut inputs = HeldInputs::default();
        for k in 0..run.len() {
            let cp = run.cp_at(k);
            let step = filter_step(&mut filter, table, &inputs.hold(run.inputs(k)), &cp, run.alpha_deg[k]);
            if k < warmup {
                continue;
            }
            for tap in (0..N_TAPS).filter(|&tap| cp[tap].is_finite()) {
                let innovation = cp[tap] - step.predicted_cp[tap];
                let filtered = cp[tap] - step.filtered_cp[tap];
                total = total.add(CpScores {
                    weighted_innovation_sq: innovation * innovation / noise_variance[tap],
                    innovation_sq: innovation * innovation,
                    filtered_sq: filtered * filtered,
                    count: 1,
                });
            }
        }
    }
    total
}
