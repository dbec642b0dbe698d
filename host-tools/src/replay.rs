//! Replay of recorded channels through the estimator that flies: estimator-core's f32
//! [`Estimator`], stepped once per recorded sample, exactly as the firmware steps it.

use estimator_core::coeffs::N_TAPS;
use estimator_core::{CoefficientSet, Estimator, Input, Output};
use firmware_sim::dataset::Run;

/// The core's input at one recorded sample (f64 channels narrowed to f32; missing stays NaN).
#[must_use]
pub fn input_at(run: &Run, sample_idx: usize) -> Input {
    let channels = &run.channels;
    let narrow = |column: &[f64]| column.get(sample_idx).map_or(f32::NAN, |&value| value as f32);
    let cp: [f32; N_TAPS] = std::array::from_fn(|tap| narrow(&channels.cp[tap]));
    Input {
        phi_deg: narrow(&channels.phi_deg),
        alpha_deg: channels.alpha_at(sample_idx, run.meta.alpha_deg) as f32,
        cmu_port: narrow(&channels.cmu_port),
        cmu_stbd: narrow(&channels.cmu_stbd),
        cp,
    }
}

/// Steps a fresh estimator over every sample of `run`.
#[must_use]
pub fn replay_run(set: &CoefficientSet, run: &Run) -> Vec<Output> {
    let mut estimator = Estimator::new(set);
    (0..run.channels.len()).map(|sample_idx| estimator.step(&input_at(run, sample_idx))).collect()
}
