//! What a SIL comparison records: its results with where they came from, as `sil.json` holds
//! them. One type, so the command line's report and the Python package's sweep write the same
//! document.

use std::collections::BTreeMap;

use serde::Serialize;

use super::{Mode, SilResults, TunePoint};

/// What the metrics are taken on (the record's `metric`).
pub const METRIC: &str = "noise-free aerodynamic roll moment of the synthetic tunnel (cl_aero), after the warm-up";

/// How the results were produced, for the report's introduction and the record.
#[derive(Debug, Clone, PartialEq)]
pub struct SilContext {
    /// The coefficient set's source.
    pub model: String,
    /// The scenario's source (file or defaults) and overrides.
    pub scenario: String,
    /// The gain search, when it ran (best first), with its seed.
    pub tuning: Option<(u64, Vec<TunePoint>)>,
}

/// The gain search of a record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Tuning<'a> {
    /// Seed of the search's scenario.
    pub seed: u64,
    /// Every grid point, best first.
    pub points: &'a [TunePoint],
}

/// A SIL comparison with its context: every number of `sil.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SilRecord<'a> {
    /// The coefficient set's source.
    pub model: &'a str,
    /// The scenario's source and overrides.
    pub scenario: &'a str,
    /// What the metrics are taken on ([`METRIC`]).
    pub metric: &'static str,
    /// Every closed-loop run.
    pub results: &'a SilResults,
    /// Per alpha: `alpha_deg` and each mode's `1 - rms(mode) / rms(none)` (null when a run is
    /// missing or the uncontrolled moment is zero).
    pub rms_reduction: Vec<BTreeMap<&'static str, Option<f64>>>,
    /// The gain search, when it ran.
    pub tuning: Option<Tuning<'a>>,
}

impl<'a> SilRecord<'a> {
    /// The record of `results` produced as `context` says.
    #[must_use]
    pub fn new(results: &'a SilResults, context: &'a SilContext) -> Self {
        let rms_reduction = results
            .alphas_deg()
            .into_iter()
            .map(|alpha_deg| {
                let mut row = BTreeMap::from([("alpha_deg", Some(alpha_deg))]);
                for mode in Mode::ALL {
                    row.insert(mode.name(), results.reduction(alpha_deg, mode));
                }
                row
            })
            .collect();
        Self {
            model: &context.model,
            scenario: &context.scenario,
            metric: METRIC,
            results,
            rms_reduction,
            tuning: context.tuning.as_ref().map(|(seed, points)| Tuning { seed: *seed, points }),
        }
    }
}
