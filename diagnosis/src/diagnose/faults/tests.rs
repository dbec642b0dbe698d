//! Tests of [`super`]: the `faults` module on synthetic data with known answers.

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::*;
use crate::diagnose::streams::synthetic_run;

const HZ: f64 = 1000.0;
const DURATION_S: f64 = 20.0;
const NOISE: f64 = 0.01;

/// One channel whose expectation is a 2 Hz swing of 0.3 and whose reading is
/// `reading(t_s, expected)` plus transducer noise (seeded).
fn run_with(seed: u64, reading: impl Fn(f64, f64) -> f64) -> RunStreams {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, NOISE).expect("a valid deviation");
    let n = (DURATION_S * HZ) as usize;
    let (mut cp, mut nu) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 0..n {
        let t_s = i as f64 / HZ;
        let expected = 0.3 * (std::f64::consts::TAU * 2.0 * t_s).sin() - 0.5;
        let value = reading(t_s, expected) + noise.sample(&mut rng);
        cp.push(value);
        nu.push(value - expected);
    }
    synthetic_run(HZ, vec![cp], vec![nu])
}

fn interval_s(run: &RunStreams, shape: Shape) -> Option<(f64, f64)> {
    let onsets = scan(std::slice::from_ref(run), 0, shape, 1.0);
    onsets.per_run[0].clone().map(|r| (r.start as f64 / HZ, r.end as f64 / HZ))
}

/// One grid cell, s: the resolution of the scan (before the trim to the fit samples).
const CELL_S: f64 = DURATION_S / GRID as f64;

/// The contract's fault lasts from its onset to the run's end: a channel stuck from 6 s is
/// found from about 6 s to the end of the run.
#[test]
fn a_channel_stuck_from_an_onset_is_found_from_it_to_the_runs_end() {
    let run = run_with(1, |t_s, e| if t_s >= 6.0 { -0.4 } else { e });
    let (start, end) = interval_s(&run, Shape::Stuck).expect("a stuck interval");
    assert!((start - 6.0).abs() <= CELL_S + 0.3, "start {start} s");
    assert!((end - DURATION_S).abs() < 1e-9, "end {end} s");
}

#[test]
fn a_channel_stuck_to_the_end_of_training_stays_stuck_in_the_held_out_part() {
    let run = run_with(2, |t_s, e| if t_s >= 9.0 { -0.4 } else { e });
    let (start, end) = interval_s(&run, Shape::Stuck).expect("a stuck interval");
    assert!((start - 9.0).abs() <= CELL_S + 0.3, "start {start} s");
    assert!((end - DURATION_S).abs() < 1e-9, "end {end} s: runs on into the held-out part");
}

#[test]
fn a_live_channel_read_at_half_its_gain_is_not_stuck() {
    // Its innovation regresses on the expectation with slope -0.5 (inside the stuck band):
    // only the flatness of the reading tells the two apart.
    let run = run_with(3, |_, e| 0.5 * e - 0.25);
    assert_eq!(interval_s(&run, Shape::Stuck), None);
}

/// A live channel that moves at a fifth of what the filter expects (its smoothed variance
/// 0.04 of the expectation's, inside the flatness bound) still moves hundreds of times
/// above its smoothed noise: not stuck.
#[test]
fn a_channel_that_moves_less_than_expected_is_not_stuck() {
    let run = run_with(4, |_, e| 0.2 * e - 0.4);
    assert_eq!(interval_s(&run, Shape::Stuck), None);
}

/// A channel stuck from 6 s whose transducer noise is correlated from sample to sample
/// (AR(1), correlation 0.5, on top of the white noise) is still a constant with its noise.
#[test]
fn a_channel_stuck_with_correlated_noise_is_stuck() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let innovation = Normal::new(0.0, NOISE).expect("a valid deviation");
    let mut level = 0.0;
    let coloured: Vec<f64> = (0..(DURATION_S * HZ) as usize)
        .map(|_| {
            level = 0.5 * level + innovation.sample(&mut rng);
            level
        })
        .collect();
    let run = run_with(5, |t_s, e| {
        if t_s >= 6.0 { -0.4 + coloured[((t_s * HZ).round() as usize).min(coloured.len() - 1)] } else { e }
    });
    let (start, _) = interval_s(&run, Shape::Stuck).expect("a stuck interval");
    assert!((start - 6.0).abs() <= CELL_S + 0.3, "start {start} s");
}

#[test]
fn a_healthy_channel_has_no_fault() {
    let run = run_with(6, |_, e| e);
    assert_eq!(interval_s(&run, Shape::Stuck), None);
    for form in Form::ALL {
        assert_eq!(fit_shared(std::slice::from_ref(&run), 0, form, 1.0), None, "{form:?}");
    }
    assert_eq!(fit_noise(std::slice::from_ref(&run), 0, 1), None);
}

/// Nothing fitted: no interval in the training part, the level the training part would
/// have fixed.
fn untrained(level: f64) -> Trained {
    Trained { per_run: vec![None], levels: vec![Some(level)] }
}

/// A fault that begins in the held-out part is found there by the fixed detector: a channel
/// stuck from 17 s (the training part never saw it) shrinks the held-out gap by most of
/// it, read at the value it froze at; the same detector on a healthy channel finds nothing
/// there and changes nothing.
#[test]
fn a_fault_beginning_in_the_held_out_part_is_found_there_and_a_healthy_channel_is_left_alone() {
    let runs = [run_with(9, |t_s, e| if t_s >= 17.0 { -0.4 } else { e })];
    assert_eq!(scan(&runs, 0, Shape::Stuck, 1.0).per_run[0], None, "not in the training part");
    let gap = part_gap(&runs, 0, Shape::Stuck, 1.0, &Trained { per_run: vec![None], levels: vec![None] }, true);
    assert!(gap.shrink() > 0.8, "held-out shrink {}", gap.shrink());
    let healthy = [run_with(11, |_, e| e)];
    for heldout in [true, false] {
        let gap = part_gap(&healthy, 0, Shape::Stuck, 1.0, &untrained(-0.4), heldout);
        assert!(gap.n > 0 && gap.mse_after == gap.mse_before, "heldout={heldout}");
    }
}

#[test]
fn the_stuck_columns_hold_the_slope_then_one_level_per_run() {
    let runs = [run_with(7, |t_s, e| if t_s >= 5.0 { -0.4 } else { e }), run_with(8, |_, e| e)];
    let onsets = scan(&runs, 0, Shape::Stuck, 1.0);
    assert!(onsets.per_run[0].is_some() && onsets.per_run[1].is_none());
    assert_eq!(onsets.columns[0].len(), 1 + runs.len());
    let inside = onsets.per_run[0].clone().expect("found");
    assert!(onsets.columns[0][1].iter().enumerate().all(|(i, v)| *v == f64::from(u8::from(inside.contains(&i)))));
    assert!(onsets.columns[1].iter().flatten().all(|v| *v == 0.0));
}

/// One bias for every run, each run's own onset: from the start in one run, from 8 s in
/// another, none in a third.
#[test]
fn a_bias_shared_by_every_run_is_one_value_with_each_runs_onset() {
    let runs = [
        run_with(20, |_, e| e + 0.03),
        run_with(21, |t_s, e| if t_s >= 8.0 { e + 0.03 } else { e }),
        run_with(22, |_, e| e),
    ];
    let shared = fit_shared(&runs, 0, Form::Bias, 1.0).expect("a bias");
    assert!((shared.beta - 0.03).abs() < 0.002, "{shared:?}");
    assert!(shared.onset_s[0].is_some_and(|t| t < 0.1), "{shared:?}");
    // 8 s is where a selection block (0.8 s, unseen by the fit) ends: the onset lies within
    // it.
    assert!(shared.onset_s[1].is_some_and(|t| (7.1..=8.1).contains(&t)), "{shared:?}");
    assert_eq!(shared.onset_s[2], None);
}

/// The pressure model's error from run to run (a level of its own in each run, of either
/// sign) is not one offset of the channel: no bias.
#[test]
fn a_bias_that_differs_from_run_to_run_is_no_fault() {
    let levels = [0.03, -0.02, 0.05, 0.01, -0.04];
    let runs: Vec<RunStreams> =
        levels.iter().enumerate().map(|(k, level)| run_with(30 + k as u64, move |_, e| e + level)).collect();
    assert_eq!(fit_shared(&runs, 0, Form::Bias, 1.0), None);
}

/// A ramp of 0.004 per second from 5 s in one run and from the start in another: one rate.
#[test]
fn a_drift_shared_by_every_run_has_one_rate() {
    let runs = [
        run_with(40, |t_s, e| e + if t_s >= 5.0 { 0.004 * (t_s - 5.0) } else { 0.0 }),
        run_with(41, |t_s, e| e + 0.004 * t_s),
    ];
    let shared = fit_shared(&runs, 0, Form::Drift, 1.0).expect("a drift");
    assert!((shared.beta - 0.004).abs() < 0.0003, "{shared:?}");
    assert!(shared.onset_s[0].is_some_and(|t| (t - 5.0).abs() < 0.5), "{shared:?}");
    assert!(shared.onset_s[1].is_some_and(|t| t < 0.5), "{shared:?}");
}

/// A channel reading 1.2 times the pressure from 6 s: gain 1.2 from about 6 s.
#[test]
fn a_wrong_gain_from_an_onset_has_its_gain_and_onset() {
    let runs = [run_with(50, |t_s, e| if t_s >= 6.0 { 1.2 * e } else { e })];
    let shared = fit_shared(&runs, 0, Form::Gain, 1.0).expect("a gain");
    assert!((Form::Gain.reported(shared.beta) - 1.2).abs() < 0.01, "{shared:?}");
    assert!(shared.onset_s[0].is_some_and(|t| (t - 6.0).abs() < 0.3), "{shared:?}");
}

/// Nothing is re-fitted on the held-out part: a bias whose value there differs from the
/// training value keeps the training value, so the held-out gap keeps the difference (a
/// re-fit would have removed it all); a bias that begins inside the held-out part is found
/// there by the detector with the value fixed.
#[test]
fn a_shared_bias_keeps_its_training_value_and_is_found_where_it_begins() {
    let runs = [
        run_with(60, |t_s, e| if t_s < 16.0 { e + 0.03 } else { e + 0.06 }),
        run_with(61, |t_s, e| if t_s >= 18.0 { e + 0.03 } else { e }),
    ];
    let shared = fit_shared(&runs, 0, Form::Bias, 1.0).expect("a bias");
    assert!((shared.beta - 0.03).abs() < 0.002, "{shared:?}");
    assert_eq!(shared.onset_s[1], None, "not in the training part");
    let first =
        shared_part_gap(&runs[..1], 0, &Shared { onset_s: vec![shared.onset_s[0]], ..shared.clone() }, 1.0, true);
    assert!((first.shrink() - 0.5).abs() < 0.1, "held-out shrink {}", first.shrink());
    let second = shared_part_gap(&runs[1..], 0, &Shared { onset_s: vec![None], ..shared.clone() }, 1.0, true);
    assert!(second.shrink() > 0.8, "held-out shrink {}", second.shrink());
    let healthy = [run_with(62, |_, e| e)];
    for heldout in [true, false] {
        let gap = shared_part_gap(&healthy, 0, &Shared { onset_s: vec![None], ..shared.clone() }, 1.0, heldout);
        assert!(gap.n > 0 && gap.mse_after == gap.mse_before, "heldout={heldout}");
    }
}

/// Noise of three times the channel's own from 7 s: found from about 7 s with its added
/// RMS; the held-out part (all after the onset) confirms it (the shrink is the root of a
/// variance difference: a few per cent of sampling error in 4000 samples leave a fifth of
/// the gap), and a healthy channel's does not show it.
#[test]
fn extra_noise_from_an_onset_is_found_with_its_added_rms() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(70);
    let extra = Normal::new(0.0, 3.0 * NOISE).expect("a valid deviation");
    let added: Vec<f64> = (0..(DURATION_S * HZ) as usize).map(|_| extra.sample(&mut rng)).collect();
    let runs = [run_with(71, |t_s, e| e + if t_s >= 7.0 { added[(t_s * HZ).round() as usize] } else { 0.0 })];
    let noise = fit_noise(&runs, 0, 1).expect("extra noise");
    assert!((noise.added_var.sqrt() - 3.0 * NOISE).abs() < 0.1 * 3.0 * NOISE, "{noise:?}");
    assert!((noise.base_var.sqrt() - NOISE).abs() < 0.1 * NOISE, "{noise:?}");
    assert!(noise.onset_s[0].is_some_and(|t| (t - 7.0).abs() < 0.2), "{noise:?}");
    let gap = noise_part_gap(&runs, 0, &noise, true);
    assert!(gap.shrink() > 0.6, "held-out shrink {}", gap.shrink());
    let healthy = [run_with(72, |_, e| e)];
    let gap = noise_part_gap(&healthy, 0, &Noise { onset_s: vec![None], ..noise.clone() }, true);
    assert!(gap.removed().abs() < 1e-12, "{gap:?}");
}

/// A bias of 0.027 read with the pressure model's own error from run to run on top (levels
/// 0.018 to 0.036, all one way, each within a factor of two of their mean): still one
/// bias, at their mean, in every run (a run below half the shared value would read as one
/// without the fault: the fixed value fits it worse than none).
#[test]
fn a_bias_with_the_models_error_from_run_to_run_is_still_one_bias() {
    let levels = [0.030, 0.036, 0.024, 0.018];
    let runs: Vec<RunStreams> =
        levels.iter().enumerate().map(|(k, level)| run_with(80 + k as u64, move |_, e| e + level)).collect();
    let shared = fit_shared(&runs, 0, Form::Bias, 1.0).expect("a bias");
    assert!((shared.beta - 0.027).abs() < 0.002, "{shared:?}");
    assert_eq!(shared.runs_with(), levels.len());
}

/// A channel biased by 0.02 from the start of every run, where the pressure model's own
/// error is a level of its own in each run as large as the bias: the runs disagree and no
/// bias holds, until the sim's own level per run (its signature's mean on a clean
/// recording) is taken off; then it is one bias, in every run, from the start.
#[test]
fn a_bias_from_the_start_is_judged_beyond_the_sims_own_level_per_run() {
    let own = [0.03, -0.02, 0.05, 0.01, -0.04];
    let mut runs: Vec<RunStreams> =
        own.iter().enumerate().map(|(k, level)| run_with(90 + k as u64, move |_, e| e + level + 0.02)).collect();
    assert_eq!(fit_shared(&runs, 0, Form::Bias, 1.0), None);
    for (run, level) in runs.iter_mut().zip(own) {
        run.remove_own_mean(&[level]);
    }
    let shared = fit_shared(&runs, 0, Form::Bias, 1.0).expect("a bias");
    assert!((shared.beta - 0.02).abs() < 0.002, "{shared:?}");
    assert!(shared.onset_s.iter().all(|onset| onset.is_some_and(|t| t < 0.1)), "{shared:?}");
}
