//! Tests of [`super`]: the sensor module on synthetic runs with known answers.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::*;
use crate::diagnose::pressure_lag::tests as lag_runs;
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
        let mut nu = vec![0.0; 100];
        nu[10..10 + length].fill(2.0 * SPIKE_SIGMA);
        spike_column(&nu, 1.0)
    };
    assert_eq!(burst(SPIKE_MAX_BURST).iter().filter(|v| **v != 0.0).count(), SPIKE_MAX_BURST);
    assert!(burst(SPIKE_MAX_BURST + 1).iter().all(|v| *v == 0.0));
}

/// A spike needs ordinary neighbours: the samples beyond 3 sigma next to one beyond the spike
/// threshold belong to it (a burst, kept whole), and the burst ends at an ordinary sample (at
/// exactly 3 sigma) or a missing one; one at the run's first or last sample has no neighbour
/// there (the filter's start-up: dropped); stretched beyond `SPIKE_MAX_BURST` samples by its
/// neighbours it is a larger excursion (dropped).
#[test]
fn a_spike_needs_ordinary_neighbours() {
    let with_neighbour = |neighbour: f64| {
        let mut nu = vec![0.0; 20];
        nu[10] = 2.0 * SPIKE_SIGMA;
        nu[9] = neighbour;
        let column = spike_column(&nu, 1.0);
        (column[9], column[10])
    };
    assert_eq!(with_neighbour(3.0 + 1e-9), (3.0 + 1e-9, 2.0 * SPIKE_SIGMA));
    assert_eq!(with_neighbour(-3.0 - 1e-9), (-3.0 - 1e-9, 2.0 * SPIKE_SIGMA));
    assert_eq!(with_neighbour(3.0), (0.0, 2.0 * SPIKE_SIGMA));
    assert_eq!(with_neighbour(f64::NAN), (0.0, 2.0 * SPIKE_SIGMA));
    let mut ends = vec![0.0; 10];
    ends[0] = 10.0;
    ends[9] = -10.0;
    assert!(spike_column(&ends, 1.0).iter().all(|v| *v == 0.0));
    let mut excursion = vec![0.0; 100];
    excursion[10..10 + SPIKE_MAX_BURST].fill(4.0);
    excursion[30] = 2.0 * SPIKE_SIGMA;
    assert_eq!(spike_column(&excursion, 1.0), excursion, "a burst of the longest length");
    excursion[10 + SPIKE_MAX_BURST] = 4.0;
    assert!(spike_column(&excursion, 1.0).iter().all(|v| *v == 0.0), "one sample longer");
}

/// A burst counts as one spike: two bursts and a single sample are three.
#[test]
fn a_burst_is_one_spike() {
    let mut nu = vec![0.0; 100];
    nu[10..20].fill(10.0);
    nu[40] = -10.0;
    nu[60..90].fill(10.0);
    assert_eq!(spike_events(&spike_column(&nu, 1.0)), 3);
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
/// deviation 1, so `MAD_TO_STD`; held-out values and missing ones do not count; without values
/// the spread is unknown (infinite), never 0 (which would make every sample a spike).
#[test]
fn the_robust_spread_uses_the_finite_training_values() {
    let residual = [1.0, 2.0, f64::NAN, 3.0, 4.0, 5.0, 100.0, 100.0];
    let segments = [Segment { residual: &residual, training: 0..6, select: Interleave::default(), heldout: 6..8 }];
    assert_eq!(robust_sigma(&segments), stats::MAD_TO_STD);
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
    let run = recording(3, |tap, idx, noise| if tap == 6 && idx >= 2000 { f64::NAN } else { healthy(tap, idx, noise) });
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
    let run =
        recording(5, |tap, idx, noise| if (1000..1500).contains(&idx) { f64::NAN } else { healthy(tap, idx, noise) });
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
    let found = lags_of(std::slice::from_ref(&run), TAPS);
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
    let found = lags_of(std::slice::from_ref(&run), TAPS);
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

/// cp02 and cp05 read through a 20 ms lag; a set that also holds the healthy cp08 (an apparent
/// lag from the lags around it) keeps the two whose innovations follow their lag, `-tau y'`, on
/// the selection blocks, and not cp08, whose innovation is the noise alone.
#[test]
fn a_set_member_without_its_own_lag_on_the_selection_part_is_dropped() {
    let tau_s = 0.02;
    let run = lagged(13, &[1, 4], tau_s);
    let runs = std::slice::from_ref(&run);
    let judged: Judged<'_> = vec![run.innovation_alone.iter().map(Vec::as_slice).collect()];
    assert_eq!(confirmed_members(runs, &judged, &[(1, tau_s), (4, tau_s), (7, tau_s)]), [true, true, false]);
}

/// A channel that reads early (its innovation the negative of a lag's) is no lagged channel,
/// however clearly its innovation follows the column: a lag's gain is positive, and the lag it
/// shows, gain times time constant, at least the least lag of a channel.
#[test]
fn a_channel_that_reads_early_is_no_lagged_member() {
    let tau_s = 0.02;
    let run = recording(14, move |tap, idx, noise| {
        let t_s = idx as f64 / HZ;
        let (unlagged, lagged) = (pressure(tap, t_s, 0.0), pressure(tap, t_s, tau_s));
        unlagged - if tap == 4 { lagged - unlagged } else { 0.0 } + noise
    });
    let runs = std::slice::from_ref(&run);
    let judged: Judged<'_> = vec![run.innovation_alone.iter().map(Vec::as_slice).collect()];
    assert_eq!(confirmed_members(runs, &judged, &[(4, tau_s)]), [false]);
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
    let found = lags_of(std::slice::from_ref(&run), TAPS);
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
    assert!(lags_of(std::slice::from_ref(&run), TAPS).is_empty());
}

/// One channel's reading with `fault(t_s, pressure)` added, the others healthy.
fn faulty(seed: u64, tap_faulty: usize, fault: impl Fn(f64, f64) -> f64) -> RunStreams {
    recording(seed, move |tap, idx, noise| {
        let (t_s, p) = (idx as f64 / HZ, pressure(tap, idx as f64 / HZ, 0.0));
        p + noise + if tap == tap_faulty { fault(t_s, p) } else { 0.0 }
    })
}

/// cp04 drifts by 0.02 per second from 1.5 s: a drift fault of cp04 at that rate, from about
/// 1.5 s (within a selection block), decisive.
#[test]
fn a_drifting_channel_is_named_drift_with_its_rate() {
    let run = faulty(20, 3, |t_s, _| if t_s >= 1.5 { 0.02 * (t_s - 1.5) } else { 0.0 });
    let finding = fault_finding(std::slice::from_ref(&run), 3, TAPS).expect("a finding");
    assert_eq!(text(&finding, "mode"), "drift", "{finding:?}");
    assert_eq!(finding.channel.as_deref(), Some("cp04"));
    assert!((number(&finding, "rate_per_s") - 0.02).abs() < 0.002, "{finding:?}");
    assert!((number(&finding, "start_s") - 1.5).abs() < 0.4, "{finding:?}");
    assert!(qualifies(&finding), "{finding:?}");
}

/// cp06 reads 1.1 times the pressure from 1 s: a gain fault of cp06 of 1.1.
#[test]
fn a_wrong_gain_is_named_with_its_gain() {
    let run = faulty(21, 5, |t_s, p| if t_s >= 1.0 { 0.1 * p } else { 0.0 });
    let finding = fault_finding(std::slice::from_ref(&run), 5, TAPS).expect("a finding");
    assert_eq!(text(&finding, "mode"), "gain", "{finding:?}");
    assert_eq!(finding.channel.as_deref(), Some("cp06"));
    assert!((number(&finding, "gain") - 1.1).abs() < 0.01, "{finding:?}");
    assert!((number(&finding, "start_s") - 1.0).abs() < 0.4, "{finding:?}");
    assert!(qualifies(&finding), "{finding:?}");
}

/// cp08's noise grows fourfold in RMS (0.04 added) from 2 s: a noise fault with `noise_rms`
/// near 0.04 (the added noise's RMS), from about 2 s.
#[test]
fn extra_noise_from_an_onset_is_named_noise() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(22);
    let extra = Normal::new(0.0, 4.0 * NOISE).expect("a valid deviation");
    let added: Vec<f64> = (0..N).map(|_| extra.sample(&mut rng)).collect();
    let run = recording(23, |tap, idx, noise| {
        healthy(tap, idx, noise) + if tap == 7 && idx >= 2000 { added[idx] } else { 0.0 }
    });
    let finding = fault_finding(std::slice::from_ref(&run), 7, TAPS).expect("a finding");
    assert_eq!(text(&finding, "mode"), "noise", "{finding:?}");
    assert_eq!(finding.channel.as_deref(), Some("cp08"));
    assert!((number(&finding, "noise_rms") - 4.0 * NOISE).abs() < 0.4 * NOISE, "{finding:?}");
    assert!((number(&finding, "start_s") - 2.0).abs() < 0.2, "{finding:?}");
    assert!(qualifies(&finding), "{finding:?}");
}

/// Bursts of thirty samples of 20 sigma on cp09 (ordinary samples around them), one every
/// 0.8 s: a spike fault of cp09 counting each burst once.
#[test]
fn a_burst_of_thirty_samples_is_a_spike() {
    let starts: Vec<usize> = (0..6).map(|k| 300 + 800 * k).collect();
    let run = recording(24, |tap, idx, noise| {
        let in_burst = starts.iter().any(|&s| (s..s + 30).contains(&idx));
        healthy(tap, idx, noise) + if tap == 8 && in_burst { 20.0 * NOISE } else { 0.0 }
    });
    let finding = fault_finding(std::slice::from_ref(&run), 8, TAPS).expect("a finding");
    assert_eq!(text(&finding, "mode"), "spike", "{finding:?}");
    assert_eq!(finding.channel.as_deref(), Some("cp09"));
    assert!((number(&finding, "spike_rate_hz") - 6.0 / DURATION_S).abs() < 1e-12, "{finding:?}");
    assert!((number(&finding, "start_s") - 0.3).abs() < 1e-9, "{finding:?}");
    assert!(qualifies(&finding), "{finding:?}");
}

/// Each of three runs with a level of its own on cp02 (the pressure model's per-run error,
/// of either sign): no bias of cp02 qualifies.
#[test]
fn a_bias_that_differs_from_run_to_run_is_no_fault() {
    let runs: Vec<RunStreams> =
        [0.03, -0.02, 0.05].iter().enumerate().map(|(k, level)| faulty(30 + k as u64, 1, move |_, _| *level)).collect();
    let finding = fault_finding(&runs, 1, TAPS);
    assert!(finding.as_ref().is_none_or(|f| text(f, "mode") != "bias" || !qualifies(f)), "{finding:?}");
}

/// cp08 noisier from the start of the run (0.03 added, three times its own): no clean stretch of
/// its own to compare with, so it is judged against the other channels, and named noise; a
/// channel only 1.3 times as noisy as the others (transducers differ) is not.
#[test]
fn extra_noise_from_the_start_is_named_against_the_other_channels() {
    let with_added = |seed: u64, rms: f64| {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let extra = Normal::new(0.0, rms).expect("a valid deviation");
        let added: Vec<f64> = (0..N).map(|_| extra.sample(&mut rng)).collect();
        recording(seed + 1, move |tap, idx, noise| healthy(tap, idx, noise) + if tap == 7 { added[idx] } else { 0.0 })
    };
    let run = with_added(25, 3.0 * NOISE);
    let finding = fault_finding(std::slice::from_ref(&run), 7, TAPS).expect("a finding");
    assert_eq!(text(&finding, "mode"), "noise", "{finding:?}");
    assert!((number(&finding, "noise_rms") - 3.0 * NOISE).abs() < 0.3 * NOISE, "{finding:?}");
    assert!(number(&finding, "start_s") < 0.01, "{finding:?}");
    assert!(qualifies(&finding), "{finding:?}");
    let slightly = with_added(27, (1.3_f64 * 1.3 - 1.0).sqrt() * NOISE);
    let finding = fault_finding(std::slice::from_ref(&slightly), 7, TAPS);
    assert!(finding.as_ref().is_none_or(|f| text(f, "mode") != "noise" || !qualifies(f)), "{finding:?}");
}

/// The lag of some channels as [`scan`] finds it, each channel first judged on the filter
/// without it.
fn lags_of(runs: &[RunStreams], n_taps: usize) -> Vec<SensorFinding> {
    let grid = lag_grid(runs[0].sample_hz);
    let alone: Judged<'_> =
        runs.iter().map(|run| run.innovation_alone.iter().take(n_taps).map(Vec::as_slice).collect()).collect();
    let best_alone = best_lags(runs, &alone, &grid, n_taps);
    lag_findings(runs, n_taps, &alone, &best_alone, &grid)
}

/// The sensor scan names a lag of nine channels on those nine, its evidence measured on the
/// innovations with the other channels de-lagged: there the members' whole lag shows.
#[test]
fn the_scan_names_a_lag_of_nine_channels_on_exactly_those_nine() {
    let taus = [0.02, 0.03, 0.0, 0.045, 0.025, 0.0, 0.035, 0.02, 0.03, 0.04, 0.0, 0.025];
    let runs: Vec<RunStreams> = (40..43).map(|seed| lag_runs::run_known(seed, &taus)).collect();
    let findings = findings(&runs, 0.0);
    let lag = findings.iter().find(|f| f.effect == firmware_sim::effect::Effect::PressureLag).expect("a lag finding");
    let expected: Vec<String> = (0..TAPS).filter(|&tap| taus[tap] > 0.0).map(channel_name).collect();
    assert_eq!(lag.channels, expected, "{}", lag.evidence);
    assert!(lag.selection.removed() > 0.25 * lag.noise_var, "{:?}", lag.selection);
}
