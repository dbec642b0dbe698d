//! Validity of superposition (paper section IV, Table 1): how far the roll+actuation moment
//! departs from the sum of the roll-only and actuation-only moments,
//! `Delta C_l = C_l,RollAFC - C_l,Roll - C_l,AFC`, formed sample by sample from runs that share
//! their roll and blowing sequences.

use firmware_sim::dataset::{Dataset, Run, RunKind};
use serde::Serialize;

/// Why the superposition difference cannot be formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SuperpositionError {
    /// The dataset lacks a run of this kind at this angle of attack.
    #[error(
        "no \"{kind}\" run at alpha = {alpha_deg} deg: Table 1 needs roll, actuation and roll+actuation runs at the same alpha"
    )]
    MissingRun {
        /// The missing kind.
        kind: RunKind,
        /// The angle of attack, deg.
        alpha_deg: f64,
    },
    /// The three runs at one alpha do not have the same samples.
    #[error(
        "runs at alpha = {alpha_deg} deg have {lengths:?} samples: the superposition difference needs runs of equal length recorded with the same inputs"
    )]
    LengthMismatch {
        /// The angle of attack, deg.
        alpha_deg: f64,
        /// Sample counts of the roll, actuation and roll+actuation runs.
        lengths: [usize; 3],
    },
    /// No angle of attack has the three kinds of run.
    #[error("the dataset has no angle of attack with roll, actuation and roll+actuation runs")]
    NoTriple,
}

/// Table 1 at one angle of attack.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SuperpositionRow {
    /// Angle of attack, deg.
    pub alpha_deg: f64,
    /// `sigma(Delta C_l) / |mean(C_l,RollAFC)|`, the paper's Table 1 quantity.
    pub ratio_to_mean: f64,
    /// `sigma(Delta C_l) / sigma(C_l,RollAFC)`, which stays meaningful when the mean is small.
    pub ratio_to_std: f64,
    /// `sigma(Delta C_l)`.
    pub delta_std: f64,
    /// `mean(C_l,RollAFC)`.
    pub rollact_mean: f64,
    /// Number of samples where all three moments were measured.
    pub n_samples: usize,
}

/// Table 1 for every angle of attack that has the three kinds of run, ascending in alpha.
pub fn superposition_table(dataset: &Dataset) -> Result<Vec<SuperpositionRow>, SuperpositionError> {
    let mut rows = Vec::new();
    for alpha_deg in dataset.alphas_deg() {
        match superposition_at(dataset, alpha_deg) {
            Ok(row) => rows.push(row),
            Err(SuperpositionError::MissingRun { .. }) => continue,
            Err(error) => return Err(error),
        }
    }
    if rows.is_empty() {
        return Err(SuperpositionError::NoTriple);
    }
    Ok(rows)
}

/// Table 1 at one angle of attack (the first run of each kind there), on every sample.
pub fn superposition_at(dataset: &Dataset, alpha_deg: f64) -> Result<SuperpositionRow, SuperpositionError> {
    superposition_over(dataset, alpha_deg, &|n_samples| 0..n_samples)
}

/// Table 1 at one angle of attack on the samples `samples(n)` of runs of `n` samples (for
/// instance the held-out part).
pub fn superposition_over(
    dataset: &Dataset,
    alpha_deg: f64,
    samples: &dyn Fn(usize) -> std::ops::Range<usize>,
) -> Result<SuperpositionRow, SuperpositionError> {
    let find = |kind| dataset.runs_of(kind, alpha_deg).next().ok_or(SuperpositionError::MissingRun { kind, alpha_deg });
    let (roll, actuation, both) = (find(RunKind::Roll)?, find(RunKind::Actuation)?, find(RunKind::RollActuation)?);
    let lengths = [roll, actuation, both].map(|run: &Run| run.channels.len());
    if lengths[0] != lengths[1] || lengths[1] != lengths[2] {
        return Err(SuperpositionError::LengthMismatch { alpha_deg, lengths });
    }
    let (mut delta, mut rollact) = (Vec::new(), Vec::new());
    for sample_idx in samples(lengths[0]) {
        let (r, a, ra) =
            (roll.channels.cl[sample_idx], actuation.channels.cl[sample_idx], both.channels.cl[sample_idx]);
        if r.is_finite() && a.is_finite() && ra.is_finite() {
            delta.push(ra - r - a);
            rollact.push(ra);
        }
    }
    let delta_std = std_dev(&delta);
    let rollact_mean = mean(&rollact);
    Ok(SuperpositionRow {
        alpha_deg,
        ratio_to_mean: delta_std / rollact_mean.abs(),
        ratio_to_std: delta_std / std_dev(&rollact),
        delta_std,
        rollact_mean,
        n_samples: delta.len(),
    })
}

fn mean(values: &[f64]) -> f64 {
    stats::mean(values).unwrap_or(f64::NAN)
}

fn std_dev(values: &[f64]) -> f64 {
    stats::population_std_dev(values).unwrap_or(f64::NAN)
}
