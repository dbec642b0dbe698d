//! The estimate envelope (`estimator_core::coeffs::Envelope`): the range of
//! roll moments the balance measured over the training part of the runs, the disturbance alone
//! in the roll runs and the total in every run. The core keeps its estimates within it, widened
//! by `estimator_core::coeffs::ENVELOPE_MARGIN` of its span on each side.

use estimator_core::blob::ENVELOPE_LIMIT;
use estimator_core::coeffs::{ENVELOPE_MARGIN, Envelope};
use firmware_sim::dataset::{Dataset, RunKind};
use serde::Serialize;

use super::split::Split;

/// The envelope and the bounds the core applies.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnvelopeFit {
    /// Measured `[lowest, highest]` balance `C_l` of the roll runs.
    pub cl_roll: [f64; 2],
    /// Measured `[lowest, highest]` balance `C_l` of every run.
    pub cl: [f64; 2],
    /// The margin, as a share of each range's span on each side.
    pub margin: f64,
    /// The bounds of `C_l,roll` the core applies (range and margin).
    pub cl_roll_bounds: [f64; 2],
    /// The bounds of `C_l,linear` and `C_l` the core applies.
    pub cl_bounds: [f64; 2],
}

impl EnvelopeFit {
    /// The core's table.
    #[must_use]
    pub fn envelope(&self) -> Envelope {
        Envelope { cl_roll: self.cl_roll.map(|value| value as f32), cl: self.cl.map(|value| value as f32) }
    }
}

/// The balance's range over the training part of the runs (of the roll runs for `cl_roll`),
/// limited to `+-ENVELOPE_LIMIT` (noted when it had to be); a dataset without a finite balance
/// sample keeps the prior's `fallback`.
#[must_use]
pub fn fit_envelope(dataset: &Dataset, split: &Split, fallback: &Envelope, notes: &mut Vec<String>) -> EnvelopeFit {
    let range = |roll_only: bool, fallback: [f32; 2]| {
        let (low, high) = dataset
            .runs
            .iter()
            .filter(|run| !roll_only || run.meta.kind == RunKind::Roll)
            .flat_map(|run| &run.channels.cl[split.training(run.channels.len())])
            .filter(|cl| cl.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(low, high), &cl| (low.min(cl), high.max(cl)));
        if low > high {
            return fallback.map(f64::from);
        }
        let limit = f64::from(ENVELOPE_LIMIT);
        [low.max(-limit), high.min(limit)]
    };
    let (cl_roll, cl) = (range(true, fallback.cl_roll), range(false, fallback.cl));
    if cl.iter().any(|value| value.abs() >= f64::from(ENVELOPE_LIMIT)) {
        notes.push(format!("the balance reaches |C_l| {ENVELOPE_LIMIT} or more: the envelope is limited to it"));
    }
    let bounds = |range: [f64; 2]| {
        let bounds = Envelope::with_margin(range.map(|value| value as f32));
        bounds.map(f64::from)
    };
    EnvelopeFit {
        cl_roll,
        cl,
        margin: f64::from(ENVELOPE_MARGIN),
        cl_roll_bounds: bounds(cl_roll),
        cl_bounds: bounds(cl),
    }
}
