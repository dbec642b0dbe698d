//! The training/held-out split of a dataset: the final part of every run is held out and never
//! used for fitting or for choosing a model, so each block is fitted on the same excitation it
//! is tested on later, but on samples it has not seen. The sparse models' structure (threshold,
//! slow pole) is chosen on a validation part, the end of the training part, and their
//! coefficients are then refitted on the whole training part (the usual train/validation/test
//! protocol; Hastie, Tibshirani & Friedman, The Elements of Statistical Learning, section 7.2),
//! so the held-out figures are not biased by the selection.

use std::ops::Range;

use firmware_sim::dataset::{Dataset, Run, RunKind};

/// Default held-out share of every run (the final 20 %).
pub const DEFAULT_HOLDOUT_FRACTION: f64 = 0.2;
/// Default validation share of the training part (its final 20 %, 16 % of a run by default).
pub const DEFAULT_VALIDATION_FRACTION: f64 = 0.2;

/// Where each run is split.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Split {
    /// Share of every run, at its end, that is held out (0..1).
    pub holdout_fraction: f64,
    /// Share of the training part, at its end, on which model structure is chosen (0..1).
    pub validation_fraction: f64,
}

impl Default for Split {
    fn default() -> Self {
        Self { holdout_fraction: DEFAULT_HOLDOUT_FRACTION, validation_fraction: DEFAULT_VALIDATION_FRACTION }
    }
}

impl Split {
    /// The default split with `holdout_fraction` held out.
    #[must_use]
    pub fn with_holdout(holdout_fraction: f64) -> Self {
        Self { holdout_fraction, ..Self::default() }
    }

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

    /// The training samples the sparse models' candidates are fitted on while their structure is
    /// chosen: the training part less its validation part.
    #[must_use]
    pub fn fitting(&self, n_samples: usize) -> Range<usize> {
        0..self.validation_start(n_samples)
    }

    /// The training samples the sparse models' structure is chosen on: the training part's end.
    #[must_use]
    pub fn validation(&self, n_samples: usize) -> Range<usize> {
        self.validation_start(n_samples)..self.boundary(n_samples)
    }

    fn validation_start(&self, n_samples: usize) -> usize {
        let training = self.boundary(n_samples);
        let kept = (1.0 - self.validation_fraction.clamp(0.0, 1.0)) * training as f64;
        (kept.round() as usize).min(training)
    }

    fn boundary(&self, n_samples: usize) -> usize {
        let kept = (1.0 - self.holdout_fraction.clamp(0.0, 1.0)) * n_samples as f64;
        (kept.round() as usize).min(n_samples)
    }

    /// A one-line description for reports.
    #[must_use]
    pub fn describe(&self) -> String {
        format!(
            "training: the first {:.0} % of every run (the sparse models' structure chosen on its final {:.0} %, \
             then refitted on all of it); held out: the final {:.0} %, never used for fitting or selection",
            100.0 * (1.0 - self.holdout_fraction),
            100.0 * self.validation_fraction,
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
        assert_eq!(split.fitting(50_000), 0..32_000);
        assert_eq!(split.validation(50_000), 32_000..40_000);
        assert_eq!(split.validation(0), 0..0);
    }
}
