//! Held-out evaluation: every run is replayed through the fitted core (estimator-core, f32,
//! the code that flies) from its first sample, and the errors are scored on the held-out part
//! only, per block and angle of attack.
//!
//! The balance's noise floor is estimated from the data: for white noise on a smooth signal
//! sampled fast, first differences have twice the noise variance; the median absolute
//! deviation makes the estimate robust to the signal's own jumps (Hampel 1974).

use estimator_core::{CoefficientSet, Output};
use firmware_sim::dataset::{Dataset, RunKind};
use rayon::prelude::*;
use serde::Serialize;

use super::split::Split;
use crate::replay::replay_run;

/// Held-out errors at one angle of attack (RMS in C_l; `None` without runs of that kind).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HeldoutAlpha {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// Roll runs: the eGK alone.
    pub egk_rms: Option<f64>,
    /// Roll runs: the pressure path alone.
    pub pressure_rms: Option<f64>,
    /// Roll runs: the fused disturbance estimate.
    pub fused_rms: Option<f64>,
    /// Actuation runs: the plant (`C_l,AFC`) against the balance.
    pub plant_rms: Option<f64>,
    /// Roll+actuation runs: the linear superposition (the paper's `E_lin`, as an RMS).
    pub linear_rms: Option<f64>,
    /// Roll+actuation runs: with the coupling operator (`E_SINDy`, as an RMS).
    pub coupled_rms: Option<f64>,
    /// `E_SINDy / E_lin` (paper Table 2).
    pub coupling_ratio: Option<f64>,
    /// Estimated white-noise RMS of the balance on these runs.
    pub noise_rms: Option<f64>,
}

impl HeldoutAlpha {
    /// Column names of [`HeldoutAlpha::cells`].
    pub const COLUMNS: [&'static str; 9] =
        ["alpha_deg", "eGK", "pressure path", "fused", "plant", "linear", "coupled", "E_SINDy/E_lin", "balance noise"];

    /// The row as text cells (RMS in scientific notation, `-` where there were no runs).
    #[must_use]
    pub fn cells(&self) -> [String; 9] {
        let cell = |value: Option<f64>| value.map_or("-".to_owned(), |v| format!("{v:.3e}"));
        [
            format!("{}", self.alpha_deg),
            cell(self.egk_rms),
            cell(self.pressure_rms),
            cell(self.fused_rms),
            cell(self.plant_rms),
            cell(self.linear_rms),
            cell(self.coupled_rms),
            self.coupling_ratio.map_or("-".to_owned(), |ratio| format!("{ratio:.3}")),
            cell(self.noise_rms),
        ]
    }
}

/// Held-out errors of a fitted set.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HeldoutReport {
    /// Per angle of attack, ascending.
    pub per_alpha: Vec<HeldoutAlpha>,
}

/// Replays every run and scores its held-out part.
#[must_use]
pub fn evaluate_heldout(dataset: &Dataset, set: &CoefficientSet, split: &Split) -> HeldoutReport {
    let outputs: Vec<Vec<Output>> = dataset.runs.par_iter().map(|run| replay_run(set, run)).collect();
    let per_alpha = dataset
        .alphas_deg()
        .into_iter()
        .map(|alpha_deg| {
            let at = |kind: RunKind| -> Vec<usize> {
                (0..dataset.runs.len())
                    .filter(|&idx| {
                        dataset.runs[idx].meta.kind == kind
                            && (dataset.runs[idx].meta.alpha_deg - alpha_deg).abs() < 1e-6
                    })
                    .collect()
            };
            let score = |runs: &[usize], pick: &dyn Fn(&Output) -> f32| -> Option<f64> {
                rms_error(dataset, &outputs, runs, split, pick)
            };
            let (roll, act, both) = (at(RunKind::Roll), at(RunKind::Actuation), at(RunKind::RollActuation));
            let linear_rms = score(&both, &|o| o.cl_linear);
            let coupled_rms = score(&both, &|o| o.cl);
            let all: Vec<usize> = roll.iter().chain(&act).chain(&both).copied().collect();
            HeldoutAlpha {
                alpha_deg,
                egk_rms: score(&roll, &|o| o.cl_egk),
                pressure_rms: score(&roll, &|o| o.cl_pressure),
                fused_rms: score(&roll, &|o| o.cl_roll),
                plant_rms: score(&act, &|o| o.cl_afc),
                linear_rms,
                coupled_rms,
                coupling_ratio: linear_rms.zip(coupled_rms).map(|(lin, cou)| cou / lin),
                noise_rms: noise_rms(dataset, &all, split),
            }
        })
        .collect();
    HeldoutReport { per_alpha }
}

fn rms_error(
    dataset: &Dataset,
    outputs: &[Vec<Output>],
    runs: &[usize],
    split: &Split,
    pick: &dyn Fn(&Output) -> f32,
) -> Option<f64> {
    let (mut sum, mut count) = (0.0, 0usize);
    for &idx in runs {
        let cl = &dataset.runs[idx].channels.cl;
        for k in split.heldout(cl.len()) {
            let estimate = f64::from(pick(&outputs[idx][k]));
            if cl[k].is_finite() && estimate.is_finite() {
                sum += (estimate - cl[k]).powi(2);
                count += 1;
            }
        }
    }
    (count > 0).then(|| (sum / count as f64).sqrt())
}

/// Robust white-noise RMS of the balance from first differences of the held-out samples.
#[must_use]
pub fn noise_rms(dataset: &Dataset, runs: &[usize], split: &Split) -> Option<f64> {
    let mut differences: Vec<f64> = Vec::new();
    for &idx in runs {
        let cl = &dataset.runs[idx].channels.cl;
        let range = split.heldout(cl.len());
        differences.extend(cl[range].windows(2).map(|pair| pair[1] - pair[0]).filter(|d| d.is_finite()));
    }
    white_noise_rms(differences)
}

/// Robust white-noise RMS of a signal from its first differences (at least 10 of them).
#[must_use]
pub fn white_noise_rms(mut differences: Vec<f64>) -> Option<f64> {
    if differences.len() < 10 {
        return None;
    }
    let median = stats::median(&mut differences)?;
    let mut deviations: Vec<f64> = differences.iter().map(|d| (d - median).abs()).collect();
    Some(stats::MAD_TO_STD * stats::median(&mut deviations)? / std::f64::consts::SQRT_2)
}
