//! Which pressure channels a lag concerns, and each one's time constant (docs/diagnosis.md,
//! Pressure lag; docs/spec/diagnosis.md: a lag "of any non-empty set of pressure channels,
//! from one to all twelve, ... the same for every lagged channel or different per channel").
//!
//! Each channel is judged on what the other channels expect of it, the others read through
//! their current de-lag: `p = y + tau y'` inverts a first-order lag exactly, so once every
//! other channel is de-lagged by its own time constant, the filter without a channel expects
//! the true pressure `p` of it, and the channel's innovation with its own estimate `l` applied
//! is `nu = y + l y' - p = -(tau - l) y'`. The slope of the innovation on the reading's falling
//! derivative is what is left of the lag, exactly (a Newton step); the estimates are moved by
//! it until they hold. A healthy channel de-lagged by mistake reads early (`+l y'`) and its
//! estimate returns to zero; so the set needs no search over subsets, and the same step serves
//! a lag of one channel, of a group or of every channel. Without the others de-lagged (the
//! filter without a group of channels, [`super::sensor`]), a large group leaves too few
//! channels to expect anything, and its lag hides in what the healthy ones expect.

use super::streams::RunStreams;

/// Most passes of the de-lag and re-judge step.
const MAX_PASSES: usize = 10;

/// A pass that moves no estimate by more than this ends the search, s (a tenth of the
/// contract's shortest lag).
const SETTLED_S: f64 = 0.5e-3;

/// Each channel's lag relative to the others, and its standard error.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChannelLags {
    /// Per channel, its lag less the mean over the channels, s: the innovations see only how
    /// the channels' lags differ, so a lag common to all of them is the balance's to tell.
    pub relative_s: Vec<f64>,
    /// Per channel, the standard error of its relative lag, s: the jackknife over the runs of the
    /// last step (the pressure model's error moves a channel's apparent lag with the excitation,
    /// run to run, beyond the step's own regression error).
    pub standard_error_s: Vec<f64>,
    /// Per channel, the first step alone (judged on the recording's own innovations, no de-lag),
    /// s: cheap, since the streams hold those innovations, so it tells whether the full search
    /// is worth running ([`first_step`]).
    #[serde(default)]
    pub first_step_s: Vec<f64>,
}

/// The first step of [`identify`] alone, per channel (mean over the channels taken out, 0 for
/// a channel without usable samples), s.
#[must_use]
pub fn first_step(runs: &[RunStreams]) -> Vec<f64> {
    let Some(n_taps) = runs.first().map(|run| run.cp.len()) else { return Vec::new() };
    centred_steps(&slope_sums(runs, &vec![0.0; n_taps]).0, None).into_iter().map(|v| v.unwrap_or(0.0)).collect()
}

/// Per channel, the step of the pooled sums (the run `left_out` left out), less the mean step
/// over the channels (a common step is no evidence: the innovations see only differences).
fn centred_steps(sums: &[Vec<(f64, f64)>], left_out: Option<usize>) -> Vec<Option<f64>> {
    let n_taps = sums.first().map_or(0, Vec::len);
    let steps: Vec<Option<f64>> = (0..n_taps)
        .map(|tap| slope(sums.iter().enumerate().filter(|(idx, _)| Some(*idx) != left_out).map(|(_, run)| run[tap])))
        .collect();
    let known: Vec<f64> = steps.iter().flatten().copied().collect();
    let common_s = known.iter().sum::<f64>() / known.len().max(1) as f64;
    steps.into_iter().map(|step| step.map(|v| v - common_s)).collect()
}

/// Per run, per channel: the channel's innovation from the filter without it, the other
/// channels read through their de-lag and the channel itself as recorded (its whole lag shows).
pub type Judged = Vec<Vec<Vec<f64>>>;

/// Every channel judged with the others de-lagged by `lag_s` (s, per channel; 0 for a healthy
/// one): where a set's lag is measured, since what the others expect is then the true pressure.
#[must_use]
pub fn judged(runs: &[RunStreams], lag_s: &[f64]) -> Judged {
    slope_sums(runs, lag_s).1
}

/// Every channel's lag relative to the others, by repeated de-lag and re-judge steps from none;
/// `None` without usable channels or with fewer than three runs (no jackknife). Slopes are
/// fitted on the training samples less the selection blocks only.
#[must_use]
pub fn identify(runs: &[RunStreams]) -> Option<ChannelLags> {
    let n_taps = runs.first()?.cp.len();
    if n_taps < 2 || runs.len() < 3 {
        return None;
    }
    let mut relative_s = vec![0.0; n_taps];
    let mut sums = Vec::new();
    let mut first_step_s = Vec::new();
    for _ in 0..MAX_PASSES {
        (sums, _) = slope_sums(runs, &relative_s);
        let steps = centred_steps(&sums, None);
        if first_step_s.is_empty() {
            first_step_s = steps.iter().map(|v| v.unwrap_or(0.0)).collect();
        }
        let mut largest = 0.0f64;
        for (tap, step) in steps.iter().enumerate() {
            let Some(delta_s) = *step else { continue };
            relative_s[tap] += delta_s;
            largest = largest.max(delta_s.abs());
        }
        if largest < SETTLED_S {
            break;
        }
    }
    // The jackknife of the last step (Efron & Tibshirani, An Introduction to the Bootstrap,
    // 1993, ch. 11), each run left out in turn.
    let n_runs = sums.len();
    let left_out: Vec<Vec<Option<f64>>> = (0..n_runs).map(|out| centred_steps(&sums, Some(out))).collect();
    let n = n_runs as f64;
    let standard_error_s = (0..n_taps)
        .map(|tap| {
            let values: Vec<f64> = left_out.iter().filter_map(|run| run[tap]).collect();
            if values.len() < 3 {
                return f64::INFINITY;
            }
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            ((n - 1.0) / n * values.iter().map(|v| (v - mean).powi(2)).sum::<f64>()).sqrt()
        })
        .collect();
    Some(ChannelLags { relative_s, standard_error_s, first_step_s })
}

/// The slope of the innovation on the reading's falling derivative from per-run sums
/// `(sum x nu, sum x^2)`; `None` without any regressor.
fn slope(sums: impl Iterator<Item = (f64, f64)>) -> Option<f64> {
    let (xy, xx) = sums.fold((0.0, 0.0), |acc, (xy, xx)| (acc.0 + xy, acc.1 + xx));
    (xx > 0.0).then(|| xy / xx)
}

/// Per run, per channel, with every channel de-lagged by `lag_s` (s): the sums `(sum x nu,
/// sum x^2)` over the fit samples of the channel's innovation from the filter without it, `nu`,
/// and the reading's falling derivative, `x = -dy/dt` ([`RunStreams::cp_dot`]), each centred
/// per run (the innovation's level is a bias, not a lag): their ratio is what is left of the
/// channel's lag. And the innovations with each channel's own de-lag taken back ([`Judged`]).
fn slope_sums(runs: &[RunStreams], lag_s: &[f64]) -> (Vec<Vec<(f64, f64)>>, Judged) {
    let n_taps = lag_s.len();
    runs.iter()
        .map(|run| {
            let corrected: Vec<Vec<f64>> = (0..n_taps)
                .map(|tap| run.cp[tap].iter().zip(&run.cp_dot[tap]).map(|(y, dy)| y + lag_s[tap] * dy).collect())
                .collect();
            // Without a de-lag the readings are the recording's, judged as the streams already were.
            let innovations = if lag_s.iter().all(|lag| *lag == 0.0) {
                run.innovation_alone.clone()
            } else {
                run.innovations_alone_on(&corrected)
            };
            let samples: Vec<usize> = run.fit_samples().collect();
            let sums = (0..n_taps)
                .map(|tap| {
                    let pairs: Vec<(f64, f64)> = samples
                        .iter()
                        .map(|&idx| (innovations[tap][idx], -run.cp_dot[tap][idx]))
                        .filter(|(nu, x)| nu.is_finite() && x.is_finite())
                        .collect();
                    if pairs.len() < 2 {
                        return (0.0, 0.0);
                    }
                    let count = pairs.len() as f64;
                    let mean_nu = pairs.iter().map(|p| p.0).sum::<f64>() / count;
                    let mean_x = pairs.iter().map(|p| p.1).sum::<f64>() / count;
                    pairs.iter().fold((0.0, 0.0), |acc, (nu, x)| {
                        (acc.0 + (x - mean_x) * (nu - mean_nu), acc.1 + (x - mean_x) * (x - mean_x))
                    })
                })
                .collect();
            // The filter without a channel does not read it, so taking its own de-lag back off
            // its innovation is exact.
            let judged = innovations
                .iter()
                .zip(&run.cp_dot)
                .zip(lag_s)
                .map(|((nu, dy), lag)| nu.iter().zip(dy).map(|(v, d)| v - lag * d).collect())
                .collect();
            (sums, judged)
        })
        .unzip()
}
