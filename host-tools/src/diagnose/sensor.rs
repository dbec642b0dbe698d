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
    let mut alignment = super::pressure_lag::finding(runs, reference_tau_s);
    let mut some = lag_findings(runs, n_taps);
    // A lag of some channels shifts the alignment of all twelve too, and a lag of every channel
    // can leave some standing out in the innovations: the balance, which reads the pressures
    // without lag, tells the two apart. Only a lag the alignment finds at all (the least effect
    // to name) can be common.
    let common_lag = alignment.as_ref().filter(|finding| strength(finding) >= least_strength());
    if let (Some(_), Some(group)) = (common_lag, some.first().filter(|finding| finding.channels.len() < n_taps)) {
        let taps: Vec<usize> = (0..n_taps).filter(|tap| group.channels.contains(&channel_name(*tap))).collect();
        if super::pressure_lag::lag_is_common(runs, &taps, reference_tau_s) {
            some.clear();
        } else {
            alignment = None;
        }
    }
    out.extend(alignment);
    out.extend(some);
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

/// Per run, per channel: the innovation a channel's lag is judged on.
type Judged<'a> = Vec<Vec<&'a [f64]>>;

/// Owned innovations per run and channel, borrowed as [`Judged`].
fn judged(innovations: &[Vec<Vec<f64>>]) -> Judged<'_> {
    innovations.iter().map(|run| run.iter().map(Vec::as_slice).collect()).collect()
}

/// The least strength of a finding to name, in noise variances: the least effect to name
/// ([`super::MIN_EFFECT_TO_NOISE`] of the noise RMS), squared.
fn least_strength() -> f64 {
    super::MIN_EFFECT_TO_NOISE * super::MIN_EFFECT_TO_NOISE
}

/// Segments of one channel's judged innovation in every run.
fn segments_judged<'a>(runs: &'a [RunStreams], judged: &Judged<'a>, tap: usize) -> Vec<Segment<'a>> {
    faults::segments_with(runs, judged.iter().map(|run| run[tap]))
}

/// What the sensor families search, for the report: `(effect, forms searched)`.
#[must_use]
pub fn family_summaries(sample_hz: f64) -> Vec<(Effect, String)> {
    let grid = lag_grid(sample_hz);
    let (low, high) = super::pressure_lag::TAU_RANGE_S;
    vec![
        (
            Effect::PressureLag,
            format!(
                "every channel with one time constant from {:.0} to {:.0} ms, the sim's own alignment then subtracted (the taps re-aligned with the balance); one or several channels, each its own time constant, {:.1} to {:.0} ms ({} values), on what the filter without the channel expects of it, a group again on the filter without the whole group; every channel against some told by the balance",
                1e3 * low,
                1e3 * high,
                1e3 * grid.first().copied().unwrap_or(0.0),
                1e3 * grid.last().copied().unwrap_or(0.0),
                grid.len()
            ),
        ),
        (
            Effect::PressureFault,
            format!(
                "one channel: dead (missing where the others read); stuck from an onset per run (bit-identical readings, or a constant with the sensor's noise that stops following the pressure); a bias stepping in at its own onset in each run; spikes of 1 to {SPIKE_MAX_BURST} samples beyond {SPIKE_SIGMA} robust standard deviations"
            ),
        ),
    ]
}

/// Time constants of the lag candidate, s: a log grid from two samples to half a second (about
/// five points an octave). A best fit at the longest is no lag, so the grid reaches far beyond a
/// tube's tens of milliseconds (gap-diagnosis.md section 2.6). Without a least gain, a longer
/// grid takes a slow change of a channel's scale for a lag (a 0.48 s lag at gain 0.19 for a
/// fifth of a 5 s lag), so lags near half a second are beyond what the family tells.
fn lag_grid(sample_hz: f64) -> Vec<f64> {
    super::candidates::log_grid(2.0 / sample_hz, 0.5, 28)
}

/// The lag column of one channel: `LP_tau[expected] - expected`, with `expected` what the
/// filter run without the channel expects of it (measured minus the judged innovation): a
/// lagged sensor reads the expected pressure through its lag (gap-diagnosis.md section 2.6,
/// the first-order form).
fn lag_column(run: &RunStreams, innovation: &[f64], tap: usize, tau_s: f64) -> Vec<f64> {
    let expected: Vec<f64> = run.cp[tap].iter().zip(innovation).map(|(cp, nu)| cp - nu).collect();
    let held =
        crate::fit::signals::hold_missing(&expected, expected.iter().copied().find(|v| v.is_finite()).unwrap_or(0.0));
    let lagged = super::candidates::first_order_lag(&held, tau_s, 1.0 / run.sample_hz);
    lagged.iter().zip(&held).map(|(l, e)| l - e).collect()
}

/// Most refinements of the lagged group: each runs the filter once without the group and once
/// more without the group and each channel outside it.
const GROUP_REFINEMENTS: usize = 3;

/// Fewest channels outside a lagged group: the filter without the group needs channels to
/// expect anything, and a lag of nearly every channel is the alignment's.
const MIN_REFERENCE_TAPS: usize = 3;

/// The lag of some channels on the innovations: each channel's time constant profiled; the
/// channels whose lag stands out from the typical channel's are named together.
///
/// Each channel is first judged on what the filter run without it expects of it
/// ([`RunStreams::innovation_alone`]): with the other channels unlagged, that expectation is
/// the unlagged pressure and the channel's whole lag shows, where its own innovation hides most
/// of it (the filter's modes follow the lagged readings: of three lagged channels, the
/// innovations singled out one). With several channels lagged, what the others expect still
/// carries the rest of the group's lag: a healthy channel takes the group's footprint, and a
/// member's lag is part hidden (fitted as a longer time constant with a smaller gain). So the
/// group found is refined: each member is judged again on the filter without the whole group,
/// each other channel on the filter without the group and itself, the typical channel is the
/// median outside the group, until the group holds. A lag common to most channels is the
/// alignment's ([`super::pressure_lag`]): the others then expect a lagged pressure too.
fn lag_findings(runs: &[RunStreams], n_taps: usize) -> Vec<SensorFinding> {
    let Some(sample_hz) = runs.first().map(|run| run.sample_hz) else {
        return Vec::new();
    };
    let grid = lag_grid(sample_hz);
    let alone: Judged<'_> =
        runs.iter().map(|run| run.innovation_alone.iter().take(n_taps).map(Vec::as_slice).collect()).collect();
    let mut lagged = standing_out(&best_lags(runs, &alone, &grid, n_taps), &vec![false; n_taps]);
    let group_of = |lagged: &[(usize, usize)]| -> Vec<bool> {
        (0..n_taps).map(|tap| lagged.iter().any(|(member, _)| *member == tap)).collect()
    };
    let refine = |group: Vec<bool>| {
        let innovations = without_group(runs, &group);
        let best = { best_lags(runs, &judged(&innovations), &grid, n_taps) };
        (group, innovations, best)
    };
    let too_many = |lagged: &[(usize, usize)]| lagged.len() + MIN_REFERENCE_TAPS > n_taps;
    let mut refined = None;
    for _ in 0..GROUP_REFINEMENTS {
        if lagged.is_empty() || too_many(&lagged) {
            break;
        }
        let (group, innovations, best) = refine(group_of(&lagged));
        let next = standing_out(&best, &group);
        let holds = group_of(&next) == group;
        let grows_too_far = too_many(&next);
        refined = Some((group, innovations, best));
        if holds || grows_too_far {
            break;
        }
        lagged = next;
    }
    if lagged.is_empty() {
        return Vec::new();
    }
    // The group's time constants and innovations, judged without the whole group.
    if !too_many(&lagged) && refined.as_ref().is_none_or(|(group, _, _)| *group != group_of(&lagged)) {
        refined = Some(refine(group_of(&lagged)));
    }
    let judged: Judged<'_> = match &refined {
        Some((_, innovations, best)) => {
            lagged = lagged.iter().filter_map(|(tap, _)| best[*tap].map(|(tau_idx, _)| (*tap, tau_idx))).collect();
            judged(innovations)
        }
        None => alone,
    };
    if lagged.is_empty() {
        return Vec::new();
    }
    // One column per lagged channel at its own time constant, pooled.
    let (mut segments, mut columns) = (Vec::new(), Vec::new());
    for (slot, &(tap, tau_idx)) in lagged.iter().enumerate() {
        segments.extend(segments_judged(runs, &judged, tap));
        columns.extend(runs.iter().zip(&judged).map(|(run, innovations)| {
            let own = lag_column(run, innovations[tap], tap, grid[tau_idx]);
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

/// Per channel, its best time constant on the grid (index) and what that lag explains in noise
/// variances of the judged innovation; `None` without a lag inside the grid.
fn best_lags(runs: &[RunStreams], judged: &Judged<'_>, grid: &[f64], n_taps: usize) -> Vec<Option<(usize, f64)>> {
    use rayon::prelude::*;
    (0..n_taps)
        .into_par_iter()
        .map(|tap| {
            let segments = segments_judged(runs, judged, tap);
            let noise_var = regression::difference_noise_var(&segments, None).max(f64::MIN_POSITIVE);
            grid.iter()
                .enumerate()
                .filter_map(|(tau_idx, &tau_s)| {
                    let columns: Vec<Vec<Vec<f64>>> =
                        runs.iter().zip(judged).map(|(run, nu)| vec![lag_column(run, nu[tap], tap, tau_s)]).collect();
                    regression::fit_through_origin(&segments, &columns)
                        // A lag, not a lead: the reading follows the expectation late (positive
                        // gain). No least gain: errors in what the other channels expect take a
                        // rig-dependent share off it (gains of 0.1 to 0.5 for a three-channel
                        // group of 23 ms on the second tunnel).
                        .filter(|fit| fit.beta.first().is_some_and(|gain| *gain > 0.0))
                        .map(|fit| (tau_idx, fit.explained_per_sample() / noise_var))
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                // A best fit at the grid's longest time constant estimates none: the deviation
                // only grows slower than any lag searched (a slow change of the Cp's scale, a
                // drift), which a lag of this channel does not explain. A lag has its optimum
                // inside the grid, which reaches far beyond tubing.
                .filter(|&(tau_idx, _)| tau_idx + 1 < grid.len())
        })
        .collect()
}

/// The channels whose lag stands out, with their best time constants: at least the least
/// effect to name and [`STAND_OUT`] times the typical channel's evidence, the median of the
/// channels outside `group`. A lag of some channels leaves the others' innovations alone, while
/// a common-mode change of every pressure (q fluctuation, a model error) shows in all of them
/// alike and is no lag of these channels.
fn standing_out(best: &[Option<(usize, f64)>], group: &[bool]) -> Vec<(usize, usize)> {
    let strength = |b: &Option<(usize, f64)>| b.map_or(0.0, |(_, v)| v);
    let mut reference: Vec<f64> =
        best.iter().zip(group).filter(|(_, member)| !**member).map(|(b, _)| strength(b)).collect();
    if reference.is_empty() {
        return Vec::new();
    }
    reference.sort_by(f64::total_cmp);
    let typical = reference[reference.len() / 2];
    let min_ratio = least_strength();
    best.iter()
        .enumerate()
        .filter_map(|(tap, b)| b.filter(|(_, v)| *v >= min_ratio && *v >= STAND_OUT * typical).map(|(t, _)| (tap, t)))
        .collect()
}

/// Per run and channel, the innovation of each channel of `group` from the filter without the
/// group, and of each other channel from the filter without the group and itself.
fn without_group(runs: &[RunStreams], group: &[bool]) -> Vec<Vec<Vec<f64>>> {
    use rayon::prelude::*;
    runs.par_iter()
        .map(|run| {
            let members = run.innovation_without(group);
            (0..group.len())
                .into_par_iter()
                .map(|tap| {
                    if group[tap] {
                        members[tap].clone()
                    } else {
                        let left_out: Vec<bool> = group.iter().enumerate().map(|(t, m)| *m || t == tap).collect();
                        run.innovation_without(&left_out).swap_remove(tap)
                    }
                })
                .collect()
        })
        .collect()
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
        // The shared slope on the expectation (checked above); the parts find their own intervals.
        let slope = fit.beta.first().copied().unwrap_or(0.0);
        let part_gap = |heldout: bool| faults::part_gap(runs, tap, faults::Shape::Stuck, tau, slope, heldout);
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
            heldout: part_gap(true),
            selection: part_gap(false),
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
            heldout: faults::part_gap(runs, tap, faults::Shape::Bias, tau, 0.0, true),
            selection: faults::part_gap(runs, tap, faults::Shape::Bias, tau, 0.0, false),
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

/// Start of the first stretch of at least 10 missing samples of the channel, s; without one,
/// the first missing sample.
fn first_long_gap_s(runs: &[RunStreams], tap: usize) -> f64 {
    let (mut best, mut first_missing) = (f64::INFINITY, f64::INFINITY);
    for run in runs {
        let mut length = 0;
        for (idx, value) in run.cp[tap].iter().enumerate() {
            length = if value.is_finite() { 0 } else { length + 1 };
            if length == 1 {
                first_missing = first_missing.min(run.t_s[idx]);
            }
            if length == 10 {
                best = best.min(run.t_s[idx + 1 - 10]);
                break;
            }
        }
    }
    // A channel that drops out in short bursts starts failing at its first missing sample.
    if best.is_finite() { best } else { first_missing }
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

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::diagnose::regression::{Fit, HeldoutGap, Interleave};
    use crate::diagnose::streams::synthetic_run;
    use crate::diagnose::{MIN_DELTA_BIC, MIN_EFFECT_TO_NOISE};

    const HZ: f64 = 1000.0;
    const N: usize = 5000;
    const DURATION_S: f64 = N as f64 / HZ;
    const NOISE: f64 = 0.01;
    const TAPS: usize = 12;

    /// The pressure of `tap` at `t_s` read through a first-order lag of `tau_s` (0: no lag), in
    /// closed form: each sinusoid of the pressure scaled by `1 / sqrt(1 + (w tau)^2)` and
    /// delayed in phase by `atan(w tau)` (the steady state), the mean passed unchanged.
    fn pressure(tap: usize, t_s: f64, tau_s: f64) -> f64 {
        let parts = [(0.3, 2.0, 0.5 * tap as f64), (0.1, 5.0, tap as f64)];
        parts
            .iter()
            .map(|&(amplitude, freq_hz, phase)| {
                let w = std::f64::consts::TAU * freq_hz;
                amplitude / (1.0 + (w * tau_s).powi(2)).sqrt() * (w * t_s + phase - (w * tau_s).atan()).sin()
            })
            .sum::<f64>()
            - 0.5
    }

    /// Twelve channels over `N` samples: `reading(tap, idx, noise)` is each reading (NaN where
    /// missing), `noise` a seeded Gaussian draw of `NOISE`; the filter's expectation is the
    /// unlagged pressure, so the innovation is the reading less it.
    fn recording(seed: u64, reading: impl Fn(usize, usize, f64) -> f64) -> RunStreams {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let normal = Normal::new(0.0, NOISE).expect("a valid deviation");
        let mut cp: Vec<Vec<f64>> = (0..TAPS).map(|_| Vec::with_capacity(N)).collect();
        let mut nu: Vec<Vec<f64>> = (0..TAPS).map(|_| Vec::with_capacity(N)).collect();
        for idx in 0..N {
            for tap in 0..TAPS {
                let value = reading(tap, idx, normal.sample(&mut rng));
                cp[tap].push(value);
                nu[tap].push(value - pressure(tap, idx as f64 / HZ, 0.0));
            }
        }
        synthetic_run(HZ, cp, nu)
    }

    fn healthy(tap: usize, idx: usize, noise: f64) -> f64 {
        pressure(tap, idx as f64 / HZ, 0.0) + noise
    }

    fn number(finding: &SensorFinding, key: &str) -> f64 {
        match finding.params.iter().find(|(k, _)| k == key) {
            Some((_, ParamValue::Number(value))) => *value,
            other => panic!("{key}: {other:?}"),
        }
    }

    fn text<'a>(finding: &'a SensorFinding, key: &str) -> &'a str {
        match finding.params.iter().find(|(k, _)| k == key) {
            Some((_, ParamValue::Text(value))) => value,
            other => panic!("{key}: {other:?}"),
        }
    }

    /// Whether a finding passes the naming thresholds (decisive and at least an effect of
    /// `MIN_EFFECT_TO_NOISE` of the noise RMS).
    fn qualifies(finding: &SensorFinding) -> bool {
        finding.delta_bic >= MIN_DELTA_BIC && strength(finding) >= MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE
    }

    fn fit(n: usize, ssr_base: f64, ssr: f64) -> Fit {
        Fit { beta: vec![1.0], ssr_base, ssr, n, n_touched: n, ssr_base_touched: ssr_base, touched: vec![true] }
    }

    fn bare_finding(explained: f64, noise_var: f64) -> SensorFinding {
        SensorFinding {
            effect: Effect::PressureLag,
            params: Vec::new(),
            channel: None,
            channels: vec!["cp03".into(), "cp07".into()],
            explained,
            noise_var,
            delta_bic: 0.0,
            heldout: HeldoutGap::EMPTY,
            selection: HeldoutGap::EMPTY,
            evidence: String::new(),
        }
    }

    /// Taps are named as in the dataset, 1-based and two digits (the contract's `cp07`).
    #[test]
    fn channels_are_named_as_in_the_dataset() {
        assert_eq!(channel_name(0), "cp01");
        assert_eq!(channel_name(6), "cp07");
        assert_eq!(channel_name(11), "cp12");
    }

    /// The signature key is the effect's name and its channels joined by `+`.
    #[test]
    fn the_floor_key_is_the_name_and_the_channels() {
        assert_eq!(bare_finding(1.0, 1.0).floor_key(), "pressure_lag:cp03+cp07");
    }

    /// Strength is explained over noise variance (2 / 0.5 = 4); a dead channel's unbounded
    /// evidence is infinitely strong, so it sorts first.
    #[test]
    fn strength_is_explained_over_noise_and_unbounded_for_a_dead_channel() {
        assert_eq!(strength(&bare_finding(2.0, 0.5)), 4.0);
        assert_eq!(strength(&bare_finding(f64::INFINITY, 0.5)), f64::INFINITY);
    }

    /// `N_eff ln(SSR_0 / SSR) - k ln N_eff` by hand: 1000 samples, autocorrelation 2, SSR
    /// halved, one parameter: 500 ln 2 - ln 500 = 340.3590; an autocorrelation time below one
    /// sample counts as one (1000 ln 2 - ln 1000 = 686.2394).
    #[test]
    fn delta_bic_is_the_hand_computed_criterion() {
        assert!((delta_bic(&fit(1000, 2.0, 1.0), 2.0, 1) - 340.358_982_181_550_4).abs() < 1e-9);
        let expected = 1000.0 * 2f64.ln() - 1000f64.ln();
        assert!((delta_bic(&fit(1000, 2.0, 1.0), 0.5, 1) - expected).abs() < 1e-9);
        assert!((delta_bic(&fit(1000, 2.0, 1.0), 1.0, 3) - (1000.0 * 2f64.ln() - 3.0 * 1000f64.ln())).abs() < 1e-9);
    }

    /// Fewer than two effective samples carry no evidence; two do: 4 samples at autocorrelation
    /// 2 give 2 ln 2 - ln 2 = ln 2, 3 samples give 0.
    #[test]
    fn delta_bic_needs_two_effective_samples() {
        assert!((delta_bic(&fit(4, 2.0, 1.0), 2.0, 1) - 2f64.ln()).abs() < 1e-12);
        assert_eq!(delta_bic(&fit(3, 2.0, 1.0), 2.0, 1), 0.0);
    }

    /// A non-finite sum of squares is no evidence of zero: it stays NaN (written null later).
    #[test]
    fn delta_bic_of_a_nan_fit_is_not_a_number() {
        assert!(delta_bic(&fit(1000, 2.0, f64::NAN), 1.0, 1).is_nan());
        assert!(delta_bic(&fit(1000, f64::NAN, 1.0), 1.0, 1).is_nan());
    }

    /// The Gaussian tail against `erfc(z / sqrt 2)`: 0.05 at 1.96, 0.0027 at 3, 1.973e-9 at the
    /// spike threshold 6 (within 1 %, plenty for a count threshold).
    #[test]
    fn the_gaussian_tail_matches_erfc() {
        assert!((gaussian_tail(1.96) - 0.049_995_790_296_440_87).abs() < 1e-6);
        assert!((gaussian_tail(3.0) - 0.002_699_796_063_260_191).abs() < 1e-6);
        let at_six = gaussian_tail(SPIKE_SIGMA) / 1.973_175_290_075_402_4e-9;
        assert!((at_six - 1.0).abs() < 0.01, "{at_six}");
    }

    /// A spike is an innovation strictly beyond `SPIKE_SIGMA` robust sigma: just above is kept
    /// with its own value (either sign), exactly at the threshold is not.
    #[test]
    fn a_spike_is_strictly_beyond_the_threshold() {
        let mut nu = vec![0.0; 30];
        nu[5] = SPIKE_SIGMA + 1e-9;
        nu[15] = -(SPIKE_SIGMA + 2.0);
        nu[25] = SPIKE_SIGMA;
        let column = spike_column(&nu, 1.0);
        let mut expected = vec![0.0; 30];
        expected[5] = nu[5];
        expected[15] = nu[15];
        assert_eq!(column, expected);
    }

    /// Bursts of up to `SPIKE_MAX_BURST` samples are spikes; one sample longer is a step or a
    /// lag, not a spike.
    #[test]
    fn a_burst_longer_than_the_limit_is_no_spike() {
        let burst = |length: usize| {
            let mut nu = vec![0.0; 40];
            nu[10..10 + length].fill(2.0 * SPIKE_SIGMA);
            spike_column(&nu, 1.0)
        };
        assert_eq!(burst(SPIKE_MAX_BURST).iter().filter(|v| **v != 0.0).count(), SPIKE_MAX_BURST);
        assert!(burst(SPIKE_MAX_BURST + 1).iter().all(|v| *v == 0.0));
    }

    /// A spike needs ordinary neighbours: a neighbour beyond 3 sigma makes it part of a larger
    /// excursion (dropped), one at exactly 3 sigma, a missing one, or none (the ends) is
    /// ordinary.
    #[test]
    fn a_spike_needs_ordinary_neighbours() {
        let with_neighbour = |neighbour: f64| {
            let mut nu = vec![0.0; 20];
            nu[10] = 2.0 * SPIKE_SIGMA;
            nu[9] = neighbour;
            spike_column(&nu, 1.0)[10]
        };
        assert_eq!(with_neighbour(3.0 + 1e-9), 0.0);
        assert_eq!(with_neighbour(-3.0 - 1e-9), 0.0);
        assert_eq!(with_neighbour(3.0), 2.0 * SPIKE_SIGMA);
        assert_eq!(with_neighbour(f64::NAN), 2.0 * SPIKE_SIGMA);
        let mut ends = vec![0.0; 10];
        ends[0] = 10.0;
        ends[9] = -10.0;
        assert_eq!(spike_column(&ends, 1.0), ends);
    }

    /// Missing innovations are never spikes, and with no spread at all (no values: infinite
    /// sigma) nothing is a spike.
    #[test]
    fn missing_values_and_an_unknown_spread_give_no_spikes() {
        let nu = [0.0, f64::NAN, 0.0, f64::INFINITY, 0.0];
        assert!(spike_column(&nu, 1.0).iter().all(|v| *v == 0.0));
        assert!(spike_column(&[0.0, 50.0, 0.0], f64::INFINITY).iter().all(|v| *v == 0.0));
    }

    /// The robust spread of the training innovations: 1, 2, 3, 4, 5 have median absolute
    /// deviation 1, so 1.4826; held-out values and missing ones do not count; without values
    /// the spread is unknown (infinite), never 0 (which would make every sample a spike).
    #[test]
    fn the_robust_spread_uses_the_finite_training_values() {
        let residual = [1.0, 2.0, f64::NAN, 3.0, 4.0, 5.0, 100.0, 100.0];
        let segments = [Segment { residual: &residual, training: 0..6, select: Interleave::default(), heldout: 6..8 }];
        assert!((robust_sigma(&segments) - 1.4826).abs() < 1e-12);
        let empty = [Segment { residual: &residual, training: 0..0, select: Interleave::default(), heldout: 0..8 }];
        assert_eq!(robust_sigma(&empty), f64::INFINITY);
    }

    /// A run at 100 Hz for the helpers below: one channel with the given readings.
    fn one_channel(values: Vec<f64>) -> RunStreams {
        let n = values.len();
        synthetic_run(100.0, vec![values], vec![vec![0.0; n]])
    }

    /// The dead channel's onset is the first stretch of at least 10 missing samples, the
    /// earliest over the runs (15 missing from 2.0 s in one run, exactly 10 from 0.5 s in the
    /// other: 0.5 s); a stretch of 9 does not count.
    #[test]
    fn the_onset_is_the_first_stretch_of_ten_missing_samples() {
        let with_gap = |start: usize, length: usize| {
            let mut values = vec![0.1; 500];
            values[start..start + length].fill(f64::NAN);
            one_channel(values)
        };
        let runs = [with_gap(200, 15), with_gap(50, 10), with_gap(10, 9)];
        assert!((first_long_gap_s(&runs, 0) - 0.5).abs() < 1e-12);
        assert!((first_long_gap_s(&runs[..1], 0) - 2.0).abs() < 1e-12);
    }

    /// The longest stretch of bit-identical readings: 7 samples (0.07 s at 100 Hz) from 0.30 s
    /// beats 4 from 0.60 s; missing samples (NaN) never repeat; a channel with no repeat has
    /// none.
    #[test]
    fn the_longest_constant_run_is_measured_in_samples() {
        let mut values: Vec<f64> = (0..100).map(|i| f64::from(i) * 0.01).collect();
        values[30..37].fill(0.42);
        values[60..64].fill(-0.1);
        values[80..95].fill(f64::NAN);
        let (length_s, start_s) = longest_constant_run(&[one_channel(values)], 0);
        assert!((length_s - 0.07).abs() < 1e-12 && (start_s - 0.30).abs() < 1e-12, "{length_s} {start_s}");
        let distinct: Vec<f64> = (0..100).map(|i| f64::from(i) * 0.01).collect();
        assert_eq!(longest_constant_run(&[one_channel(distinct)], 0), (0.0, 0.0));
    }

    /// No runs, or runs without pressure channels, give no finding.
    #[test]
    fn no_channels_no_findings() {
        assert!(findings(&[], 0.0).is_empty());
        let mut run = synthetic_run(HZ, vec![vec![0.0; 100]], vec![vec![0.0; 100]]);
        run.cp.clear();
        run.innovation.clear();
        run.cp_dot.clear();
        assert!(findings(&[run], 0.0).is_empty());
    }

    /// Twelve healthy channels (white innovations of the transducer noise): nothing qualifies
    /// to be named.
    #[test]
    fn healthy_channels_have_no_qualifying_finding() {
        let run = recording(1, healthy);
        let found = findings(std::slice::from_ref(&run), 0.0);
        assert!(found.iter().all(|f| !qualifies(f)), "{:?}", found.iter().find(|f| qualifies(f)));
    }

    /// A recording with every channel missing throughout: no reading, no finding (no made-up
    /// figures).
    #[test]
    fn a_recording_without_readings_has_no_finding() {
        let run = recording(2, |_, _, _| f64::NAN);
        assert!(findings(&[run], 0.0).is_empty());
    }

    /// cp07 missing from 2 s to the end of a 5 s run, the others measured: a dead fault of
    /// cp07 from 2 s, 60 % missing, unbounded evidence, ranked first.
    #[test]
    fn a_channel_dead_from_two_seconds_is_named_first() {
        let run =
            recording(3, |tap, idx, noise| if tap == 6 && idx >= 2000 { f64::NAN } else { healthy(tap, idx, noise) });
        let found = findings(std::slice::from_ref(&run), 0.0);
        let first = found.first().expect("a finding");
        assert_eq!(first.effect, Effect::PressureFault);
        assert_eq!(text(first, "mode"), "dead");
        assert_eq!(first.channel.as_deref(), Some("cp07"));
        assert_eq!(first.channels, vec!["cp07".to_owned()]);
        assert!((number(first, "start_s") - 2.0).abs() < 1e-12);
        assert!((number(first, "missing_fraction") - 0.6).abs() < 1e-12);
        assert_eq!(first.explained, f64::INFINITY);
        assert_eq!(first.delta_bic, f64::INFINITY);
        assert!(found[1..].iter().all(|f| f.channel.as_deref() != Some("cp07") || text(f, "mode") != "dead"));
    }

    /// A channel that drops every tenth sample from 1 s on (8 % missing, never ten in a row) is
    /// reported dead; its onset must be where the drops start (1 s) or unknown (NaN, written
    /// null), not a made-up 0 s.
    #[test]
    fn an_intermittent_channels_onset_is_not_a_made_up_zero() {
        let drops = |tap: usize, idx: usize| tap == 3 && idx >= 1000 && idx.is_multiple_of(10);
        let run = recording(12, |tap, idx, noise| if drops(tap, idx) { f64::NAN } else { healthy(tap, idx, noise) });
        let finding = fault_finding(std::slice::from_ref(&run), 3, TAPS).expect("a finding");
        assert_eq!(text(&finding, "mode"), "dead");
        let start_s = number(&finding, "start_s");
        assert!(start_s.is_nan() || (start_s - 1.0).abs() < 0.01, "start_s = {start_s}");
    }

    /// The dead rule's boundary: a channel missing in exactly 2 % of the samples (100 of 5000)
    /// is not dead, one more sample is.
    #[test]
    fn a_channel_is_dead_only_beyond_two_percent_missing() {
        let missing = |count: usize| {
            let run = recording(4, move |tap, idx, noise| {
                if tap == 2 && (1000..1000 + count).contains(&idx) { f64::NAN } else { healthy(tap, idx, noise) }
            });
            fault_finding(std::slice::from_ref(&run), 2, TAPS)
        };
        let is_dead = |finding: Option<SensorFinding>| finding.is_some_and(|f| text(&f, "mode") == "dead");
        assert!(!is_dead(missing(100)));
        assert!(is_dead(missing(101)));
    }

    /// A dropout of the whole scanner (every channel missing in the same 10 % of the samples) is
    /// no fault of one channel.
    #[test]
    fn a_dropout_of_every_channel_is_no_dead_channel() {
        let run = recording(
            5,
            |tap, idx, noise| if (1000..1500).contains(&idx) { f64::NAN } else { healthy(tap, idx, noise) },
        );
        for tap in 0..TAPS {
            let finding = fault_finding(std::slice::from_ref(&run), tap, TAPS);
            assert!(finding.is_none_or(|f| text(&f, "mode") != "dead"), "tap {tap}");
        }
    }

    /// cp03 with `count` isolated spikes of 20 sigma, alternating in sign, with ordinary
    /// neighbours, spread over the run.
    fn spiky(count: usize) -> RunStreams {
        let at: Vec<usize> = (0..count).map(|k| 130 + 240 * k).collect();
        recording(6, move |tap, idx, noise| {
            let clean = pressure(tap, idx as f64 / HZ, 0.0);
            if tap != 2 {
                return clean + noise;
            }
            match at.iter().position(|&i| i == idx) {
                Some(k) => clean + if k % 2 == 0 { 20.0 } else { -20.0 } * NOISE,
                None if at.iter().any(|&i| i.abs_diff(idx) == 1) => clean,
                None => clean + noise,
            }
        })
    }

    /// Twenty spikes in 5 s on cp03: a spike fault of cp03 at 4 spikes per second, decisive.
    #[test]
    fn spikes_on_one_channel_are_a_spike_fault_at_their_rate() {
        let run = spiky(20);
        let finding = fault_finding(std::slice::from_ref(&run), 2, TAPS).expect("a finding");
        assert_eq!(text(&finding, "mode"), "spike");
        assert_eq!(finding.channel.as_deref(), Some("cp03"));
        assert!((number(&finding, "spike_rate_hz") - 20.0 / DURATION_S).abs() < 1e-12);
        assert!(qualifies(&finding), "{finding:?}");
    }

    /// The spike count must exceed three times the Gaussian tail's count plus three (at 5000
    /// samples: 3.00003): three spikes carry no evidence, four do.
    #[test]
    fn three_spikes_are_chance_and_four_are_a_fault() {
        let three = fault_finding(std::slice::from_ref(&spiky(3)), 2, TAPS);
        if let Some(f) = &three {
            assert!(f.delta_bic < MIN_DELTA_BIC, "{f:?}");
            if text(f, "mode") == "spike" {
                assert_eq!((f.delta_bic, f.explained), (0.0, 0.0));
            }
        }
        let four = fault_finding(std::slice::from_ref(&spiky(4)), 2, TAPS).expect("a finding");
        assert_eq!(text(&four, "mode"), "spike");
        assert!(four.delta_bic >= MIN_DELTA_BIC, "{four:?}");
    }

    /// cp10 reads 0.05 (five noise sigma) high from 2 s on: a bias fault of cp10 of about 0.05
    /// from about 2 s (within a scan cell and a selection block), held to the end of the run.
    #[test]
    fn a_step_in_one_channel_is_a_bias_fault_with_its_value_and_onset() {
        let run =
            recording(7, |tap, idx, noise| healthy(tap, idx, noise) + if tap == 9 && idx >= 2000 { 0.05 } else { 0.0 });
        let finding = fault_finding(std::slice::from_ref(&run), 9, TAPS).expect("a finding");
        assert_eq!(text(&finding, "mode"), "bias");
        assert_eq!(finding.channel.as_deref(), Some("cp10"));
        assert!((number(&finding, "value") - 0.05).abs() < 0.003, "{finding:?}");
        assert!((number(&finding, "start_s") - 2.0).abs() < 0.4, "{finding:?}");
        assert!((number(&finding, "faulty_s") - 3.0).abs() < 0.4, "{finding:?}");
        assert!(qualifies(&finding));
    }

    /// cp01 stuck at one bit-identical reading from 2 s on: a stuck fault of cp01 from about
    /// 2 s, whose evidence says it repeats one reading (longer than `STUCK_MIN_S`).
    #[test]
    fn a_channel_stuck_at_one_reading_is_a_stuck_fault() {
        let run = recording(8, |tap, idx, noise| if tap == 0 && idx >= 2000 { -0.4 } else { healthy(tap, idx, noise) });
        let finding = fault_finding(std::slice::from_ref(&run), 0, TAPS).expect("a finding");
        assert_eq!(text(&finding, "mode"), "stuck");
        assert_eq!(finding.channel.as_deref(), Some("cp01"));
        assert!((number(&finding, "start_s") - 2.0).abs() < 0.4, "{finding:?}");
        assert!(finding.evidence.contains("repeats one reading for 3.00 s"), "{}", finding.evidence);
        assert!(qualifies(&finding));
    }

    /// Channels lagged by `tau_s` (closed form), the others healthy.
    fn lagged(seed: u64, taps: &'static [usize], tau_s: f64) -> RunStreams {
        recording(seed, move |tap, idx, noise| {
            let t_s = idx as f64 / HZ;
            pressure(tap, t_s, if taps.contains(&tap) { tau_s } else { 0.0 }) + noise
        })
    }

    /// cp05 read through a 15.5 ms lag: the lag of cp05 alone, its time constant within one
    /// step of the candidate's grid, gain near 1 (the innovation is the whole lag), decisive.
    #[test]
    fn a_lag_of_one_channel_is_found_on_that_channel() {
        let grid = lag_grid(HZ);
        let tau_s = grid[10];
        let run = lagged(9, &[4], tau_s);
        let found = lag_findings(std::slice::from_ref(&run), TAPS);
        assert_eq!(found.len(), 1);
        let finding = &found[0];
        assert_eq!(finding.effect, Effect::PressureLag);
        assert_eq!(finding.channel.as_deref(), Some("cp05"));
        assert_eq!(finding.channels, vec!["cp05".to_owned()]);
        let fitted = number(finding, "tau_s_cp05");
        assert!((grid[9]..=grid[11]).contains(&fitted), "{fitted} for {tau_s}");
        assert!((number(finding, "gain_cp05") - 1.0).abs() < 0.1, "{finding:?}");
        assert!(qualifies(finding), "{finding:?}");
    }

    /// Five of twelve channels lagged: the five are named together (no single channel), each
    /// with its time constant.
    #[test]
    fn a_lag_of_some_channels_names_exactly_those_channels() {
        let grid = lag_grid(HZ);
        let run = lagged(10, &[1, 4, 6, 9, 11], grid[12]);
        let found = lag_findings(std::slice::from_ref(&run), TAPS);
        assert_eq!(found.len(), 1);
        let finding = &found[0];
        assert_eq!(finding.channel, None);
        assert_eq!(finding.channels, ["cp02", "cp05", "cp07", "cp10", "cp12"].map(String::from).to_vec());
        assert_eq!(text(finding, "channels"), "cp02,cp05,cp07,cp10,cp12");
        for name in &finding.channels {
            let fitted = number(finding, &format!("tau_s_{name}"));
            assert!((grid[11]..=grid[13]).contains(&fitted), "{name}: {fitted}");
        }
    }

    /// A deviation that grows slower than any lag searched (cp05 reads the pressure plus a
    /// fifth of what a 5 s lag would take off it, a slow change of its scale) has its best fit at
    /// the grid's longest time constant: no lag of cp05 is named.
    #[test]
    fn a_deviation_slower_than_any_lag_searched_is_no_lag() {
        let tau_s = 5.0;
        let run = recording(12, move |tap, idx, noise| {
            let t_s = idx as f64 / HZ;
            let (unlagged, lagged) = (pressure(tap, t_s, 0.0), pressure(tap, t_s, tau_s));
            unlagged + if tap == 4 { 0.2 * (lagged - unlagged) } else { 0.0 } + noise
        });
        let found = lag_findings(std::slice::from_ref(&run), TAPS);
        assert!(found.iter().all(|finding| !qualifies(finding)), "{found:?}");
    }

    /// Six of twelve channels with lag evidence of 5 to 10 noise variances, the others 0.1 to
    /// 0.6: against the median of all twelve (a lagged channel's), nothing stands out; against
    /// the median outside the group, all six do, and a healthy channel does not. Fits at the
    /// grid's end are no lag and count as no evidence.
    #[test]
    fn the_typical_channel_is_the_median_outside_the_group() {
        let evidence = [5.0, 0.1, 6.0, 0.2, 7.0, 0.3, 8.0, 0.4, 9.0, 0.5, 10.0, 0.6];
        let best: Vec<Option<(usize, f64)>> = evidence.iter().enumerate().map(|(tap, v)| Some((tap, *v))).collect();
        assert!(standing_out(&best, &[false; 12]).is_empty());
        let group: Vec<bool> = (0..12).map(|tap| tap % 2 == 0).collect();
        let found: Vec<usize> = standing_out(&best, &group).iter().map(|(tap, _)| *tap).collect();
        assert_eq!(found, vec![0, 2, 4, 6, 8, 10]);
        let mut without_some = best.clone();
        without_some[1] = None;
        without_some[3] = None;
        // The outside median falls to 0.4: four times it is 1.6, still below every member.
        assert_eq!(standing_out(&without_some, &group).len(), 6);
        assert!(standing_out(&best, &[true; 12]).is_empty(), "no channel outside: no reference");
    }

    /// A lag common to every channel does not show in the innovations as one channel standing
    /// out: the innovation candidate names nothing (it is the alignment's, `pressure_lag`).
    #[test]
    fn a_lag_of_every_channel_is_not_an_innovation_finding() {
        let every: &'static [usize] = &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11];
        let run = lagged(11, every, lag_grid(HZ)[10]);
        assert!(lag_findings(std::slice::from_ref(&run), TAPS).is_empty());
    }
}
