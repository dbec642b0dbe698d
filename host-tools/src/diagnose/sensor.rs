//! Sensor candidates, on the pressure filter's per-channel innovations (gap-diagnosis.md
//! sections 1.6 and 2.6): a tubing lag (the innovation follows `-tau dp/dt`, on every channel or
//! on some) and a faulty channel (stuck, dead, biased or spiking: one channel departs from the
//! other eleven). Gaps here are in Cp units.

use firmware_sim::effect::Effect;

use super::faults;
use super::regression::{self, Segment};
use super::streams::RunStreams;

/// Shortest run of identical raw readings that counts as a stuck channel, s: a live transducer
/// with any noise never repeats its reading this long.
const STUCK_MIN_S: f64 = 0.05;

/// Innovation beyond this many robust standard deviations is a spike.
const SPIKE_SIGMA: f64 = 6.0;

/// How many times the typical channel's lag evidence a channel's must be to stand out as lagged.
const STAND_OUT: f64 = 4.0;

/// Longest burst of consecutive spiking samples that still counts as spikes.
const SPIKE_MAX_BURST: usize = 5;

/// A sensor finding with its strength.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorFinding {
    /// [`Effect::PressureLag`] or [`Effect::PressureFault`].
    pub effect: Effect,
    /// Physical parameters.
    pub params: Vec<(String, ParamValue)>,
    /// The channel, for a single-channel finding (`cp07`).
    pub channel: Option<String>,
    /// Every channel the finding concerns (one for a fault; one, some or all for a lag).
    pub channels: Vec<String>,
    /// Mean square the finding explains per affected training sample, Cp^2.
    pub explained: f64,
    /// Noise variance of the affected channels' innovations, Cp^2.
    pub noise_var: f64,
    /// Evidence: `N_eff ln(SSR_0 / SSR) - k ln N_eff`.
    pub delta_bic: f64,
    /// Held-out gap before and after, Cp.
    pub heldout: regression::HeldoutGap,
    /// Gap on the selection part before and after, Cp (the decisions rest on it).
    pub selection: regression::HeldoutGap,
    /// One line of evidence for the report.
    pub evidence: String,
}

/// A parameter value: a number or a word (the fault mode).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    /// A number.
    Number(f64),
    /// A word.
    Text(String),
}

/// Name of channel `tap` (0-based) as in the dataset (`cp01`).
#[must_use]
pub fn channel_name(tap: usize) -> String {
    format!("cp{:02}", tap + 1)
}

/// Every sensor finding, strongest first. `reference_tau_s` is the sim's own alignment of the
/// taps with the balance ([`super::pressure_lag::finding`]).
#[must_use]
pub fn findings(runs: &[RunStreams], reference_tau_s: f64) -> Vec<SensorFinding> {
    let n_taps = runs.first().map_or(0, |run| run.cp.len());
    let mut out = Vec::new();
    if n_taps == 0 {
        return out;
    }
    out.extend(super::pressure_lag::finding(runs, reference_tau_s));
    out.extend(lag_findings(runs, n_taps));
    out.extend((0..n_taps).filter_map(|tap| fault_finding(runs, tap, n_taps)));
    out.sort_by(|a, b| strength(b).total_cmp(&strength(a)));
    out
}

impl SensorFinding {
    /// Its key in the sim's signature: the name and its channels (`pressure_lag:cp03+cp07`).
    #[must_use]
    pub fn floor_key(&self) -> String {
        format!("{}:{}", self.effect, self.channels.join("+"))
    }
}

/// Strength of a finding in noise units: explained mean square over the noise variance.
#[must_use]
pub fn strength(finding: &SensorFinding) -> f64 {
    if finding.noise_var > 0.0 { finding.explained / finding.noise_var } else { 0.0 }
}

use faults::segments_of;

/// Time constants of the lag candidate, s: a log grid from two samples to half a second.
fn lag_grid(sample_hz: f64) -> Vec<f64> {
    super::candidates::log_grid(2.0 / sample_hz, 0.5, 28)
}

/// The lag column of one channel: `LP_tau[expected] - expected`, with `expected` the filter's
/// one-step expectation of the channel (measured minus innovation): a lagged sensor reads the
/// expected pressure through its lag (gap-diagnosis.md section 2.6, the first-order form).
fn lag_column(run: &RunStreams, tap: usize, tau_s: f64) -> Vec<f64> {
    let expected: Vec<f64> = run.cp[tap].iter().zip(&run.innovation[tap]).map(|(cp, nu)| cp - nu).collect();
    let held =
        crate::fit::signals::hold_missing(&expected, expected.iter().copied().find(|v| v.is_finite()).unwrap_or(0.0));
    let lagged = super::candidates::first_order_lag(&held, tau_s, 1.0 / run.sample_hz);
    lagged.iter().zip(&held).map(|(l, e)| l - e).collect()
}

/// The lag of some channels on the innovations: each channel's time constant profiled; the
/// channels whose lag stands out from the typical channel's are named together. With the other
/// channels unlagged, the filter's modes follow them and a lagged channel's innovation shows its
/// lag; a lag common to most channels is the alignment's ([`super::pressure_lag`]), which the
/// innovations cannot see.
fn lag_findings(runs: &[RunStreams], n_taps: usize) -> Vec<SensorFinding> {
    let Some(sample_hz) = runs.first().map(|run| run.sample_hz) else {
        return Vec::new();
    };
    let grid = lag_grid(sample_hz);
    // Per channel and grid point: the fit.
    let per_tau: Vec<Vec<Option<regression::Fit>>> = grid
        .iter()
        .map(|&tau_s| {
            (0..n_taps)
                .map(|tap| {
                    let segments = segments_of(runs, tap);
                    let columns: Vec<Vec<Vec<f64>>> =
                        runs.iter().map(|run| vec![lag_column(run, tap, tau_s)]).collect();
                    regression::fit_through_origin(&segments, &columns)
                })
                .collect()
        })
        .collect();
    // Per channel, its best time constant and what it explains in noise variances.
    let best: Vec<Option<(usize, f64)>> = (0..n_taps)
        .map(|tap| {
            let noise_var = regression::difference_noise_var(&segments_of(runs, tap), None).max(f64::MIN_POSITIVE);
            per_tau
                .iter()
                .enumerate()
                // A lag, not a lead: the reading follows the expectation late (positive gain).
                .filter_map(|(tau_idx, fits)| {
                    fits[tap]
                        .as_ref()
                        .filter(|fit| fit.beta.first().is_some_and(|gain| *gain > 0.0))
                        .map(|fit| (tau_idx, fit.explained_per_sample() / noise_var))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
        })
        .collect();
    // The channels that stand out: a lag of some channels leaves the others' innovations
    // alone, while a common-mode change of every pressure (q fluctuation, a model error) shows
    // in all of them alike and is no lag of these channels.
    let mut strengths: Vec<f64> = best.iter().map(|b| b.map_or(0.0, |(_, v)| v)).collect();
    strengths.sort_by(f64::total_cmp);
    let typical = strengths[strengths.len() / 2];
    let min_ratio = super::MIN_EFFECT_TO_NOISE * super::MIN_EFFECT_TO_NOISE;
    let lagged: Vec<(usize, usize)> = best
        .iter()
        .enumerate()
        .filter_map(|(tap, b)| b.filter(|(_, v)| *v >= min_ratio && *v >= STAND_OUT * typical).map(|(t, _)| (tap, t)))
        .collect();
    if lagged.is_empty() {
        return Vec::new();
    }
    // One column per lagged channel at its own time constant, pooled.
    let (mut segments, mut columns) = (Vec::new(), Vec::new());
    for (slot, &(tap, tau_idx)) in lagged.iter().enumerate() {
        segments.extend(segments_of(runs, tap));
        columns.extend(runs.iter().map(|run| {
            let own = lag_column(run, tap, grid[tau_idx]);
            (0..lagged.len()).map(|s| if s == slot { own.clone() } else { vec![0.0; own.len()] }).collect::<Vec<_>>()
        }));
    }
    let Some(fit) = regression::fit_through_origin(&segments, &columns) else { return Vec::new() };
    let taus: Vec<(usize, f64)> = lagged.iter().map(|&(tap, tau_idx)| (tap, grid[tau_idx])).collect();
    let mut finding = lag_finding(&segments, &columns, &fit, &taus, 2 * lagged.len());
    // The choice of the channels costs ln C(n, k).
    finding.delta_bic -= (1..=lagged.len()).map(|i| ((n_taps - lagged.len() + i) as f64 / i as f64).ln()).sum::<f64>();
    vec![finding]
}

fn lag_finding(
    segments: &[Segment<'_>],
    columns: &[Vec<Vec<f64>>],
    fit: &regression::Fit,
    taus: &[(usize, f64)],
    k: usize,
) -> SensorFinding {
    let noise_var = regression::difference_noise_var(segments, None);
    let autocorrelation = regression::integrated_autocorrelation(segments, 50);
    let heldout = regression::heldout_gap(segments, columns, &fit.beta, &fit.touched);
    let selection = regression::selection_gap(segments, columns, &fit.beta, &fit.touched);
    let names: Vec<String> = taus.iter().map(|(tap, _)| channel_name(*tap)).collect();
    let mut params = vec![
        ("tau_s".into(), ParamValue::Number(taus.iter().map(|(_, t)| t).sum::<f64>() / taus.len().max(1) as f64)),
        ("channels".into(), ParamValue::Text(names.join(","))),
    ];
    for ((tap, tau_s), gain) in taus.iter().zip(&fit.beta) {
        params.push((format!("tau_s_{}", channel_name(*tap)), ParamValue::Number(*tau_s)));
        params.push((format!("gain_{}", channel_name(*tap)), ParamValue::Number(*gain)));
    }
    SensorFinding {
        effect: Effect::PressureLag,
        params,
        channel: (names.len() == 1).then(|| names[0].clone()),
        channels: names.clone(),
        explained: fit.explained_per_sample(),
        noise_var,
        delta_bic: delta_bic(fit, autocorrelation, k),
        heldout,
        selection,
        evidence: format!(
            "the innovation of {} follows a first-order lag of the expected pressure ({})",
            names.join(", "),
            taus.iter()
                .map(|(tap, t)| format!("{}: {:.1} ms", channel_name(*tap), 1e3 * t))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// `N_eff ln(SSR_0 / SSR) - k ln N_eff` with `N_eff = N / tau`.
#[must_use]
pub fn delta_bic(fit: &regression::Fit, autocorrelation_time: f64, k: usize) -> f64 {
    let n_eff = fit.n as f64 / autocorrelation_time.max(1.0);
    if fit.ssr <= 0.0 || fit.ssr_base <= 0.0 || n_eff < 2.0 {
        return 0.0;
    }
    n_eff * (fit.ssr_base / fit.ssr).ln() - k as f64 * n_eff.ln()
}

/// The fault candidate of one channel: the most explanatory of dead, stuck, bias and spike.
fn fault_finding(runs: &[RunStreams], tap: usize, n_taps: usize) -> Option<SensorFinding> {
    let name = channel_name(tap);
    // Dead: the channel is missing where the others are measured.
    let (mut missing, mut others_missing, mut total) = (0usize, 0usize, 0usize);
    for run in runs {
        for idx in 0..run.len() {
            total += 1;
            let others = (0..n_taps).filter(|&other| other != tap && !run.cp[other][idx].is_finite()).count();
            if !run.cp[tap][idx].is_finite() {
                missing += 1;
            }
            if others * 2 > n_taps - 1 {
                others_missing += 1;
            }
        }
    }
    let segments = segments_of(runs, tap);
    let noise_var = regression::difference_noise_var(&segments, None).max(f64::MIN_POSITIVE);
    let missing_fraction = missing as f64 / total.max(1) as f64;
    let others_fraction = others_missing as f64 / total.max(1) as f64;
    if missing_fraction > 0.02 && missing_fraction > 10.0 * others_fraction {
        let onset = first_long_gap_s(runs, tap);
        return Some(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("dead".into())),
                ("start_s".into(), ParamValue::Number(onset)),
                ("missing_fraction".into(), ParamValue::Number(missing_fraction)),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            // A dead channel carries no reading: its whole signal is the gap.
            explained: f64::INFINITY,
            noise_var,
            delta_bic: f64::INFINITY,
            heldout: regression::HeldoutGap::EMPTY,
            selection: regression::HeldoutGap::EMPTY,
            evidence: format!(
                "{name} is missing in {:.1} % of the samples (the others in {:.1} %)",
                100.0 * missing_fraction,
                100.0 * others_fraction
            ),
        });
    }
    let tau = regression::integrated_autocorrelation(&segments, 50);
    let onset_s = |onsets: &faults::Onsets| -> f64 {
        runs.iter()
            .zip(&onsets.per_run)
            .filter_map(|(run, interval)| interval.as_ref().map(|r| run.t_s.get(r.start).copied().unwrap_or(0.0)))
            .fold(f64::INFINITY, f64::min)
    };
    // Seconds the fault holds, summed over the runs.
    let faulty_s = |onsets: &faults::Onsets| -> f64 {
        runs.iter()
            .zip(&onsets.per_run)
            .filter_map(|(run, interval)| interval.as_ref().map(|r| r.len() as f64 / run.sample_hz))
            .sum()
    };
    let runs_with = |onsets: &faults::Onsets| onsets.per_run.iter().filter(|o| o.is_some()).count();
    let mut shapes: Vec<SensorFinding> = Vec::new();
    // Stuck (or flat): from its onset in each run the reading stops following the pressure.
    let stuck = faults::scan(runs, tap, faults::Shape::Stuck, tau);
    if runs_with(&stuck) > 0
        && let Some(fit) = regression::fit_through_origin(&segments, &stuck.columns)
        && faults::stuck_slope_holds(&fit)
    {
        let (repeat_s, repeat_start_s) = longest_constant_run(runs, tap);
        let start_s = onset_s(&stuck);
        let k = fit.beta.len() + runs_with(&stuck);
        shapes.push(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("stuck".into())),
                ("start_s".into(), ParamValue::Number(start_s)),
                ("faulty_s".into(), ParamValue::Number(faulty_s(&stuck))),
                ("runs".into(), ParamValue::Number(runs_with(&stuck) as f64)),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            explained: fit.explained_per_sample(),
            noise_var,
            delta_bic: delta_bic(&fit, tau, k),
            heldout: regression::heldout_gap(&segments, &stuck.columns, &fit.beta, &fit.touched),
            selection: regression::selection_gap(&segments, &stuck.columns, &fit.beta, &fit.touched),
            evidence: if repeat_s >= STUCK_MIN_S {
                format!("{name} repeats one reading for {repeat_s:.2} s from t = {repeat_start_s:.2} s")
            } else {
                format!(
                    "{name} stops following the pressure from t = {start_s:.2} s in {} run(s) (a constant with noise)",
                    runs_with(&stuck)
                )
            },
        });
    }
    // Spikes: isolated innovations, or bursts of a few samples, far beyond the channel's robust
    // spread.
    let robust_sigma = robust_sigma(&segments);
    let spike_columns: Vec<Vec<Vec<f64>>> =
        runs.iter().map(|run| vec![spike_column(&run.innovation[tap], robust_sigma)]).collect();
    if let Some(fit) = regression::fit_through_origin(&segments, &spike_columns) {
        let count: usize = spike_columns.iter().map(|cols| cols[0].iter().filter(|v| **v != 0.0).count()).sum();
        let duration_s: f64 = runs.iter().map(|run| run.len() as f64 / run.sample_hz).sum();
        // A spike count the Gaussian tail explains is not a fault.
        let expected = gaussian_tail(SPIKE_SIGMA) * runs.iter().map(RunStreams::len).sum::<usize>() as f64;
        let delta = if (count as f64) > 3.0 * expected + 3.0 { delta_bic(&fit, tau, 1) } else { 0.0 };
        shapes.push(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("spike".into())),
                ("spike_rate_hz".into(), ParamValue::Number(count as f64 / duration_s.max(f64::MIN_POSITIVE))),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            explained: if delta > 0.0 { fit.explained_per_sample() } else { 0.0 },
            noise_var,
            delta_bic: delta,
            heldout: regression::heldout_gap(&segments, &spike_columns, &[1.0], &fit.touched),
            selection: regression::selection_gap(&segments, &spike_columns, &[1.0], &fit.touched),
            evidence: format!(
                "{name} has {count} innovations beyond {SPIKE_SIGMA} robust sigma (Gaussian tail: {expected:.1})"
            ),
        });
    }
    // Bias: the innovation's mean steps over each run's own interval, by a value of its own.
    let bias = faults::scan(runs, tap, faults::Shape::Bias, tau);
    if runs_with(&bias) > 0
        && let Some(fit) = regression::fit_through_origin(&segments, &bias.columns)
    {
        let start_s = onset_s(&bias);
        let largest = fit.beta.iter().copied().fold(0.0, |acc: f64, b| if b.abs() > acc.abs() { b } else { acc });
        shapes.push(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("bias".into())),
                ("value".into(), ParamValue::Number(largest)),
                ("start_s".into(), ParamValue::Number(start_s)),
                ("faulty_s".into(), ParamValue::Number(faulty_s(&bias))),
                ("runs".into(), ParamValue::Number(runs_with(&bias) as f64)),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            explained: fit.explained_per_sample(),
            noise_var,
            delta_bic: delta_bic(&fit, tau, 2 * runs_with(&bias)),
            heldout: regression::heldout_gap(&segments, &bias.columns, &fit.beta, &fit.touched),
            selection: regression::selection_gap(&segments, &bias.columns, &fit.beta, &fit.touched),
            evidence: format!(
                "{name}'s innovation mean steps by up to {largest:.4} from t = {start_s:.2} s in {} run(s)",
                runs_with(&bias)
            ),
        });
    }
    shapes.into_iter().max_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic))
}

/// The spikes of one innovation series: isolated samples, or bursts of up to
/// [`SPIKE_MAX_BURST`] samples, beyond [`SPIKE_SIGMA`] robust standard deviations, with ordinary
/// samples on both sides (a longer excursion is a lag or a step, not a spike); zero elsewhere.
fn spike_column(nu: &[f64], robust_sigma: f64) -> Vec<f64> {
    let big = |idx: usize| nu[idx].is_finite() && nu[idx].abs() > SPIKE_SIGMA * robust_sigma;
    let quiet = |idx: Option<usize>| idx.is_none_or(|i| !(nu[i].is_finite() && nu[i].abs() > 3.0 * robust_sigma));
    let mut out = vec![0.0; nu.len()];
    let mut idx = 0;
    while idx < nu.len() {
        if !big(idx) {
            idx += 1;
            continue;
        }
        let start = idx;
        while idx < nu.len() && big(idx) {
            idx += 1;
        }
        let next = (idx < nu.len()).then_some(idx);
        if idx - start <= SPIKE_MAX_BURST && quiet(start.checked_sub(1)) && quiet(next) {
            out[start..idx].copy_from_slice(&nu[start..idx]);
        }
    }
    out
}

/// Upper tail probability of `|N(0, 1)| > z`.
fn gaussian_tail(z: f64) -> f64 {
    // Abramowitz & Stegun 7.1.26 for erfc, plenty for a count threshold.
    let x = z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * x);
    let poly =
        t * (0.254_829_592 + t * (-0.284_496_736 + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    poly * (-x * x).exp()
}

/// The robust spread of the training innovations ([`regression::mad_sigma`]).
fn robust_sigma(segments: &[Segment<'_>]) -> f64 {
    let mut values: Vec<f64> = segments
        .iter()
        .flat_map(|segment| segment.training.clone().map(|i| segment.residual[i]))
        .filter(|v| v.is_finite())
        .collect();
    regression::mad_sigma(&mut values).unwrap_or(f64::INFINITY)
}

/// Start of the first stretch of at least 10 missing samples of the channel, s.
fn first_long_gap_s(runs: &[RunStreams], tap: usize) -> f64 {
    let mut best = f64::INFINITY;
    for run in runs {
        let mut length = 0;
        for (idx, value) in run.cp[tap].iter().enumerate() {
            length = if value.is_finite() { 0 } else { length + 1 };
            if length == 10 {
                best = best.min(run.t_s[idx + 1 - 10]);
                break;
            }
        }
    }
    if best.is_finite() { best } else { 0.0 }
}

/// Longest stretch of identical finite raw readings (s) and the start of the longest, s.
fn longest_constant_run(runs: &[RunStreams], tap: usize) -> (f64, f64) {
    let (mut best_s, mut start_s) = (0.0, 0.0);
    for run in runs {
        let mut begin = 0;
        for idx in 1..=run.len() {
            let same = idx < run.len() && run.cp[tap][idx].is_finite() && run.cp[tap][idx] == run.cp[tap][idx - 1];
            if !same {
                let length_s = (idx - begin) as f64 / run.sample_hz;
                if idx - begin > 1 && length_s > best_s {
                    best_s = length_s;
                    start_s = run.t_s[begin];
                }
                begin = idx;
            }
        }
    }
    (best_s, start_s)
}
