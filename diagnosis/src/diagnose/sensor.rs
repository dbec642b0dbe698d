//! Sensor candidates, on the pressure filter's per-channel innovations (docs/diagnosis.md,
//! Sensor checks): a tubing lag (the innovation follows `-tau dp/dt`, on every channel or
//! on some) and a faulty channel (stuck, dead, biased, drifting, wrong gain, noisy or spiking: one channel departs from the
//! other eleven). Gaps here are in Cp units.

use firmware_sim::effect::Effect;

use super::faults;
use super::finding::{ParamValue, SensorFinding, channel_name, strength};
use super::regression::{self, Fit, Segment, delta_bic};
use super::streams::RunStreams;

/// Shortest run of identical raw readings that counts as a stuck channel, s: a live transducer
/// with any noise never repeats its reading this long.
const STUCK_MIN_S: f64 = 0.05;

/// Innovation beyond this many robust standard deviations is a spike.
const SPIKE_SIGMA: f64 = 6.0;

/// How many times the typical channel's lag evidence a channel's must be to stand out as lagged.
const STAND_OUT: f64 = 4.0;

/// Longest burst that still counts as a spike, samples: the contract's spikes are "single
/// samples or bursts" (docs/spec/diagnosis.md, pressure_fault); the tunnels' bursts last up to
/// 40 samples (docs/diagnosis.md, Pressure faults). A longer excursion is a step, a lag or the
/// flow, not a spike.
const SPIKE_MAX_BURST: usize = 40;

/// Innovation beyond this many robust standard deviations is out of the ordinary: a spike's
/// neighbours must be within it, and a burst is the stretch of samples beyond it around a
/// sample beyond [`SPIKE_SIGMA`] (a burst's samples need not all be that large).
const ORDINARY_SIGMA: f64 = 3.0;

/// Every sensor finding, strongest first ([`scan`]'s ranked findings).
#[must_use]
pub fn findings<'a>(
    runs: &[RunStreams],
    reference: impl Into<super::pressure_lag::Reference<'a>>,
) -> Vec<SensorFinding> {
    scan(runs, reference, None).ranked
}

/// What the sensor families find.
#[derive(Debug, Clone, Default)]
pub struct Findings {
    /// Every finding, strongest first.
    pub ranked: Vec<SensorFinding>,
    /// A lag of each channel alone, at its best time constant, judged on what the filter
    /// without the channel expects of it: not named, the floors of a lag of any set of channels
    /// in the sim's signature (keyed by [`channel_lag_key`]). What the family finds on each
    /// channel of data without a lag is the pressure model's own error there; the family's
    /// choice of a set is made on the channels that stand out, so the set the sim's own data
    /// chose says nothing of the others.
    pub channel_lags: Vec<SensorFinding>,
}

/// Every sensor finding, and the lag of each channel alone. `reference` is the sim's own
/// alignment of the taps with the balance and its scatter (`pressure_lag::finding`).
#[must_use]
pub fn scan<'a>(
    runs: &[RunStreams],
    reference: impl Into<super::pressure_lag::Reference<'a>>,
    own_channel_lags: Option<&super::lag_set::ChannelLags>,
) -> Findings {
    let reference = reference.into();
    let reference_tau_s = reference.tau_s;
    let Some(first) = runs.first().filter(|run| !run.cp.is_empty()) else { return Findings::default() };
    let (n_taps, grid) = (first.cp.len(), lag_grid(first.sample_hz));
    let alone: Judged<'_> =
        runs.iter().map(|run| run.innovation_alone.iter().take(n_taps).map(Vec::as_slice).collect()).collect();
    let best_alone = best_lags(runs, &alone, &grid, n_taps);
    let mut out = Vec::new();
    let mut alignment = super::pressure_lag::finding(runs, reference);
    let mut some = lag_findings(runs, n_taps, &alone, &best_alone, &grid);
    // A lag of some channels shifts the alignment of all twelve too, and a lag of every channel
    // can leave some standing out in the innovations: the balance, which reads the pressures
    // without lag, tells the two apart. Only a lag the alignment finds at all (the least effect
    // to name) can be common.
    let common_lag = alignment.as_ref().filter(|finding| strength(finding) >= least_strength());
    // A lag the alignment finds may be of some channels or of all: each channel's own, from
    // how the channels' lags differ and the lag they share, names the set and each time
    // constant ([`super::pressure_lag::set_finding`]).
    // The full search runs where a lag shows at all: the alignment's, a group's, or a first
    // step that moves a channel beyond the sim's own by the least lag of a set.
    let first_step_shows = || {
        // Without the sim's own first step (a signature written before it was kept), the
        // pressure model's own differences would pass for a lag on every recording.
        let Some(own) = own_channel_lags.filter(|own| !own.first_step_s.is_empty()) else { return false };
        let first = super::lag_set::first_step(runs);
        let deviation: Vec<f64> =
            first.iter().enumerate().map(|(tap, v)| v - own.first_step_s.get(tap).copied().unwrap_or(0.0)).collect();
        let (low, high) = deviation.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
        high - low >= super::pressure_lag::MIN_CHANNEL_LAG_S
    };
    if (common_lag.is_some() || !some.is_empty() || first_step_shows())
        && let Some(set) = super::lag_set::identify(runs).and_then(|lags| {
            let set = super::pressure_lag::channel_set(runs, reference, &lags, own_channel_lags, common_lag.is_some())?;
            let lags_of = |set: &[(usize, f64)]| {
                let mut lag_s = vec![0.0; n_taps];
                for &(tap, lag) in set {
                    lag_s[tap] = lag;
                }
                lag_s
            };
            let mut judged = super::lag_set::judged(runs, &lags_of(&set));
            // Every channel named must show its own lag on the selection part; the others are
            // judged again without the de-lag of those that do not.
            let confirmed = confirmed_members(runs, &self::judged(&judged), &set);
            let set: Vec<(usize, f64)> =
                set.into_iter().zip(&confirmed).filter(|(_, ok)| **ok).map(|(m, _)| m).collect();
            if set.is_empty() {
                return None;
            }
            if confirmed.contains(&false) {
                judged = super::lag_set::judged(runs, &lags_of(&set));
            }
            set_finding(runs, &judged, &set, n_taps, reference_tau_s)
        })
    {
        // The group the innovations found stays a candidate beside it: where the balance cannot
        // confirm a lag on the selection part (a rig the sim fits poorly), the innovations can.
        if some.first().is_some_and(|group| group.channels == set.channels) {
            some.clear();
        }
        alignment = Some(set);
    } else if let (Some(_), Some(group)) = (common_lag, some.first().filter(|finding| finding.channels.len() < n_taps))
    {
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
    Findings { ranked: out, channel_lags: channel_lags(runs, &alone, &best_alone, &grid) }
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
                "one channel: dead (missing where the others read); stuck from an onset per run (bit-identical readings, or a constant with the sensor's noise that stops following the pressure); from an onset per run (or none) to the run's end, with one value for every run: a bias, a drift (a ramp from the onset), a wrong gain (the reading g Cp), on what the other channels expect of it; extra noise (a variance ratio test on the innovation's differences, one added variance); spikes, single samples or bursts of up to {SPIKE_MAX_BURST} samples beyond {ORDINARY_SIGMA} robust standard deviations holding one beyond {SPIKE_SIGMA}"
            ),
        ),
    ]
}

/// Time constants of the lag candidate, s: a log grid from two samples to half a second (about
/// five points an octave). A best fit at the longest is no lag, so the grid reaches far beyond a
/// tube's tens of milliseconds (docs/diagnosis.md, Pressure lag). Without a least gain, a longer
/// grid takes a slow change of a channel's scale for a lag (a 0.48 s lag at gain 0.19 for a
/// fifth of a 5 s lag), so lags near half a second are beyond what the family tells.
fn lag_grid(sample_hz: f64) -> Vec<f64> {
    super::candidates::log_grid(2.0 / sample_hz, 0.5, 28)
}

/// The lag column of one channel: `LP_tau[expected] - expected`, with `expected` what the
/// filter run without the channel expects of it (measured minus the judged innovation): a
/// lagged sensor reads the expected pressure through its lag (docs/diagnosis.md, Pressure lag,
/// the first-order form).
fn lag_column(run: &RunStreams, innovation: &[f64], tap: usize, tau_s: f64) -> Vec<f64> {
    let expected: Vec<f64> = run.cp[tap].iter().zip(innovation).map(|(cp, nu)| cp - nu).collect();
    let held = model_fit::fit::signals::hold_missing(
        &expected,
        expected.iter().copied().find(|v| v.is_finite()).unwrap_or(0.0),
    );
    let lagged = super::candidates::first_order_lag(&held, tau_s, 1.0 / run.sample_hz);
    lagged.iter().zip(&held).map(|(l, e)| l - e).collect()
}

/// The lag column of one channel from its own reading: `-tau y'`, the deviation of a reading
/// `y` lagged by `tau` from the true pressure, exactly (`p = y + tau y'`; [`RunStreams::cp_dot`],
/// 0 where the channel is missing).
fn reading_lag_column(run: &RunStreams, tap: usize, tau_s: f64) -> Vec<f64> {
    run.cp_dot[tap].iter().map(|dy| if dy.is_finite() { -tau_s * dy } else { 0.0 }).collect()
}

/// A member's lag column in every run and its fit to the member's judged innovation over the
/// training part less the selection blocks: of two estimates of the lag's deviation `-tau p'`,
/// the one that explains more there.
///
/// Why two: each carries its own error, and which is smaller depends on the rig. What the other
/// channels expect ([`lag_column`]) carries their noise and the pressure model's error through
/// the lag's high-pass; on a rig the model fits poorly its gain came out 0.1 to 0.4 for channels
/// lagged by tens of milliseconds (errors in variables). The channel's own reading
/// ([`reading_lag_column`]) carries only its own noise, differentiated; on this project's tunnel,
/// whose model fits well and whose weaker channels hold little signal, its gains came out 0.06 to
/// 0.6 for a lag of every channel, where the expectation gave 0.95 to 1.05. The choice is made on
/// the training part; the selection part confirms it ([`confirmed_members`]).
fn member_column(
    runs: &[RunStreams],
    judged: &Judged<'_>,
    tap: usize,
    tau_s: f64,
) -> Option<(Vec<Vec<Vec<f64>>>, Fit)> {
    let segments = segments_judged(runs, judged, tap);
    let expected: Vec<Vec<Vec<f64>>> =
        runs.iter().zip(judged).map(|(run, nu)| vec![lag_column(run, nu[tap], tap, tau_s)]).collect();
    let reading: Vec<Vec<Vec<f64>>> = runs.iter().map(|run| vec![reading_lag_column(run, tap, tau_s)]).collect();
    [expected, reading]
        .into_iter()
        .filter_map(|columns| regression::fit_through_origin(&segments, &columns).map(|fit| (columns, fit)))
        .min_by(|a, b| a.1.ssr.total_cmp(&b.1.ssr))
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
fn lag_findings<'a>(
    runs: &'a [RunStreams],
    n_taps: usize,
    alone: &Judged<'a>,
    best_alone: &[Option<(usize, f64)>],
    grid: &[f64],
) -> Vec<SensorFinding> {
    let mut lagged = standing_out(best_alone, &vec![false; n_taps]);
    let group_of = |lagged: &[(usize, usize)]| -> Vec<bool> {
        (0..n_taps).map(|tap| lagged.iter().any(|(member, _)| *member == tap)).collect()
    };
    let refine = |group: Vec<bool>| {
        let innovations = without_group(runs, &group);
        let best = { best_lags(runs, &judged(&innovations), grid, n_taps) };
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
        None => alone.clone(),
    };
    // Each member must show its own lag on the selection part.
    let taus: Vec<(usize, f64)> = lagged.iter().map(|&(tap, tau_idx)| (tap, grid[tau_idx])).collect();
    let confirmed = confirmed_members(runs, &judged, &taus);
    lagged = lagged.into_iter().zip(confirmed).filter(|(_, ok)| *ok).map(|(member, _)| member).collect();
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

/// The finding of a lagged set (`set`: each channel and its lag, s), judged on the innovations
/// of each member with every other channel de-lagged (`judged`, [`super::lag_set::Judged`]):
/// one column per member at its own time constant, pooled, as a group's
/// ([`lag_findings`]). `reference_tau_s` (the sim's own alignment) marks it as a whole set
/// ([`super::finding::is_set_lag`]).
fn set_finding(
    runs: &[RunStreams],
    judged: &super::lag_set::Judged,
    set: &[(usize, f64)],
    n_taps: usize,
    reference_tau_s: f64,
) -> Option<SensorFinding> {
    let judged: Judged<'_> = judged.iter().map(|run| run.iter().map(Vec::as_slice).collect()).collect();
    let (mut segments, mut columns) = (Vec::new(), Vec::new());
    for (slot, &(tap, tau_s)) in set.iter().enumerate() {
        let (own, _) = member_column(runs, &judged, tap, tau_s)?;
        segments.extend(segments_judged(runs, &judged, tap));
        columns.extend(own.into_iter().map(|mut run| {
            let own = run.swap_remove(0);
            let zeros = vec![0.0; own.len()];
            (0..set.len()).map(|s| if s == slot { own.clone() } else { zeros.clone() }).collect::<Vec<_>>()
        }));
    }
    let fit = regression::fit_through_origin(&segments, &columns)?;
    let mut finding = lag_finding(&segments, &columns, &fit, set, 2 * set.len());
    // The choice of the channels costs ln C(n, k).
    finding.delta_bic -= (1..=set.len()).map(|i| ((n_taps - set.len() + i) as f64 / i as f64).ln()).sum::<f64>();
    finding.params.push(("reference_tau_s".to_owned(), ParamValue::Number(reference_tau_s)));
    Some(finding)
}

/// Which members of a lagged set (`set`: each channel and its lag, s) show their own lag on the
/// selection part: the member's innovation, judged with the other members de-lagged (`judged`),
/// regressed on its lag column ([`member_column`]) over the training part less the selection
/// blocks, must fit a gain that makes the lag it shows (gain times time constant) at least the
/// least lag of a channel ([`super::pressure_lag::MIN_CHANNEL_LAG_S`]; positive: a lag's reading
/// follows the pressure late, never early), and the selection blocks' residual, regressed on
/// that fitted prediction, must stand [`super::attribution::CONFIRM_Z`] standard errors above
/// zero (the calibration slope of the balance candidates, [`super::attribution::Slope`]; its
/// noise the innovation's mean square there, its correlation time the innovation's). The
/// contract's report names every lagged channel, so each one needs its own evidence: the set is
/// chosen from how the channels' lags differ, and where the pressure model fits a rig poorly a
/// healthy channel's apparent lag moves with the lags around it.
fn confirmed_members(runs: &[RunStreams], judged: &Judged<'_>, set: &[(usize, f64)]) -> Vec<bool> {
    set.iter()
        .map(|&(tap, tau_s)| {
            let segments = segments_judged(runs, judged, tap);
            let Some((columns, fit)) = member_column(runs, judged, tap, tau_s) else { return false };
            let gain = fit.beta[0];
            let (mut rp, mut pp, mut rr, mut n) = (0.0, 0.0, 0.0, 0usize);
            for (segment, cols) in segments.iter().zip(&columns) {
                for i in segment.select.samples() {
                    let (r, predicted) = (segment.residual[i], gain * cols[0][i]);
                    if r.is_finite() && predicted.is_finite() {
                        rp += r * predicted;
                        pp += predicted * predicted;
                        rr += r * r;
                        n += 1;
                    }
                }
            }
            if n == 0 {
                return false;
            }
            let autocorrelation = regression::integrated_autocorrelation(&segments, 50);
            let slope = super::attribution::Slope::from_sums(rp, pp, rr / n as f64, autocorrelation);
            gain * tau_s >= super::pressure_lag::MIN_CHANNEL_LAG_S && slope.confirmed()
        })
        .collect()
}

/// The key of a lag of `channel` alone in the sim's signature ([`Findings::channel_lags`]).
#[must_use]
pub fn channel_lag_key(channel: &str) -> String {
    format!("{}:{channel}:alone", Effect::PressureLag)
}

/// A lag of each channel alone at its best time constant `best_alone`, judged on `alone`
/// ([`Findings::channel_lags`]).
fn channel_lags(
    runs: &[RunStreams],
    alone: &Judged<'_>,
    best_alone: &[Option<(usize, f64)>],
    grid: &[f64],
) -> Vec<SensorFinding> {
    best_alone
        .iter()
        .enumerate()
        .filter_map(|(tap, best)| {
            let (tau_idx, _) = (*best)?;
            let segments = segments_judged(runs, alone, tap);
            let columns: Vec<Vec<Vec<f64>>> =
                runs.iter().zip(alone).map(|(run, nu)| vec![lag_column(run, nu[tap], tap, grid[tau_idx])]).collect();
            let fit = regression::fit_through_origin(&segments, &columns)?;
            Some(lag_finding(&segments, &columns, &fit, &[(tap, grid[tau_idx])], 2))
        })
        .collect()
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

/// The fault candidate of one channel (docs/spec/diagnosis.md, pressure_fault: "stuck, dead
/// (missing), biased, drifting, with a wrong gain, with extra noise, or spiking"): dead when
/// missing where the others read; otherwise the form with the most evidence (delta BIC) among
/// stuck, spike, bias, drift, gain and noise. Bias, drift and gain have one parameter for every
/// run and an onset per run ([`faults::fit_shared`]); noise is a variance ratio test
/// ([`faults::fit_noise`]).
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
        // The training part fixes the intervals and the frozen readings; the parts are judged
        // with them ([`faults::part_gap`]).
        let trained = faults::Trained::new(runs, tap, faults::Shape::Stuck, &stuck);
        let part_gap = |heldout: bool| faults::part_gap(runs, tap, faults::Shape::Stuck, tau, &trained, heldout);
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
    // Spikes: single innovations, or bursts of up to SPIKE_MAX_BURST samples, far beyond the
    // channel's robust spread. The count is of spikes (a burst is one), against the Gaussian
    // tail's count of samples beyond SPIKE_SIGMA.
    let robust_sigma = robust_sigma(&segments);
    let spike_columns: Vec<Vec<Vec<f64>>> =
        runs.iter().map(|run| vec![spike_column(&run.innovation[tap], robust_sigma)]).collect();
    if let Some(fit) = regression::fit_through_origin(&segments, &spike_columns) {
        let count: usize = spike_columns.iter().map(|cols| spike_events(&cols[0])).sum();
        let duration_s: f64 = runs.iter().map(|run| run.len() as f64 / run.sample_hz).sum();
        let first_spike_s = runs
            .iter()
            .zip(&spike_columns)
            .filter_map(|(run, cols)| cols[0].iter().position(|v| *v != 0.0).map(|i| run.t_s[i]))
            .fold(f64::INFINITY, f64::min);
        // A spike count the Gaussian tail explains is not a fault.
        let expected = gaussian_tail(SPIKE_SIGMA) * runs.iter().map(RunStreams::len).sum::<usize>() as f64;
        let delta = if (count as f64) > 3.0 * expected + 3.0 { delta_bic(&fit, tau, 1) } else { 0.0 };
        shapes.push(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("spike".into())),
                ("spike_rate_hz".into(), ParamValue::Number(count as f64 / duration_s.max(f64::MIN_POSITIVE))),
                ("start_s".into(), ParamValue::Number(first_spike_s)),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            explained: if delta > 0.0 { fit.explained_per_sample() } else { 0.0 },
            noise_var,
            delta_bic: delta,
            heldout: regression::heldout_gap(&segments, &spike_columns, &[1.0], &fit.touched),
            selection: regression::selection_gap(&segments, &spike_columns, &[1.0], &fit.touched),
            evidence: format!(
                "{name} has {count} spikes (single samples or bursts) beyond {SPIKE_SIGMA} robust sigma (Gaussian tail: {expected:.1})"
            ),
        });
    }
    // Bias, drift, wrong gain: one value of the channel for every run, from each run's own
    // onset (or none) to its end, on what the other channels expect of it.
    let judged_segments = faults::segments_judged(runs, tap);
    let judged_tau = regression::integrated_autocorrelation(&judged_segments, 50);
    let judged_noise_var = regression::difference_noise_var(&judged_segments, None).max(f64::MIN_POSITIVE);
    for form in faults::Form::ALL {
        let Some(shared) = faults::fit_shared(runs, tap, form, judged_tau) else { continue };
        let columns = shared.columns(runs, tap);
        let Some(fit) = regression::fit_through_origin(&judged_segments, &columns) else { continue };
        let value = form.reported(shared.beta);
        let start_s = shared.start_s();
        let runs_with = shared.runs_with();
        shapes.push(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text(form.mode().into())),
                (form.parameter().into(), ParamValue::Number(value)),
                ("start_s".into(), ParamValue::Number(start_s)),
                ("faulty_s".into(), ParamValue::Number(shared.faulty_s(runs))),
                ("runs".into(), ParamValue::Number(runs_with as f64)),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            explained: fit.explained_per_sample(),
            noise_var: judged_noise_var,
            // One shared parameter and an onset per faulty run.
            delta_bic: delta_bic(&fit, judged_tau, 1 + runs_with),
            heldout: faults::shared_part_gap(runs, tap, &shared, judged_tau, true),
            selection: faults::shared_part_gap(runs, tap, &shared, judged_tau, false),
            evidence: format!(
                "{name} departs from what the other channels expect of it by one {} of {value:.4} from t = {start_s:.2} s in {runs_with} run(s)",
                form.mode()
            ),
        });
    }
    // Extra noise: the innovation's variance rises from an onset, by one added variance.
    if let Some(noise) = faults::fit_noise(runs, tap, n_taps) {
        let start_s = noise.onset_s.iter().flatten().copied().fold(f64::INFINITY, f64::min);
        let runs_with = noise.onset_s.iter().flatten().count();
        let noise_rms = noise.added_var.sqrt();
        shapes.push(SensorFinding {
            effect: Effect::PressureFault,
            params: vec![
                ("mode".into(), ParamValue::Text("noise".into())),
                ("noise_rms".into(), ParamValue::Number(noise_rms)),
                ("start_s".into(), ParamValue::Number(start_s)),
                ("runs".into(), ParamValue::Number(runs_with as f64)),
            ],
            channel: Some(name.clone()),
            channels: vec![name.clone()],
            explained: noise.added_var,
            noise_var: noise.base_var,
            delta_bic: noise.delta_bic,
            heldout: faults::noise_part_gap(runs, tap, &noise, true),
            selection: faults::noise_part_gap(runs, tap, &noise, false),
            evidence: format!(
                "{name}'s noise rises by {noise_rms:.4} RMS (own {:.4}) from t = {start_s:.2} s in {runs_with} run(s)",
                noise.base_var.sqrt()
            ),
        });
    }
    shapes.into_iter().max_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic))
}

/// The spikes of one innovation series: single samples or bursts of up to [`SPIKE_MAX_BURST`]
/// samples, each a stretch of samples beyond [`ORDINARY_SIGMA`] robust standard deviations that
/// holds at least one beyond [`SPIKE_SIGMA`], with ordinary samples (within
/// [`ORDINARY_SIGMA`], or missing) on both sides; zero elsewhere. A longer excursion is a lag or
/// a step, not a spike; one at the run's first or last sample has no neighbour on that side (the
/// pressure filter's first innovations are its start-up, not a reading).
fn spike_column(nu: &[f64], robust_sigma: f64) -> Vec<f64> {
    let beyond = |idx: usize, sigmas: f64| nu[idx].is_finite() && nu[idx].abs() > sigmas * robust_sigma;
    let mut out = vec![0.0; nu.len()];
    let mut idx = 0;
    while idx < nu.len() {
        if !beyond(idx, ORDINARY_SIGMA) {
            idx += 1;
            continue;
        }
        let start = idx;
        while idx < nu.len() && beyond(idx, ORDINARY_SIGMA) {
            idx += 1;
        }
        // Inside the run: an excursion at either end has no ordinary sample on that side to
        // tell it from the filter's start-up or the record's end.
        let inside = start > 0 && idx < nu.len();
        if inside && idx - start <= SPIKE_MAX_BURST && (start..idx).any(|i| beyond(i, SPIKE_SIGMA)) {
            out[start..idx].copy_from_slice(&nu[start..idx]);
        }
    }
    out
}

/// The spikes (single samples or bursts) in a spike column: its stretches of non-zero values.
fn spike_events(column: &[f64]) -> usize {
    column.iter().enumerate().filter(|(i, v)| **v != 0.0 && (*i == 0 || column[i - 1] == 0.0)).count()
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

/// The robust spread of the training innovations ([`stats::mad_sigma`]).
fn robust_sigma(segments: &[Segment<'_>]) -> f64 {
    let mut values: Vec<f64> = segments
        .iter()
        .flat_map(|segment| segment.training.clone().map(|i| segment.residual[i]))
        .filter(|v| v.is_finite())
        .collect();
    stats::mad_sigma(&mut values).unwrap_or(f64::INFINITY)
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
mod tests;
