//! The onset of a pressure-channel fault in each run (the `pressure_fault` family, shared/spec/
//! diagnosis.md): a fault can start at any time, in any run, or be there from the start; each run
//! gets its own onset, or none, chosen on the training part by the evidence of the fault's
//! shape in that run alone.
//!
//! Two shapes are scanned. A bias adds a constant to the reading from its onset: the innovation's
//! mean steps. A stuck (or flat-dead) channel stops following the pressure and reads a constant
//! with its transducer's noise: from the onset the innovation is that constant less the filter's
//! expectation of the channel, so it regresses on the expectation with a slope near -1 (a live
//! channel: near 0). Bit-identical repeats are the noise-free case of the same shape.

use super::regression::{self, Segment};
use super::streams::RunStreams;

/// Onsets scanned per run: this many positions, evenly spaced over the run.
const ONSET_GRID: usize = 40;

/// Evidence a run needs for its own onset (BIC, with the choice of the onset paid for).
const MIN_RUN_DELTA_BIC: f64 = 10.0;

/// Slopes on the expectation that count as a reading that no longer follows the pressure (the
/// filter's own correction pulls the expectation a little towards the stuck reading).
const STUCK_SLOPE: (f64, f64) = (-1.5, -0.3);

/// The shape of a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// A constant added from the onset.
    Bias,
    /// A constant reading (with noise) from the onset.
    Stuck,
}

/// The scan's result: each run's onset (a sample index) or none, and the regression columns
/// (per run: the shared columns, then one step per run for a stuck reading's own level).
#[derive(Debug, Clone)]
pub struct Onsets {
    /// Per run, the first faulty sample.
    pub per_run: Vec<Option<usize>>,
    /// The columns of the fault for [`regression::fit_through_origin`].
    pub columns: Vec<Vec<Vec<f64>>>,
}

/// Scans every run of channel `tap` for the onset of `shape`; `tau` is the innovation's
/// integrated autocorrelation time (samples), for the effective number of samples.
#[must_use]
pub fn scan(runs: &[RunStreams], tap: usize, shape: Shape, tau: f64) -> Onsets {
    let per_run: Vec<Option<usize>> = runs.iter().map(|run| best_onset(run, tap, shape, tau)).collect();
    let n_runs = runs.len();
    let columns = runs
        .iter()
        .zip(&per_run)
        .enumerate()
        .map(|(run_idx, (run, onset))| {
            let n = run.len();
            let step: Vec<f64> = (0..n).map(|i| if onset.is_some_and(|k| i >= k) { 1.0 } else { 0.0 }).collect();
            match shape {
                Shape::Bias => vec![step],
                Shape::Stuck => {
                    let expected = expectation(run, tap);
                    let mean =
                        onset.map_or(0.0, |k| mean_of(run.fit_samples().filter(|&i| i >= k).map(|i| expected[i])));
                    let mut cols = vec![
                        (0..n)
                            .map(|i| {
                                if onset.is_some_and(|k| i >= k) && expected[i].is_finite() {
                                    expected[i] - mean
                                } else {
                                    0.0
                                }
                            })
                            .collect(),
                    ];
                    for slot in 0..n_runs {
                        cols.push(if slot == run_idx { step.clone() } else { vec![0.0; n] });
                    }
                    cols
                }
            }
        })
        .collect();
    Onsets { per_run, columns }
}

/// The filter's one-step expectation of the channel (reading less innovation).
fn expectation(run: &RunStreams, tap: usize) -> Vec<f64> {
    run.cp[tap].iter().zip(&run.innovation[tap]).map(|(cp, nu)| cp - nu).collect()
}

fn mean_of(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.filter(|v| v.is_finite()).fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}

/// The onset with the most evidence for `shape` in one run, if decisive.
fn best_onset(run: &RunStreams, tap: usize, shape: Shape, tau: f64) -> Option<usize> {
    let nu = &run.innovation[tap];
    let expected = expectation(run, tap);
    let samples: Vec<usize> = run.fit_samples().filter(|&i| nu[i].is_finite() && expected[i].is_finite()).collect();
    if samples.len() < 20 {
        return None;
    }
    let mean_all = mean_of(samples.iter().map(|&i| nu[i]));
    let ssr0: f64 = samples.iter().map(|&i| (nu[i] - mean_all).powi(2)).sum();
    if ssr0 <= 0.0 {
        return None;
    }
    let n_eff = samples.len() as f64 / tau.max(1.0);
    let mut best: Option<(usize, f64)> = None;
    for step in 0..ONSET_GRID {
        let onset = run.len() * step / ONSET_GRID;
        let post: Vec<usize> = samples.iter().copied().filter(|&i| i >= onset).collect();
        if post.len() < 10 {
            continue;
        }
        let gain = match shape {
            // The mean after the onset against the run's mean.
            Shape::Bias => {
                let pre: Vec<usize> = samples.iter().copied().filter(|&i| i < onset).collect();
                let (m_post, m_pre) = (mean_of(post.iter().map(|&i| nu[i])), mean_of(pre.iter().map(|&i| nu[i])));
                let (a, b) = (post.len() as f64, pre.len() as f64);
                if pre.is_empty() { a * m_post * m_post } else { a * b / (a + b) * (m_post - m_pre).powi(2) }
            }
            Shape::Stuck => {
                let (m_e, m_r) = (mean_of(post.iter().map(|&i| expected[i])), mean_of(post.iter().map(|&i| nu[i])));
                let (mut sxy, mut sxx) = (0.0, 0.0);
                for &i in &post {
                    let (x, y) = (expected[i] - m_e, nu[i] - m_r);
                    sxy += x * y;
                    sxx += x * x;
                }
                let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
                if slope < STUCK_SLOPE.0 || slope > STUCK_SLOPE.1 { 0.0 } else { sxy * sxy / sxx }
            }
        };
        if best.is_none_or(|(_, g)| gain > g) {
            best = Some((onset, gain));
        }
    }
    let (onset, gain) = best?;
    let remaining = (ssr0 - gain).max(f64::MIN_POSITIVE);
    let evidence = n_eff * (ssr0 / remaining).ln() - 2.0 * n_eff.ln() - (ONSET_GRID as f64).ln();
    (evidence >= MIN_RUN_DELTA_BIC).then_some(onset)
}

/// Segments of one channel's innovation (for the fit of the fault's columns).
#[must_use]
pub fn segments_of(runs: &[RunStreams], tap: usize) -> Vec<Segment<'_>> {
    runs.iter()
        .map(|run| Segment {
            residual: &run.innovation[tap],
            training: run.training.clone(),
            select: run.select,
            heldout: run.heldout.clone(),
        })
        .collect()
}

/// Whether a fitted stuck shape really stopped following the pressure (its shared slope).
#[must_use]
pub fn stuck_slope_holds(fit: &regression::Fit) -> bool {
    fit.beta.first().is_some_and(|slope| (STUCK_SLOPE.0..=STUCK_SLOPE.1).contains(slope))
}
