//! Where and how much a pressure-channel fault acts in each run (the `pressure_fault` family,
//! docs/spec/diagnosis.md: "one channel stuck, dead (missing), biased, drifting, with a wrong
//! gain, with extra noise, or spiking ..., from the start of a run or from any moment in it";
//! docs/diagnosis.md, Pressure faults).
//!
//! A stuck (or flat-dead) channel is scanned for an interval per run ([`scan`]): it stops
//! following the pressure and reads a constant with its transducer's noise, so over the interval
//! the innovation is that constant less the filter's expectation of the channel: it regresses on
//! the expectation with a slope near -1 (a live channel: near 0), and the reading, smoothed,
//! stays flat where the expectation moves. Flatness is what tells a stuck channel from one with
//! a wrong gain (its innovation too regresses on the expectation, but its reading still follows
//! the pressure). Bit-identical repeats are the noise-free case of the same shape.
//!
//! A bias, a drift and a wrong gain ([`Form`], [`fit_shared`]) are one value of the channel for
//! every run, from an onset of each run's own (or none) to the run's end; extra noise
//! ([`fit_noise`]) is a variance ratio test with one added variance.

use super::regression::{self, Segment};
use super::streams::RunStreams;

mod noise;
mod shared;
mod stuck;

pub use noise::*;
pub use shared::*;
pub use stuck::*;

/// Fewest samples after an onset.
const MIN_FAULTY_SAMPLES: usize = 10;

/// How far a run's own level may lie from the shared one and still be the same fault: within a
/// factor of this either way. A biased channel's runs agree on its one offset up to the model's
/// own error; a level of its own in each run (the pressure model's per-run error) does not.
const AGREEMENT_FACTOR: f64 = 2.0;

/// Interval ends scanned per run: this many cells, evenly spaced over the run; an interval is
/// any run of whole cells.
const GRID: usize = 40;

/// Evidence a run needs for its own interval (BIC, with the choice of the interval paid for).
const MIN_RUN_DELTA_BIC: f64 = 10.0;

/// The filter's one-step expectation of the channel (reading less innovation).
fn expectation(run: &RunStreams, tap: usize) -> Vec<f64> {
    run.cp[tap].iter().zip(&run.innovation[tap]).map(|(cp, nu)| cp - nu).collect()
}

fn mean_of(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.filter(|v| v.is_finite()).fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// A centred moving average of `half` samples each side over the finite values (NaN where the
/// window holds none).
fn moving_average(values: &[f64], half: usize) -> Vec<f64> {
    let (mut sum, mut count) = (vec![0.0; values.len() + 1], vec![0usize; values.len() + 1]);
    for (i, v) in values.iter().enumerate() {
        let finite = v.is_finite();
        sum[i + 1] = sum[i] + if finite { *v } else { 0.0 };
        count[i + 1] = count[i] + usize::from(finite);
    }
    (0..values.len())
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(values.len()));
            let n = count[hi] - count[lo];
            if n == 0 { f64::NAN } else { (sum[hi] - sum[lo]) / n as f64 }
        })
        .collect()
}

/// Segments of one channel's innovation (for the fit of the fault's columns).
#[must_use]
pub fn segments_of(runs: &[RunStreams], tap: usize) -> Vec<Segment<'_>> {
    segments_over(runs, |run| &run.innovation[tap])
}

/// Segments of one stream of every run (`stream(run)`), with each run's split.
pub fn segments_over<'a>(runs: &'a [RunStreams], stream: impl Fn(&'a RunStreams) -> &'a [f64]) -> Vec<Segment<'a>> {
    segments_with(runs, runs.iter().map(stream))
}

/// Segments of the given streams, one per run in order, with each run's split.
pub fn segments_with<'a>(runs: &'a [RunStreams], streams: impl IntoIterator<Item = &'a [f64]>) -> Vec<Segment<'a>> {
    runs.iter()
        .zip(streams)
        .map(|(run, residual)| Segment {
            residual,
            training: run.training.clone(),
            select: run.select,
            heldout: run.heldout.clone(),
        })
        .collect()
}

/// The stream the shared forms are judged on: the channel's innovation from the filter run
/// without it, the reading less what the other channels expect of it, beyond its mean on the
/// sim's own recording ([`RunStreams::departure_alone`]). The filter's modes follow every
/// channel that corrects them, so a channel's own innovation shows only part of a slow
/// departure (a bias, a drift, a wrong gain); the others' expectation does not move with it,
/// and the departure shows whole.
fn judged(run: &RunStreams, tap: usize) -> &[f64] {
    &run.departure_alone[tap]
}

/// What the other channels expect of the channel at sample `i`: the reading less its
/// innovation from the filter run without it.
fn expected(run: &RunStreams, tap: usize, i: usize) -> f64 {
    run.cp[tap][i] - run.innovation_alone[tap][i]
}

#[cfg(test)]
mod tests;
