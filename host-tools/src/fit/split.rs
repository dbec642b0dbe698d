//! The training/held-out split of a dataset: the final part of every run is held out and never
//! used for fitting, so each block is fitted on the same excitation it is tested on later, but
//! on samples it has not seen.

use std::ops::Range;

use firmware_sim::dataset::{Dataset, Run, RunKind};

/// Default held-out share of every run (the final 20 %).
pub const DEFAULT_HOLDOUT_FRACTION: f64 = 0.2;

/// Where each run is split.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Split {
    /// Share of every run, at its end, that is held out (0..1).
    pub holdout_fraction: f64,
}

impl Default for Split {
    fn default() -> Self {
        Self { holdout_fraction: DEFAULT_HOLDOUT_FRACTION }
    }
}

impl Split {
    /// The training samples of a run of `n_samples`: the first `1 - holdout_fraction`.
    #[must_use]
    pub fn training(&self, n_samples: usize) -> Range<usize> {
        0..self.boundary(n_samples)
    }

    /// The held-out samples of a run of `n_samples`: the rest.
    #[must_use]
    pub fn heldout(&self, n_samples: usize) -> Range<usize> {
        self.boundary(n_samples)..n_samples
    }

    fn boundary(&self, n_samples: usize) -> usize {
        let kept = (1.0 - self.holdout_fraction.clamp(0.0, 1.0)) * n_samples as f64;
        (kept.round() as usize).min(n_samples)
    }

    /// A one-line description for reports.
    #[must_use]
    pub fn describe(&self) -> String {
        format!(
            "training: the first {:.0} % of every run; held out: the final {:.0} %, never used for fitting",
            100.0 * (1.0 - self.holdout_fraction),
            100.0 * self.holdout_fraction
        )
    }
}

/// The runs of one kind, in manifest order.
pub fn runs_of_kind(dataset: &Dataset, kind: RunKind) -> impl Iterator<Item = &Run> {
    dataset.runs.iter().filter(move |run| run.meta.kind == kind)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_covers_every_sample_once() {
        let split = Split::default();
        assert_eq!(split.training(50_000), 0..40_000);
        assert_eq!(split.heldout(50_000), 40_000..50_000);
        assert_eq!(split.training(0), 0..0);
    }
}
