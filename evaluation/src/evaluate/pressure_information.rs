//! What the pressures can tell about the eGK's error: the measured pressures used as freely
//! as a linear filter bank allows to predict the eGK's residual on the roll runs, fitted on
//! the training part and scored on the held-out part.
//!
//! Why: the fusion (docs/equations.md, Fusion design) can only improve on the eGK with
//! what the pressures know about the eGK's error. The pressure path is a linear filter of the
//! same twelve pressures, and the fusion a linear filter of it and of the eGK, so a regression
//! on every tap, raw and through first-order low-passes spanning the fusion's time scales, plus
//! both estimates, is a generous stand-in for the best linear fusion. When even that does not
//! lower the eGK's held-out error, a tie of the fused estimate with the eGK is what the data
//! allow, not a defect of the fusion.

use estimator_core::coeffs::N_TAPS;
use firmware_sim::dataset::{Dataset, RunKind};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use super::{Replayed, runs_at};
use model_fit::fit::signals::hold_missing;
use model_fit::fit::split::Split;

/// Time constants of the low-passes applied to every tap, s: the fusion's correlation times
/// (a few ms to a fraction of a second; docs/equations.md, Fusion design, puts `T_e` at 0.2 to
/// 1 s).
const LOWPASS_TAU_S: [f64; 3] = [0.005, 0.03, 0.2];

/// The bound at one angle of attack.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PressureInformationRow {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Held-out RMS of the eGK alone.
    pub egk_rms: f64,
    /// Held-out RMS of the fused estimate.
    pub fused_rms: f64,
    /// Held-out RMS of the eGK corrected by the regression on the pressures.
    pub best_linear_rms: f64,
    /// Regression columns (taps and their low-passes, both estimates, a constant).
    pub n_columns: usize,
}

/// The bound at every angle of attack with roll runs (none without them).
#[must_use]
pub fn pressure_information(
    dataset: &Dataset,
    replayed: &Replayed,
    split: &Split,
    alphas_deg: &[f64],
) -> Vec<PressureInformationRow> {
    alphas_deg.iter().filter_map(|&alpha_deg| row_at(dataset, replayed, split, alpha_deg)).collect()
}

fn row_at(dataset: &Dataset, replayed: &Replayed, split: &Split, alpha_deg: f64) -> Option<PressureInformationRow> {
    let (mut train, mut heldout) = (Samples::default(), Samples::default());
    for idx in runs_at(dataset, Some(RunKind::Roll), alpha_deg) {
        let run = &dataset.runs[idx];
        let sample_hz = run.meta.sample_hz;
        let outputs = &replayed.outputs[idx];
        let n = run.channels.cl.len().min(outputs.len());
        let mut columns: Vec<Vec<f64>> = Vec::new();
        for tap in &run.channels.cp {
            let held = hold_missing(&tap[..n], 0.0);
            for tau_s in LOWPASS_TAU_S {
                columns.push(lowpass(&held, tau_s, sample_hz));
            }
            columns.push(held);
        }
        columns.push(outputs[..n].iter().map(|o| f64::from(o.cl_egk)).collect());
        columns.push(outputs[..n].iter().map(|o| f64::from(o.cl_pressure)).collect());
        columns.push(vec![1.0; n]);
        let heldout_range = split.heldout(n);
        for k in split.training(n).chain(heldout_range.clone()) {
            let (egk, fused, measured) =
                (f64::from(outputs[k].cl_egk), f64::from(outputs[k].cl_roll), run.channels.cl[k]);
            let row: Vec<f64> = columns.iter().map(|column| column[k]).collect();
            if !(measured.is_finite() && egk.is_finite() && fused.is_finite() && row.iter().all(|v| v.is_finite())) {
                continue;
            }
            let target = if heldout_range.contains(&k) { &mut heldout } else { &mut train };
            target.push(row, measured - egk, measured - fused);
        }
    }
    let n_columns = N_TAPS * (LOWPASS_TAU_S.len() + 1) + 3;
    if train.residual.len() <= 10 * n_columns || heldout.residual.is_empty() {
        return None;
    }
    let x = DMatrix::from_row_slice(train.residual.len(), n_columns, &train.rows);
    let y = DVector::from_vec(train.residual.clone());
    // Standardised columns keep the least-squares problem well conditioned (pressures are
    // O(0.1), moments O(1e-3)).
    let scale: Vec<f64> = (0..n_columns).map(|col| x.column(col).norm().max(f64::MIN_POSITIVE)).collect();
    let scaled = DMatrix::from_fn(x.nrows(), n_columns, |row, col| x[(row, col)] / scale[col]);
    let beta = scaled.svd(true, true).solve(&y, 1e-12).ok()?;
    let corrected: Vec<f64> = heldout
        .residual
        .iter()
        .enumerate()
        .map(|(sample, residual)| {
            let row = &heldout.rows[sample * n_columns..(sample + 1) * n_columns];
            residual - row.iter().zip(&scale).zip(beta.iter()).map(|((v, s), b)| v / s * b).sum::<f64>()
        })
        .collect();
    Some(PressureInformationRow {
        alpha_deg,
        egk_rms: rms(&heldout.residual),
        fused_rms: rms(&heldout.fused_residual),
        best_linear_rms: rms(&corrected),
        n_columns,
    })
}

/// Regression rows (row-major) and targets.
#[derive(Default)]
struct Samples {
    rows: Vec<f64>,
    residual: Vec<f64>,
    fused_residual: Vec<f64>,
}

impl Samples {
    fn push(&mut self, row: Vec<f64>, residual: f64, fused_residual: f64) {
        self.rows.extend(row);
        self.residual.push(residual);
        self.fused_residual.push(fused_residual);
    }
}

/// Causal first-order low-pass `y[k] = p y[k-1] + (1 - p) u[k]`, `p = exp(-1 / (tau f_s))`,
/// started at the first value.
fn lowpass(values: &[f64], tau_s: f64, sample_hz: f64) -> Vec<f64> {
    let pole = (-1.0 / (tau_s * sample_hz)).exp();
    let mut state = values.first().copied().unwrap_or(0.0);
    values
        .iter()
        .map(|&value| {
            state = pole * state + (1.0 - pole) * value;
            state
        })
        .collect()
}

fn rms(values: &[f64]) -> f64 {
    stats::rms(values).unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lowpass_settles_to_a_step_and_holds_missing_samples() {
        let step = vec![1.0; 2000];
        let filtered = lowpass(&step, 0.01, 1000.0);
        assert!((filtered[1999] - 1.0).abs() < 1e-12);
        assert_eq!(hold_missing(&[f64::NAN, 2.0, f64::NAN, 3.0], 0.0), vec![0.0, 2.0, 2.0, 3.0]);
    }
}
