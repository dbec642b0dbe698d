//! Tests of [`super`]: the `candidates` module on synthetic data with known answers.

use super::*;

/// A per-alpha form repeats each base column once per angle, non-zero only in the slot of
/// the run's own angle; the physical parameters come back per angle under `name@alpha`.
#[test]
fn per_alpha_columns_sit_in_their_angles_slot_and_report_per_angle() {
    let context = test_context();
    let mut run = crate::diagnose::streams::synthetic_run(100.0, vec![vec![0.0; 50]], vec![vec![0.0; 50]]);
    run.alpha_deg = 20.0;
    run.phi_dot_rad_s = vec![3.0; 50];
    let form = Form { shape: Shape::Fixed, per_alpha: true };
    let cols = columns(&RollDamping, &form, &run, 0, &context);
    assert_eq!(cols.len(), 2);
    assert!(cols[0].iter().all(|v| *v == 0.0), "0 deg slot of a 20 deg run");
    assert!(cols[1].iter().all(|v| (*v - 0.03).abs() < 1e-15), "p_hat = 3 rad/s x 0.01 s");
    let params = physical_params(&RollDamping, &form, &[-0.2, -0.3], &context, &[cols]);
    assert_eq!(params["clp@0"], serde_json::json!(-0.2));
    assert_eq!(params["clp@20"], serde_json::json!(-0.3));
    assert!(!params.contains_key("per_alpha"));
}

/// A non-finite fitted figure is reported as null, never as a number.
#[test]
fn non_finite_parameters_are_null() {
    let context = test_context();
    let form = Form { shape: Shape::Fixed, per_alpha: false };
    let params = physical_params(&RollDamping, &form, &[f64::NAN], &context, &[]);
    assert_eq!(params["clp"], serde_json::Value::Null);
    assert_eq!(FormValue::Number(f64::INFINITY).to_json(&[]), serde_json::Value::Null);
}

/// The log grid starts and ends at its bounds with a constant ratio.
#[test]
fn log_grid_spans_its_bounds_geometrically() {
    let grid = log_grid(0.01, 10.0, 4);
    for (got, want) in grid.iter().zip([0.01, 0.1, 1.0, 10.0]) {
        assert!((got / want - 1.0).abs() < 1e-12, "{got} vs {want}");
    }
    assert_eq!(log_grid(0.5, 2.0, 1), vec![0.5]);
}

/// The resonance's lowest frequency is an octave above the roll's band: a 3 Hz roll gives
/// about 6 Hz, a 0.2 Hz roll the 2 Hz floor, no rolling run the floor.
#[test]
fn resonance_floor_is_an_octave_above_the_motion() {
    let sample_hz = 200.0;
    let roll = |freq_hz: f64| {
        let n = 4000;
        let mut run = crate::diagnose::streams::synthetic_run(sample_hz, vec![vec![0.0; n]], vec![vec![0.0; n]]);
        run.kind = firmware_sim::dataset::RunKind::Roll;
        run.phi_rad = (0..n).map(|i| (std::f64::consts::TAU * freq_hz * i as f64 / sample_hz).sin()).collect();
        run
    };
    let fast = resonance_min_hz(&[roll(3.0)]);
    assert!((fast - 6.0).abs() <= 0.5, "3 Hz roll: {fast} Hz");
    assert_eq!(resonance_min_hz(&[roll(0.2)]), 2.0);
    let mut still = roll(3.0);
    still.kind = firmware_sim::dataset::RunKind::Actuation;
    assert_eq!(resonance_min_hz(&[still]), 2.0);
}

#[test]
fn lag_and_resonator_have_unit_dc_gain() {
    let step = vec![1.0; 20_000];
    let lagged = first_order_lag(&[vec![0.0], step.clone()].concat(), 0.05, 1e-3);
    assert!((lagged.last().unwrap() - 1.0).abs() < 1e-9);
    let rung = resonator(&[vec![0.0], step].concat(), 25.0, 0.05, 1e-3);
    assert!((rung.last().unwrap() - 1.0).abs() < 1e-6);
    let peak = rung.iter().copied().fold(0.0, f64::max);
    assert!(peak > 1.7, "lightly damped step overshoots: {peak}");
}

#[test]
fn form_entries_name_every_parameter_and_count_the_profiled_ones() {
    let form = Form {
        shape: Shape::SlowState { tau_s: 0.5, drive: Drive::RollRate, law: SlowLaw::State, at_alphas: None },
        per_alpha: true,
    };
    let entries = form.entries();
    assert_eq!(entries[0], ("tau_s", FormValue::Number(0.5)));
    assert_eq!(entries[1], ("drive", FormValue::Choice("roll_rate")));
    assert_eq!(entries[2], ("law", FormValue::Choice("state")));
    assert_eq!(entries[3], ("per_alpha", FormValue::Flag(true)));
    assert_eq!(form.n_profiled(), 1);
    assert_eq!(
        Form { shape: Shape::Mode { freq_hz: 9.0, zeta: 0.02, drive_corner_hz: 4.0 }, per_alpha: false }.n_profiled(),
        3
    );
    assert_eq!(Form { shape: Shape::Wander { knot_spacing_s: 2.0 }, per_alpha: false }.n_profiled(), 0);
}

/// The report's statement of a family: its regressors, then every profiled parameter with
/// its range and count, then the choices; a scheduled family says it may take one gain per
/// angle.
#[test]
fn a_family_summary_states_its_forms_and_ranges() {
    let context = test_context();
    let (forms, text) = family_summary(&BalanceResonance, 1000.0, &context);
    assert_eq!(forms, 40 * (3 * 2 + 2));
    assert!(text.starts_with(BalanceResonance.regressors()), "{text}");
    assert!(text.contains("zeta 0.0200 to 0.2500 (4 values)"), "{text}");
    assert!(text.contains("drive: unrecorded"), "{text}");
    assert!(text.contains("freq_hz 4.0000 to 300.0000 (40 values)"), "{text}");
    let (forms, text) = family_summary(&RollDamping, 1000.0, &context);
    assert_eq!(forms, 6);
    assert!(text.ends_with("law: linear or quadratic or cubic; one gain for all angles or one per angle"), "{text}");
}

#[test]
fn every_candidate_has_a_distinct_name_and_a_separating_experiment() {
    let names: std::collections::BTreeSet<&str> = ALL.iter().map(|c| c.name()).collect();
    assert_eq!(names.len(), ALL.len());
    for candidate in ALL {
        assert!(!candidate.separating_experiment().is_empty(), "{}", candidate.name());
    }
}

/// Three angles give every set but none and all (six); five give the bands of neighbouring
/// angles (fourteen), and a set reports its own angles and holds no other.
#[test]
fn angle_sets_are_every_proper_set_of_few_angles_and_bands_of_many() {
    let alphas_deg = [2.0, 10.0, 20.0];
    let sets = AngleSet::proper_sets(alphas_deg.len(), 3);
    assert_eq!(sets.len(), 6);
    let as_angles: Vec<Vec<f64>> = sets.iter().map(|set| set.angles_deg(&alphas_deg)).collect();
    assert!(as_angles.contains(&vec![10.0]), "the inner angle alone");
    assert!(as_angles.contains(&vec![2.0, 20.0]), "both outer angles");
    assert!(!as_angles.contains(&alphas_deg.to_vec()), "every angle is the form without a set");
    let inner = sets[as_angles.iter().position(|a| *a == vec![10.0]).unwrap_or(0)];
    assert!(inner.holds(10.0, &alphas_deg) && !inner.holds(2.0, &alphas_deg) && !inner.holds(12.0, &alphas_deg));
    assert_eq!(FormValue::Angles(inner).to_json(&alphas_deg), serde_json::json!([10.0]));
    let five = [0.0, 5.0, 10.0, 15.0, 20.0];
    let bands = AngleSet::proper_sets(five.len(), 3);
    assert_eq!(bands.len(), 14);
    for band in &bands {
        let slots: Vec<usize> = (0..five.len()).filter(|&slot| band.holds(five[slot], &five)).collect();
        assert!(slots.windows(2).all(|pair| pair[1] == pair[0] + 1), "neighbours: {slots:?}");
    }
}

/// The shortest slow state is twice the eGK lag where the vortex state carries the moment
/// (the largest `|K_v|`), not the prior lag kept where it carries none.
#[test]
fn slow_state_floor_is_twice_the_egk_lag_where_the_vortices_act() {
    let mut set = estimator_core::coeffs::BUILT_IN;
    let n = usize::from(set.n_alpha);
    assert!(n >= 2, "the built-in schedule has several angles");
    for (idx, egk) in set.egk.iter_mut().enumerate().take(n) {
        (egk.tau1_s, egk.vortex_gain) = if idx == n - 1 { (0.04, -0.2) } else { (0.18, 0.001) };
    }
    let alphas: Vec<f64> = set.alpha_schedule_deg[..n].iter().map(|a| f64::from(*a)).collect();
    assert!((slow_tau_min_s(&set, alphas.iter().copied()) - 0.08).abs() < 1e-6);
    // Without the angle where the vortices act, the prior is all there is.
    assert!((slow_tau_min_s(&set, alphas[..1].iter().copied()) - 0.36).abs() < 1e-6);
    assert_eq!(slow_tau_min_s(&set, std::iter::empty()), SLOW_TAU_MIN_S);
}
