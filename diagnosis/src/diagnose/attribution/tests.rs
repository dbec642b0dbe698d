//! Tests of [`super`]: the attribution module on synthetic runs with known answers.

use std::collections::BTreeMap;

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::*;
use crate::diagnose::candidates::{GravityTare, InertialTare, test_context};
use crate::diagnose::finding::{ParamValue, SensorFinding};
use crate::diagnose::result::Verdict;
use crate::diagnose::streams::synthetic_run;
use crate::diagnose::{
    BalanceAttribution, Decision, GapSummary, LeftGap, MAX_REMAINDER_GAP_SHARE, MAX_REMAINDER_GAP_TO_NOISE,
    MAX_REMAINDER_SHARE, MIN_DELTA_BIC, MIN_EFFECT_TO_NOISE, MIN_REMAINDER_TO_NOISE, MIN_SENSOR_GAP_SHARE, ProbeResult,
    SensorAttribution, Signature, Streams,
};

const HZ: f64 = 1000.0;
const N: usize = 5000;

/// The smallest excess a named effect needs, in noise variances.
const MIN_RATIO: f64 = MIN_EFFECT_TO_NOISE * MIN_EFFECT_TO_NOISE;

/// A run of `N` samples whose balance residual is `residual(t_s, noise)`, with a seeded
/// Gaussian noise of `noise_std`, the wing rolling `0.5 sin(2 pi 0.7 t)` rad.
fn rolling(seed: u64, noise_std: f64, residual: impl Fn(f64, f64, f64) -> f64) -> RunStreams {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, noise_std).expect("a valid deviation");
    let mut run = synthetic_run(HZ, vec![vec![0.0; N]], vec![vec![0.0; N]]);
    let w = std::f64::consts::TAU * 0.7;
    run.phi_rad = run.t_s.iter().map(|t| 0.5 * (w * t).sin()).collect();
    run.phi_dot_rad_s = run.t_s.iter().map(|t| 0.5 * w * (w * t).cos()).collect();
    run.phi_ddot_rad_s2 = run.t_s.iter().map(|t| 40.0 * (std::f64::consts::TAU * 1.5 * t).sin()).collect();
    run.residual = (0..N).map(|i| residual(run.t_s[i], run.phi_rad[i], normal.sample(&mut rng))).collect();
    run
}

/// Streams over `runs` with a balance noise variance of `noise_var` (1: every excess below
/// is the selection part's mean square removed).
fn streams(runs: Vec<RunStreams>, noise_var: f64) -> Streams {
    let residuals = runs.iter().map(|run| run.residual.clone()).collect();
    Streams {
        runs,
        residuals,
        noise_var,
        autocorrelation_time: 1.0,
        set: estimator_core::coeffs::BUILT_IN,
        moment_scale_nm: 2.0,
        half_span_time_s: 0.01,
        resonance_min_hz: 4.0,
        resonance_seeds_hz: Vec::new(),
    }
}

/// A profiled candidate that removes `removed` of mean square on the selection part
/// (1 + removed -> 1; exact in binary for the values used) with evidence `delta_bic`.
fn profiled(candidate: Candidate, removed: f64, delta_bic: f64) -> Profiled {
    Profiled {
        candidate,
        form: Form { shape: candidates::Shape::Fixed, per_alpha: false },
        // Explains `removed` per training sample, and the selection part confirms it whole.
        fit: Fit {
            beta: vec![1.0],
            ssr_base: 1.0 + 100.0 * removed,
            ssr: 1.0,
            n: 100,
            n_touched: 100,
            ssr_base_touched: 1.0 + 100.0 * removed,
            touched: vec![true],
        },
        delta_bic,
        profile: Vec::new(),
        selection: HeldoutGap { mse_before: 1.0 + removed, mse_after: 1.0, noise_var: 0.0, n: 100, floor_var: 0.0 },
        heldout: HeldoutGap::EMPTY,
        selection_slope: Slope { value: 1.0, standard_error: 0.1 },
        active_share: 1.0,
        selection_active_share: 1.0,
        cross_validation: None,
        beyond_its_range: false,
        limit_margin: f64::INFINITY,
    }
}

/// A sensor finding that removes `removed` noise variances on the selection part.
fn sensor_finding(removed: f64) -> SensorFinding {
    SensorFinding {
        effect: firmware_sim::effect::Effect::PressureFault,
        params: vec![("mode".into(), ParamValue::Text("bias".into()))],
        channel: Some("cp04".into()),
        channels: vec!["cp04".into()],
        explained: removed,
        noise_var: 1.0,
        delta_bic: 100.0,
        heldout: HeldoutGap::EMPTY,
        selection: HeldoutGap { mse_before: 1.0 + removed, mse_after: 1.0, noise_var: 0.0, n: 100, floor_var: 0.0 },
        evidence: String::new(),
    }
}

fn balance(first_round: Vec<Profiled>, named: Vec<Profiled>) -> BalanceAttribution {
    BalanceAttribution { first_round, named, remainder: Vec::new() }
}

fn probe(structure: f64, remainder_structured: bool) -> ProbeResult {
    ProbeResult { base: BTreeMap::new(), structure, remainder_structured, remainder_gap: LeftGap::default() }
}

fn no_sensor() -> SensorAttribution {
    SensorAttribution { findings: Vec::new(), channel_lags: Vec::new(), named: None }
}

/// A gap summary with nothing beyond the sim's own scatter, or everything.
fn gaps(beyond_scatter: bool) -> GapSummary {
    GapSummary {
        heldout: HeldoutGap { mse_before: 0.0, mse_after: 0.0, noise_var: 0.0, n: 0, floor_var: 0.0 },
        by_kind: BTreeMap::new(),
        excess_runs: Vec::new(),
        beyond_scatter,
    }
}

fn decide(balance: &BalanceAttribution, probe: &ProbeResult, sensor: &SensorAttribution) -> Decision {
    Decision::make(&streams(Vec::new(), 1.0), balance, probe, sensor, &gaps(false), &Signature::default())
}

/// The Legendre polynomials against their closed forms (degrees 0 to 5) and `P_n(1) = 1`,
/// `P_n(-1) = (-1)^n`.
#[test]
fn legendre_matches_the_closed_forms() {
    let closed: [fn(f64) -> f64; 6] = [
        |_| 1.0,
        |x| x,
        |x| (3.0 * x * x - 1.0) / 2.0,
        |x| (5.0 * x.powi(3) - 3.0 * x) / 2.0,
        |x| (35.0 * x.powi(4) - 30.0 * x * x + 3.0) / 8.0,
        |x| (63.0 * x.powi(5) - 70.0 * x.powi(3) + 15.0 * x) / 8.0,
    ];
    for (degree, p) in closed.iter().enumerate() {
        for x in [-1.0, -0.3, 0.0, 0.7, 1.0] {
            assert!((legendre(degree, x) - p(x)).abs() < 1e-12, "P{degree}({x})");
        }
        assert!((legendre(degree, 1.0) - 1.0).abs() < 1e-12);
        assert!((legendre(degree, -1.0) - if degree % 2 == 0 { 1.0 } else { -1.0 }).abs() < 1e-12);
    }
}

/// The segments carry the given residuals (not the runs' own) with each run's three parts.
#[test]
fn segments_carry_the_given_residuals_and_each_runs_parts() {
    let runs = [rolling(1, 1.0, |_, _, n| n), synthetic_run(500.0, vec![vec![0.0; 100]], vec![vec![0.0; 100]])];
    let residuals = vec![vec![7.0; N], vec![-1.0; 100]];
    let segments = segments(&runs, &residuals);
    assert_eq!(segments.len(), 2);
    for ((segment, run), residual) in segments.iter().zip(&runs).zip(&residuals) {
        assert!(std::ptr::eq(segment.residual, residual.as_slice()));
        assert_eq!(segment.training, run.training);
        assert_eq!(segment.select, run.select);
        assert_eq!(segment.heldout, run.heldout);
    }
    assert_eq!(segments[1].training, 0..80);
    assert_eq!(segments[1].heldout, 80..100);
}

/// The static-nonlinearity probe at one sample, by hand: phi = 0.5, rate = -0.4, eGK 0.1
/// give phi^3 = 0.125, phi^5 = 0.03125, rate |rate| = -0.16, tanh(-2), 0.1 phi^2 = 0.025.
#[test]
fn the_static_nonlinearity_probe_is_its_hand_computed_columns() {
    let mut run = synthetic_run(100.0, vec![vec![0.0; 3]], vec![vec![0.0; 3]]);
    run.phi_rad = vec![0.5; 3];
    run.phi_dot_rad_s = vec![-0.4; 3];
    run.cl_egk = vec![0.1; 3];
    let columns = probe_columns(&[run], "static_nonlinearity");
    let values: Vec<f64> = columns[0].iter().map(|col| col[1]).collect();
    let expected = [0.125, 0.03125, -0.16, (-2.0f64).tanh(), 0.025];
    assert_eq!(values.len(), expected.len());
    for (value, want) in values.iter().zip(expected) {
        assert!((value - want).abs() < 1e-15, "{values:?}");
    }
}

/// The moment-nonlinearity probe at one sample, by hand: a sim moment of 0.1 (eGK 0.04,
/// jets 0.03 and 0.02, coupling 0.01) is 2 typical moments, so the columns are 4 and 8.
#[test]
fn the_moment_nonlinearity_probe_is_the_square_and_cube_of_the_moment() {
    let mut run = synthetic_run(100.0, vec![vec![0.0; 3]], vec![vec![0.0; 3]]);
    run.cl_egk = vec![0.04; 3];
    run.cl_afc_side = [vec![0.03; 3], vec![0.02; 3]];
    run.coupling = vec![0.01; 3];
    let columns = probe_columns(&[run], "moment_nonlinearity");
    let values: Vec<f64> = columns[0][5..].iter().map(|col| col[2]).collect();
    assert_eq!(values.len(), 2);
    assert!((values[0] - 4.0).abs() < 1e-12 && (values[1] - 8.0).abs() < 1e-12, "{values:?}");
}

/// The slow-gain probe: per run, the sim's moment (2 here) times `P_1..P_4` of time mapped
/// to [-1, 1], in that run's own four columns and zero in the other run's: at the start
/// `2 (-1)^d`, at the middle `2 P_d(0)` = 0, -1, 0, 0.75, at the end 2.
#[test]
fn the_slow_gain_probe_is_the_moment_times_legendre_polynomials_per_run() {
    let run = || {
        let mut run = synthetic_run(10.0, vec![vec![0.0; 11]], vec![vec![0.0; 11]]);
        run.cl_egk = vec![2.0; 11];
        run
    };
    let columns = probe_columns(&[run(), run()], "slow_gain");
    assert_eq!(columns.len(), 2);
    assert_eq!(columns[0].len(), 8);
    let middle = [0.0, -1.0, 0.0, 0.75];
    for degree in 1..=4 {
        let own = &columns[0][degree - 1];
        assert!((own[0] - 2.0 * (-1f64).powi(degree as i32)).abs() < 1e-12);
        assert!((own[5] - middle[degree - 1]).abs() < 1e-12, "P{degree}(0): {}", own[5]);
        assert!((own[10] - 2.0).abs() < 1e-12);
        assert!(columns[0][4 + degree - 1].iter().all(|v| *v == 0.0));
        assert!(columns[1][degree - 1].iter().all(|v| *v == 0.0));
        assert_eq!(columns[1][4 + degree - 1], *own);
    }
}

/// The input-dynamics probe: four signals through three lags each (12 columns); a constant
/// input stays itself through a unit-gain lag started at rest (total blowing 0.01 + 0.02).
#[test]
fn the_input_dynamics_probe_lags_four_inputs_three_ways() {
    let mut run = synthetic_run(100.0, vec![vec![0.0; 50]], vec![vec![0.0; 50]]);
    run.phi_rad = vec![0.2; 50];
    run.cmu = [vec![0.01; 50], vec![0.02; 50]];
    let columns = probe_columns(&[run], "input_dynamics");
    assert_eq!(columns[0].len(), 12);
    assert!(columns[0][..3].iter().flatten().all(|v| (v - 0.2).abs() < 1e-15));
    assert!(columns[0][6..9].iter().flatten().all(|v| (v - 0.03).abs() < 1e-15));
    assert!(columns[0][3..6].iter().chain(&columns[0][9..]).flatten().all(|v| *v == 0.0));
}

/// Subtracting an effect removes `beta * column` at every sample of the run, held-out part
/// included: with the inertial tare's column `phi_ddot` and beta 2, `r - 2 phi_ddot`.
#[test]
fn subtract_removes_the_fitted_effect_over_whole_runs() {
    let context = test_context();
    let run = rolling(2, 1.0, |_, _, n| n);
    let mut effect = profiled(&InertialTare, 0.0, 0.0);
    effect.form.shape = candidates::Shape::Tare { per_run: false, corner_hz: None };
    effect.fit.beta = vec![2.0];
    let residuals = vec![run.residual.clone()];
    let after = subtract(&effect, std::slice::from_ref(&run), &residuals, &context);
    for idx in [0, N / 2, N - 1] {
        let expected = run.residual[idx] - 2.0 * run.phi_ddot_rad_s2[idx];
        assert!((after[0][idx] - expected).abs() < 1e-12, "sample {idx}");
    }
}

/// A balance that keeps `-I phi_ddot` (effect RMS about four times the noise): the inertial
/// tare is profiled with its coefficient `-I / (q S b)`, decisive evidence, and a held-out
/// shrink near 1.
#[test]
fn profile_recovers_an_injected_inertial_tare_out_of_sample() {
    let context = test_context();
    let ixx_kgm2 = 3.0e-4;
    let run = rolling(3, 1e-3, |_, _, n| n);
    let residual: Vec<f64> = run
        .phi_ddot_rad_s2
        .iter()
        .zip(&run.residual)
        .map(|(a, n)| -ixx_kgm2 * a / context.moment_scale_nm + n)
        .collect();
    let found = profile(&InertialTare, std::slice::from_ref(&run), &[residual], &context, 1.0).expect("a profile");
    let expected = -ixx_kgm2 / context.moment_scale_nm;
    assert!((found.fit.beta[0] / expected - 1.0).abs() < 0.02, "{:?}", found.fit.beta);
    assert!(found.delta_bic >= MIN_DELTA_BIC, "{}", found.delta_bic);
    assert!(found.heldout.shrink() > 0.85, "{:?}", found.heldout);
    assert!(found.selected() > 0.0);
}

/// A run whose roll acceleration comes in bursts of 20 Hz in the middle of every block the fit
/// uses, none in the selection blocks (each 250 samples, every fifth), and whose residual is
/// an inertial tare of it (`gain` times it) plus white noise.
fn bursts_outside_the_selection(seed: u64, gain: f64) -> (RunStreams, Vec<f64>) {
    let mut run = rolling(seed, 1e-3, |_, _, n| n);
    let select = run.select;
    assert_eq!(select.block, 250, "the selection blocks of a {N}-sample run");
    run.phi_ddot_rad_s2 = (0..N)
        .map(|i| {
            let within = i % select.block;
            let burst = (i / select.block) % 5 != 4 && (75..175).contains(&within);
            if burst { 40.0 * (std::f64::consts::TAU * 20.0 * i as f64 / HZ).sin() } else { 0.0 }
        })
        .collect();
    let residual = run.phi_ddot_rad_s2.iter().zip(&run.residual).map(|(a, n)| gain * a + n).collect();
    (run, residual)
}

/// An effect the selection blocks hold none of is confirmed by cross-validating the training
/// part instead (its slope near one), and the same bursts without the effect are not confirmed.
#[test]
fn an_effect_the_selection_blocks_miss_is_confirmed_by_cross_validation() {
    let context = test_context();
    let (run, residual) = bursts_outside_the_selection(5, -3.0e-4 / context.moment_scale_nm);
    let found = profile(&InertialTare, std::slice::from_ref(&run), &[residual], &context, 1.0).expect("a profile");
    let cross = found.cross_validation.expect("the training part cross-validated");
    let Slope { value, standard_error } = cross.slope;
    assert!((value - 1.0).abs() < 0.2 && standard_error < 0.1, "{cross:?}");
    let explained = found.explained() / found.active_share;
    assert!((found.selected() / explained - 1.0).abs() < 0.2, "{} against {explained}", found.selected());

    let (run, residual) = bursts_outside_the_selection(6, 0.0);
    let found = profile(&InertialTare, std::slice::from_ref(&run), &[residual], &context, 1.0).expect("a profile");
    assert_eq!(found.selected(), 0.0, "{:?}", found.cross_validation);
}

/// White noise alone holds no effect: neither tare is decisive on it.
#[test]
fn profile_finds_no_decisive_effect_in_white_noise() {
    let context = test_context();
    let run = rolling(4, 1e-3, |_, _, n| n);
    let residuals = vec![run.residual.clone()];
    for candidate in [&InertialTare as Candidate, &GravityTare] {
        let found = profile(candidate, std::slice::from_ref(&run), &residuals, &context, 1.0).expect("a profile");
        assert!(found.delta_bic < MIN_DELTA_BIC, "{}: {}", candidate.name(), found.delta_bic);
    }
}

/// Without runs there is nothing to profile.
#[test]
fn profile_without_runs_is_none() {
    assert!(profile(&InertialTare, &[], &[], &test_context(), 1.0).is_none());
}

/// A candidate qualifies with decisive evidence (delta BIC at least `MIN_DELTA_BIC`) and an
/// out-of-sample excess of at least `MIN_EFFECT_TO_NOISE^2` noise variances; both edges are
/// inclusive, and just below either one it does not.
#[test]
fn a_candidate_qualifies_exactly_at_both_thresholds() {
    let streams = streams(Vec::new(), 1.0);
    let floor = Signature::default();
    let stage = balance(Vec::new(), Vec::new());
    let tiny = 2f64.powi(-30);
    assert!(stage.qualifies(&profiled(&InertialTare, MIN_RATIO, MIN_DELTA_BIC), &streams, &floor));
    assert!(!stage.qualifies(&profiled(&InertialTare, MIN_RATIO - tiny, MIN_DELTA_BIC), &streams, &floor));
    assert!(!stage.qualifies(&profiled(&InertialTare, MIN_RATIO, MIN_DELTA_BIC - 1e-9), &streams, &floor));
}

/// Where the sim leaves four noise variances beside a candidate on the selection part (its own
/// error on this excitation larger than on the fit's recording), the candidate must explain a
/// quarter of them: one noise variance qualifies, a hair less does not, whatever the signature.
#[test]
fn a_candidate_must_explain_a_share_of_what_the_sim_leaves_beside_it() {
    let streams = streams(Vec::new(), 1.0);
    let stage = balance(Vec::new(), Vec::new());
    let beside = |removed: f64| {
        let mut candidate = profiled(&InertialTare, removed, MIN_DELTA_BIC);
        candidate.selection.mse_after = 4.0;
        candidate
    };
    let floor = Signature::default();
    assert!(stage.qualifies(&beside(4.0 * MIN_RATIO), &streams, &floor));
    assert!(!stage.qualifies(&beside(4.0 * MIN_RATIO - 2f64.powi(-30)), &streams, &floor));
}

/// The selection part's slope: an effect that acts in one selection block in four, fitted
/// where it is real, has slope 1 there; fitted on noise it has slope about 0. What is
/// selected is the larger of the removal per selection sample where the effect acts and
/// the training part's size per sample where it acts times the confirmed slope.
#[test]
fn the_selection_slope_confirms_an_effect_whatever_share_of_it_the_blocks_hold() {
    let run = rolling(3, 1.0, |_, _, n| n);
    let select: Vec<usize> = run.select.samples().collect();
    let first_block: std::collections::HashSet<usize> = select[..run.select.block].iter().copied().collect();
    let effect: Vec<f64> = (0..run.len())
        .map(|i| if first_block.contains(&i) || !run.select.contains(i) { (i as f64 * 0.05).sin() } else { 0.0 })
        .collect();
    let mut real = run.clone();
    real.residual = run.residual.iter().zip(&effect).map(|(r, e)| r + e).collect();
    let runs = vec![real];
    let residuals: Vec<Vec<f64>> = runs.iter().map(|r| r.residual.clone()).collect();
    let segments = segments(&runs, &residuals);
    let columns = vec![vec![effect.clone()]];
    let fit = regression::fit_through_origin(&segments, &columns).expect("a fit");
    let noise_var = regression::difference_noise_var(&segments, None);
    let slope = selection_slope(&segments, &columns, &fit, noise_var, 1.0);
    assert!(
        (slope.value - 1.0).abs() < 3.0 * slope.standard_error && slope.value > CONFIRM_Z * slope.standard_error,
        "{slope:?}"
    );
    // The same column fitted on noise alone.
    let noise = vec![rolling(4, 1.0, |_, _, n| n)];
    let noise_residuals: Vec<Vec<f64>> = noise.iter().map(|r| r.residual.clone()).collect();
    let noise_segments = super::segments(&noise, &noise_residuals);
    let noise_fit = regression::fit_through_origin(&noise_segments, &columns).expect("a fit");
    let spurious = selection_slope(&noise_segments, &columns, &noise_fit, noise_var, 1.0);
    assert!(spurious.value.abs() < 3.0 * spurious.standard_error, "{spurious:?}");
    // Explains 0.25 per training sample where it acts (all of them).
    let mut found = profiled(&InertialTare, 0.25, MIN_DELTA_BIC);
    // No selection sample where it acts: the slope alone decides, capped at 1.
    found.selection_active_share = 0.0;
    found.selection_slope = Slope { value: 0.5, standard_error: 0.2 };
    assert!((found.selected() - 0.125).abs() < 1e-12, "{}", found.selected());
    found.selection_slope = Slope { value: 0.3, standard_error: 0.2 };
    assert_eq!(found.selected(), 0.0);
    found.selection_slope = Slope { value: 3.0, standard_error: 0.2 };
    assert!((found.selected() - 0.25).abs() < 1e-12);
    // Removes 0.25 on the selection part, where it acts in half the samples: 0.5 per
    // sample where it acts, the larger measure.
    found.selection_active_share = 0.5;
    found.selection_slope = Slope { value: 0.3, standard_error: 0.2 };
    assert!((found.selected() - 0.5).abs() < 1e-12, "{}", found.selected());
    found.active_share = 0.25;
    found.selection_slope = Slope { value: 1.0, standard_error: 0.2 };
    assert!((found.selected() - 1.0).abs() < 1e-12, "{}", found.selected());
}

/// The naming threshold counts the sim's own gap on the touched runs as noise: a gap of one
/// noise variance on the one roll run at 20 deg doubles it there; a run at an angle the
/// signature lacks takes its kind's figure; untouched runs and no runs leave it at the
/// white noise's.
#[test]
fn the_naming_threshold_counts_the_sims_own_gap_on_the_touched_runs() {
    let mut at_20 = rolling(1, 1.0, |_, _, n| n);
    at_20.kind = firmware_sim::dataset::RunKind::Roll;
    at_20.alpha_deg = 20.0;
    let mut at_30 = at_20.clone();
    at_30.alpha_deg = 30.0;
    let streams = streams(vec![at_20, at_30], 1.0);
    let floor = Signature {
        gap_to_noise_by_kind: [("roll@20".to_owned(), 1.0), ("roll".to_owned(), 3.0)].into_iter().collect(),
        ..Signature::default()
    };
    let threshold = |touched: &[bool]| crate::diagnose::naming_threshold(&streams, touched, &floor);
    assert_eq!(threshold(&[true, false]), 2.0 * MIN_RATIO);
    assert_eq!(threshold(&[false, true]), 4.0 * MIN_RATIO);
    assert_eq!(threshold(&[true, true]), 3.0 * MIN_RATIO);
    assert_eq!(threshold(&[false, false]), MIN_RATIO);
    assert_eq!(crate::diagnose::naming_threshold(&streams, &[true, true], &Signature::default()), MIN_RATIO);
}

/// The excess is counted beyond the sim's own signature for that candidate (0.375 removed
/// over a floor of 0.125 is exactly the threshold; a hair more floor and it fails), in noise
/// variances of the balance stream; a negative floor sets none.
#[test]
fn the_excess_is_counted_beyond_the_signature_in_noise_variances() {
    let stage = balance(Vec::new(), Vec::new());
    let candidate = profiled(&InertialTare, 0.375, 50.0);
    let floor = |value: f64| Signature {
        explained_to_noise: BTreeMap::from([("inertial_tare".to_owned(), value)]),
        ..Signature::default()
    };
    let unit = streams(Vec::new(), 1.0);
    assert!(stage.qualifies(&candidate, &unit, &floor(0.125)));
    assert!(!stage.qualifies(&candidate, &unit, &floor(0.125 + 2f64.powi(-30))));
    let candidate = profiled(&InertialTare, 0.75, 50.0);
    assert_eq!(stage.excess(&candidate, &unit, &floor(-3.0)), 0.75);
    // Another candidate's floor does not count against it.
    let other =
        Signature { explained_to_noise: BTreeMap::from([("gravity_tare".to_owned(), 10.0)]), ..Signature::default() };
    assert_eq!(stage.excess(&candidate, &unit, &other), 0.75);
    // With a noise variance of 2, 0.75 removed is 0.375 noise variances.
    assert_eq!(stage.excess(&candidate, &streams(Vec::new(), 2.0), &floor(0.0)), 0.375);
}

/// A candidate's floor is what it took of the sim's own error on the fit's recording, and on
/// another it may take as much again: 8 removed over a floor of 4 just qualifies, far above
/// the naming threshold; a hair more floor and it does not.
#[test]
fn a_candidate_must_clear_its_floor_twice_over() {
    let stage = balance(Vec::new(), Vec::new());
    let candidate = profiled(&InertialTare, 8.0, 50.0);
    let floor = |value: f64| Signature {
        explained_to_noise: BTreeMap::from([("inertial_tare".to_owned(), value)]),
        ..Signature::default()
    };
    let unit = streams(Vec::new(), 1.0);
    assert!(stage.qualifies(&candidate, &unit, &floor(4.0)));
    assert!(!stage.qualifies(&candidate, &unit, &floor(4.0 + 2f64.powi(-30))));
}

/// Nothing named and nothing that predicts the gap: `none`. Something that predicts at
/// least `MIN_EFFECT_TO_NOISE^2` noise variances out of sample (the best candidate, or the
/// structure probe) without being named: `unattributed`; just below: `none`.
#[test]
fn nothing_named_is_none_below_the_threshold_and_unattributed_at_it() {
    let tiny = 2f64.powi(-30);
    let quiet = balance(vec![profiled(&InertialTare, MIN_RATIO - tiny, 0.0)], Vec::new());
    assert_eq!(decide(&quiet, &probe(0.0, false), &no_sensor()).verdict(), Verdict::None);
    let predicted = balance(vec![profiled(&InertialTare, MIN_RATIO, 0.0)], Vec::new());
    assert_eq!(decide(&predicted, &probe(0.0, false), &no_sensor()).verdict(), Verdict::Unattributed);
    let empty = balance(Vec::new(), Vec::new());
    assert_eq!(decide(&empty, &probe(MIN_RATIO - tiny, false), &no_sensor()).verdict(), Verdict::None);
    assert_eq!(decide(&empty, &probe(MIN_RATIO, false), &no_sensor()).verdict(), Verdict::Unattributed);
}

/// A named balance effect is the verdict `effect`, unless the probe still finds structure
/// in the remainder: then `unattributed`.
#[test]
fn a_named_balance_effect_is_the_verdict_unless_structure_remains() {
    let top = profiled(&InertialTare, 2.0, 100.0);
    let named = balance(vec![top.clone()], vec![top]);
    let clean = decide(&named, &probe(0.0, false), &no_sensor());
    assert!(matches!(clean, Decision::Balance));
    assert_eq!(clean.verdict(), Verdict::Effect);
    assert_eq!(decide(&named, &probe(0.0, true), &no_sensor()).verdict(), Verdict::Unattributed);
}

/// Recalibration names no effect: a gap it alone spans is unattributed, and beside an effect of
/// the vocabulary the effect is the verdict.
#[test]
fn a_gap_only_recalibration_spans_is_unattributed() {
    use crate::diagnose::candidates::Recalibration;
    let gain = profiled(&Recalibration, 2.0, 100.0);
    let alone = balance(vec![gain.clone()], vec![gain.clone()]);
    assert!(matches!(decide(&alone, &probe(0.0, false), &no_sensor()), Decision::Unattributed));
    let tare = profiled(&InertialTare, 2.0, 100.0);
    let beside = balance(vec![gain.clone(), tare.clone()], vec![gain, tare]);
    assert_eq!(decide(&beside, &probe(0.0, false), &no_sensor()).verdict(), Verdict::Effect);
}

/// A delay or a lag keeps the plant's static gain: fitted at eleven times the plant's moment
/// (or at less than half of it) it is not that effect; a gain of 0.7 is. A tare's gain is its
/// size, free.
#[test]
fn a_delay_or_lag_far_from_unit_gain_is_not_plausible() {
    use crate::diagnose::candidates::{ActuatorDelay, ActuatorLag, UNIT_GAIN_RANGE};
    let with_gain = |candidate: Candidate, gain: f64| {
        let mut p = profiled(candidate, 2.0, 100.0);
        p.fit.beta = vec![gain];
        p
    };
    assert!(with_gain(&ActuatorDelay, 0.7).plausible());
    assert!(with_gain(&ActuatorLag, UNIT_GAIN_RANGE.1).plausible());
    assert!(!with_gain(&ActuatorDelay, 11.26).plausible());
    assert!(!with_gain(&ActuatorLag, 0.44).plausible());
    assert!(with_gain(&InertialTare, 11.26).plausible());
}

/// A named balance effect that leaves both the noise RMS and half the gap's RMS on the runs
/// it acts on does not explain the gap: `unattributed`. Less than the noise, or less than half
/// of a strong gap, is the effect's.
#[test]
fn a_named_effect_that_leaves_the_noise_and_half_the_gap_is_unattributed() {
    let top = profiled(&InertialTare, 2.0, 100.0);
    let named = balance(vec![top.clone()], vec![top]);
    let leaves =
        |before: f64, after: f64| ProbeResult { remainder_gap: LeftGap { before, after }, ..probe(0.0, false) };
    let noise = MAX_REMAINDER_GAP_TO_NOISE * MAX_REMAINDER_GAP_TO_NOISE;
    let share = MAX_REMAINDER_GAP_SHARE * MAX_REMAINDER_GAP_SHARE;
    let tiny = 2f64.powi(-30);
    assert_eq!(decide(&named, &leaves(noise / share, noise), &no_sensor()).verdict(), Verdict::Unattributed);
    assert!(matches!(decide(&named, &leaves(noise / share, noise - tiny), &no_sensor()), Decision::Balance));
    // A gap of 336 noise variances that leaves 38: well beyond the noise, but a ninth of it.
    assert!(matches!(decide(&named, &leaves(336.0, 38.0), &no_sensor()), Decision::Balance));
    assert_eq!(decide(&named, &leaves(336.0, 84.0), &no_sensor()).verdict(), Verdict::Unattributed);
}

/// Structure the probe finds in the remainder overturns a named effect where it reaches both
/// [`MIN_REMAINDER_TO_NOISE`] of the noise the naming threshold counts and a tenth of the named
/// effect's excess; less is what the named effect and the probe's own scatter may leave.
#[test]
fn remainder_structure_counts_from_a_share_of_the_noise_and_of_the_named_effect() {
    let noise_scale = 2.0;
    let least = MIN_REMAINDER_TO_NOISE * noise_scale;
    // Beside a weak effect the noise's share is the bar.
    assert!(!ProbeResult::structure_counts(least * (1.0 - 1e-9), noise_scale, least));
    assert!(ProbeResult::structure_counts(least, noise_scale, least));
    // Beside a strong effect a tenth of its excess is.
    let excess = 20.0 * least / MAX_REMAINDER_SHARE;
    assert!(!ProbeResult::structure_counts(2.0 * least, noise_scale, excess));
    assert!(ProbeResult::structure_counts(MAX_REMAINDER_SHARE * excess, noise_scale, excess));
}

/// A named sensor effect wins only when stronger than the named balance effect (strictly:
/// a tie goes to the balance); with no balance effect it is the verdict.
#[test]
fn a_sensor_effect_wins_only_when_strictly_stronger() {
    let top = profiled(&InertialTare, 0.8, 100.0);
    let named = balance(vec![top.clone()], vec![top]);
    let sensor = |removed: f64| SensorAttribution {
        findings: Vec::new(),
        channel_lags: Vec::new(),
        named: Some(sensor_finding(removed)),
    };
    assert!(matches!(decide(&named, &probe(0.0, false), &sensor(0.8)), Decision::Balance));
    assert!(matches!(decide(&named, &probe(0.0, false), &sensor(0.8 + 2f64.powi(-30))), Decision::Sensor(_)));
    let alone = decide(&balance(Vec::new(), Vec::new()), &probe(0.0, false), &sensor(0.3));
    assert!(matches!(&alone, Decision::Sensor(f) if f.channel.as_deref() == Some("cp04")));
    assert_eq!(alone.verdict(), Verdict::Effect);
}

/// A fault of one channel is named only when it stands out from the other channels: by the
/// naming threshold and by at least the runner-up's own level. A deviation several taps share
/// alike (a dynamic-pressure fluctuation) names no channel; a lag finding is not held to it.
#[test]
fn a_one_channel_fault_must_stand_out_from_the_other_channels() {
    let on = |channel: &str, removed: f64| SensorFinding {
        channel: Some(channel.into()),
        channels: vec![channel.into()],
        ..sensor_finding(removed)
    };
    let floor = Signature::default();
    let named = |findings: &[SensorFinding]| {
        findings.iter().find(|f| SensorAttribution::stands_out(f, findings, &floor)).map(|f| f.channels[0].clone())
    };
    assert_eq!(named(&[on("cp05", 7.0), on("cp02", 0.5)]), Some("cp05".into()));
    assert_eq!(named(&[on("cp05", 1.0), on("cp02", 0.5)]), Some("cp05".into()), "a lead equal to the runner-up");
    assert_eq!(named(&[on("cp05", 0.99), on("cp02", 0.5)]), None);
    assert_eq!(named(&[on("cp06", 2.9), on("cp04", 2.6), on("cp10", 2.4)]), None, "common to the taps");
    assert_eq!(named(&[on("cp06", 0.3), on("cp04", 0.1)]), None, "a lead below the naming threshold");
    let lag = SensorFinding { effect: firmware_sim::effect::Effect::PressureLag, ..on("cp06", 0.3) };
    assert!(SensorAttribution::stands_out(&lag, &[lag.clone(), on("cp04", 2.6)], &floor));
}

/// The structure probe on a residual that is white noise finds less than an effect of
/// `MIN_EFFECT_TO_NOISE` (verdict `none`); on one holding a static cubic of the roll angle
/// that no candidate spans (effect RMS several times the noise) it finds more
/// (`unattributed`).
#[test]
fn the_probe_tells_noise_from_structure_no_candidate_spans() {
    let noise_std = 1e-3;
    let floor = Signature::default();
    let empty = balance(Vec::new(), Vec::new());
    let white = streams(vec![rolling(5, noise_std, |_, _, n| n)], noise_std * noise_std);
    let found = ProbeResult::run(&white, &empty, &floor);
    assert!(found.structure < MIN_RATIO, "{}", found.structure);
    let white_gaps = GapSummary::run(&white, &floor);
    assert!(!white_gaps.beyond_scatter);
    assert!(matches!(Decision::make(&white, &empty, &found, &no_sensor(), &white_gaps, &floor), Decision::None));
    let cubic = streams(vec![rolling(6, noise_std, |_, phi, n| 0.05 * phi.powi(3) + n)], noise_std * noise_std);
    let found = ProbeResult::run(&cubic, &empty, &floor);
    assert!(found.structure >= MIN_RATIO, "{}", found.structure);
    let cubic_gaps = GapSummary::run(&cubic, &floor);
    assert!(matches!(
        Decision::make(&cubic, &empty, &found, &no_sensor(), &cubic_gaps, &floor),
        Decision::Unattributed
    ));
}

/// A gap that nothing predicts (the probe finds nothing, no candidate qualifies) is
/// unattributed when it lies beyond the sim's own scatter, and `none` otherwise.
#[test]
fn an_unpredictable_gap_beyond_the_sims_scatter_is_unattributed() {
    let empty = balance(Vec::new(), Vec::new());
    let nothing = probe(0.0, false);
    let make = |beyond| {
        Decision::make(&streams(Vec::new(), 1.0), &empty, &nothing, &no_sensor(), &gaps(beyond), &Signature::default())
    };
    assert!(matches!(make(false), Decision::None));
    assert!(matches!(make(true), Decision::Unattributed));
}

/// A sensor finding clears its floor only by the least effect to name and by the floor again
/// (the floor taken as known within a factor of two): 2.0 removed over a floor of 1.0 is
/// exactly enough, a hair less is not; without a floor the least effect to name decides.
#[test]
fn a_sensor_finding_must_remove_twice_its_floor() {
    let tiny = 2f64.powi(-30);
    // All of the channel's gap beyond the noise is the finding's.
    let finding = |removed: f64| SensorFinding {
        selection: HeldoutGap { mse_before: 1.0 + removed, mse_after: 1.0, noise_var: 1.0, n: 100, floor_var: 0.0 },
        ..sensor_finding(removed)
    };
    let floor = |value: f64| Signature {
        explained_to_noise: BTreeMap::from([("pressure_fault:cp04".to_owned(), value)]),
        ..Signature::default()
    };
    assert!(SensorAttribution::qualifies(&finding(2.0), &floor(1.0)));
    assert!(!SensorAttribution::qualifies(&finding(2.0 - 1e-9), &floor(1.0)));
    assert!(SensorAttribution::qualifies(&finding(MIN_RATIO), &floor(0.0)));
    assert!(!SensorAttribution::qualifies(&finding(MIN_RATIO - tiny), &floor(0.0)));
}

/// A lag of some channels takes as its floor the mean of what a lag of each of its channels
/// alone removed on the sim's own data, when that exceeds the floor of the set itself; the
/// common lag of every channel keeps its own key.
#[test]
fn a_lag_of_some_channels_has_the_floor_of_its_channels_alone() {
    let lag = |channels: &[&str], all: bool| SensorFinding {
        effect: firmware_sim::effect::Effect::PressureLag,
        params: vec![("channels".into(), ParamValue::Text(if all { "all".into() } else { channels.join(",") }))],
        channel: None,
        channels: channels.iter().map(|c| (*c).to_owned()).collect(),
        ..sensor_finding(1.0)
    };
    let floor = Signature {
        explained_to_noise: BTreeMap::from([
            (crate::diagnose::sensor::channel_lag_key("cp02"), 0.6),
            (crate::diagnose::sensor::channel_lag_key("cp07"), 0.2),
            ("pressure_lag:cp02+cp07".to_owned(), 0.1),
        ]),
        ..Signature::default()
    };
    assert!((SensorAttribution::floor_of(&lag(&["cp02", "cp07"], false), &floor) - 0.4).abs() < 1e-12);
    assert_eq!(SensorAttribution::floor_of(&lag(&["cp07"], false), &floor), 0.2);
    assert_eq!(SensorAttribution::floor_of(&lag(&["cp02", "cp07"], true), &floor), 0.1);
}

/// A sensor finding that removes less than a third of its channels' gap beyond the noise on
/// the selection part is a sliver of the gap, not its cause: not named, however large.
#[test]
fn a_sensor_finding_must_remove_a_third_of_its_channels_gap() {
    let with_gap = |removed: f64, gap: f64| SensorFinding {
        selection: HeldoutGap {
            mse_before: 1.0 + gap,
            mse_after: 1.0 + gap - removed,
            noise_var: 1.0,
            n: 100,
            floor_var: 0.0,
        },
        ..sensor_finding(removed)
    };
    let floor = Signature::default();
    assert!(SensorAttribution::qualifies(&with_gap(3.0, 9.0), &floor));
    assert!(!SensorAttribution::qualifies(&with_gap(3.0, 9.1), &floor));
    assert!((SensorAttribution::gap_share(&with_gap(3.0, 9.0)) - 1.0 / 3.0).abs() < 1e-12);
}

/// A lag of a whole set is measured beyond the sim's own lags, so the rest of the pressure
/// model's error on a rig it fits poorly is no measure of it: it is named on the floor and the
/// evidence alone, where a finding on the innovations alone removing the same share is not.
#[test]
fn a_set_lag_is_named_beyond_the_sims_own_lags_whatever_the_models_error() {
    let poorly_fitted = |set: bool| {
        let mut finding = SensorFinding {
            effect: firmware_sim::effect::Effect::PressureLag,
            params: vec![("tau_s".into(), ParamValue::Number(0.03))],
            channel: None,
            channels: vec!["cp02".into(), "cp07".into()],
            selection: HeldoutGap { mse_before: 13.0, mse_after: 11.0, noise_var: 1.0, n: 100, floor_var: 0.0 },
            ..sensor_finding(2.0)
        };
        if set {
            finding.params.push(("reference_tau_s".into(), ParamValue::Number(0.0)));
        }
        finding
    };
    let floor = Signature::default();
    assert!(SensorAttribution::gap_share(&poorly_fitted(true)) < MIN_SENSOR_GAP_SHARE);
    assert!(SensorAttribution::qualifies(&poorly_fitted(true), &floor));
    assert!(!SensorAttribution::qualifies(&poorly_fitted(false), &floor));
}

/// A steady tone from the rig (40 Hz, under white noise of its own RMS) is predicted by the
/// `spectral_line` probe at its seed, most of its variance; white noise alone is not.
#[test]
fn a_steady_tone_is_predicted_by_the_line_probe_and_noise_is_not() {
    let (sample_hz, n, freq_hz) = (1000.0, 20_000, 40.0);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let noise = Normal::new(0.0, 1.0).unwrap();
    let run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
    let removed_share = |residual: Vec<f64>, of_var: f64| {
        let columns = line_columns(std::slice::from_ref(&run), std::slice::from_ref(&residual), &[freq_hz]);
        let (column, target) = (&columns[0][0][2000..], &residual[2000..]);
        let beta = crate::diagnose::candidates::test_fit(&[column.to_vec()], target);
        let before: f64 = target.iter().map(|r| r * r).sum();
        let after: f64 = target.iter().zip(column).map(|(r, c)| (r - beta[0] * c).powi(2)).sum();
        (before - after) / (of_var * target.len() as f64)
    };
    let tone: Vec<f64> = (0..n)
        .map(|i| 2f64.sqrt() * (std::f64::consts::TAU * freq_hz * i as f64 / sample_hz).sin() + noise.sample(&mut rng))
        .collect();
    let share = removed_share(tone, 1.0);
    assert!(share > 0.7, "the line probe took {share} of the tone's variance");
    let quiet: Vec<f64> = (0..n).map(|_| noise.sample(&mut rng)).collect();
    let share = removed_share(quiet, 1.0);
    assert!(share < 0.01, "the line probe took {share} of white noise");
}

/// Three first-order lags lead the coarse grid; the best second-order valve and the best rate
/// limit are refined too, and no second one of their kinds.
#[test]
fn the_best_form_of_every_kind_is_refined_beside_the_leaders() {
    use crate::diagnose::candidates::{Jets, Shape};
    let lag = |tau_s| Shape::Lag { tau_s, jets: Jets::Both };
    let valve = |tau_s| Shape::SecondOrderLag { tau_s, zeta: 1.0, jets: Jets::Port };
    let limit = Shape::RateLimit { full_stroke_s: 0.1, jets: Jets::Both };
    let ranked = [lag(0.02), lag(0.03), lag(0.01), lag(0.04), valve(0.012), valve(0.024), limit];
    assert_eq!(refined_leaders(&ranked), vec![0, 1, 2, 4, 6]);
    assert_eq!(refined_leaders(&ranked[..2]), vec![0, 1]);
}

/// A run of 20 s at 200 Hz rolling at two frequencies (0.2 and 0.65 Hz), whose eGK moment lags
/// the roll angle by 50 ms, and whose residual is `effect` of the run plus white noise of 1e-3.
fn two_tone_rolling(seed: u64, effect: impl Fn(&RunStreams) -> Vec<f64>) -> (RunStreams, Vec<f64>) {
    let (sample_hz, n) = (200.0, 4000);
    let mut run = synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
    run.alpha_deg = 20.0;
    let t_s: Vec<f64> = (0..n).map(|i| i as f64 / sample_hz).collect();
    run.phi_rad = t_s.iter().map(|t| 0.5 * (1.3 * t).sin() + 0.2 * (4.1 * t + 1.0).sin()).collect();
    run.phi_dot_rad_s = t_s.iter().map(|t| 0.65 * (1.3 * t).cos() + 0.82 * (4.1 * t + 1.0).cos()).collect();
    run.cl_egk =
        candidates::first_order_lag(&run.phi_rad, 0.05, 1.0 / sample_hz).iter().map(|phi| -0.01 * phi).collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, 1e-3).expect("a valid deviation");
    let residual = effect(&run).into_iter().map(|v| v + noise.sample(&mut rng)).collect();
    run.residual.clone_from(&residual);
    (run, residual)
}

/// A static term of the roll angle (a linear stiffness of the mount, outside the vocabulary)
/// is explained with decisive evidence by a slow state at an end of its time constant, but no
/// better than by the state's limits there, so it is not a plausible slow state; a state of the
/// roll angle at 0.8 s, inside the range, beats both limits and is.
#[test]
fn a_slow_state_is_plausible_only_where_the_data_resolve_its_time_constant() {
    use crate::diagnose::candidates::VortexLag;
    let context = test_context();
    let (run, residual) = two_tone_rolling(5, |run| run.phi_rad.iter().map(|phi| 0.004 * phi).collect());
    let found = profile(&VortexLag, std::slice::from_ref(&run), &[residual], &context, 1.0).expect("a profile");
    assert!(found.delta_bic >= MIN_DELTA_BIC, "the static term is explained: {}", found.delta_bic);
    assert!(found.limit_margin < MIN_DELTA_BIC && !found.plausible(), "{:?}: {}", found.form, found.limit_margin);
    let (run, residual) = two_tone_rolling(6, |run| {
        candidates::first_order_lag(&run.phi_rad, 0.8, 1.0 / run.sample_hz).iter().map(|x| 0.01 * x).collect()
    });
    let found = profile(&VortexLag, std::slice::from_ref(&run), &[residual], &context, 1.0).expect("a profile");
    assert!(found.limit_margin >= MIN_DELTA_BIC && found.plausible(), "{:?}: {}", found.form, found.limit_margin);
}
