//! The synthetic wind tunnel: determinism, the paper's Table 1 on the default campaign, and
//! that each effect, switched on alone, changes the channels it should and no others.

use evaluation::analysis::superposition::superposition_table;
use firmware_sim::campaign::Scenario;
use firmware_sim::dataset::{Channels, Dataset, RunKind};
use firmware_sim::effect::Effect;

/// A short campaign at one alpha with all three kinds, where every effect is visible.
fn short_scenario(alpha_deg: f64) -> Scenario {
    let mut scenario = Scenario { duration_s: 12.0, alphas_deg: vec![alpha_deg], ..Scenario::default() };
    scenario.excitation.blowing.delay_s = 1.0;
    scenario
}

fn simulate(scenario: &Scenario) -> Dataset {
    scenario.simulate(&|| {}).expect("a valid scenario simulates")
}

/// Names of the recorded columns of `with` that differ from `without` (NaN-aware, bit-exact).
fn changed_columns(without: &Channels, with: &Channels) -> Vec<String> {
    let mut columns: Vec<(String, &Vec<f64>, &Vec<f64>)> = vec![
        ("t_s".into(), &without.t_s, &with.t_s),
        ("phi_deg".into(), &without.phi_deg, &with.phi_deg),
        ("cmu_port".into(), &without.cmu_port, &with.cmu_port),
        ("cmu_stbd".into(), &without.cmu_stbd, &with.cmu_stbd),
        ("cl".into(), &without.cl, &with.cl),
    ];
    for tap in 0..12 {
        columns.push((format!("cp{:02}", tap + 1), &without.cp[tap], &with.cp[tap]));
    }
    let optional = [
        ("phi_cmd_deg", &without.phi_cmd_deg, &with.phi_cmd_deg),
        ("cmu_port_cmd", &without.cmu_port_cmd, &with.cmu_port_cmd),
        ("cmu_stbd_cmd", &without.cmu_stbd_cmd, &with.cmu_stbd_cmd),
    ];
    for (name, a, b) in optional {
        if let (Some(a), Some(b)) = (a, b) {
            columns.push((name.into(), a, b));
        }
    }
    columns
        .into_iter()
        .filter(|(_, a, b)| a.len() != b.len() || a.iter().zip(b.iter()).any(|(x, y)| x.to_bits() != y.to_bits()))
        .map(|(name, _, _)| name)
        .collect()
}

/// Every column an effect changed, over the runs of each kind.
fn changes_by_kind(effect: &str, alpha_deg: f64) -> Vec<(RunKind, Vec<String>)> {
    let baseline = short_scenario(alpha_deg);
    let mut with_effect = baseline.clone();
    with_effect.apply_effect_arg(effect).expect("a vocabulary effect parses");
    let (without, with) = (simulate(&baseline), simulate(&with_effect));
    without.runs.iter().zip(&with.runs).map(|(a, b)| (a.meta.kind, changed_columns(&a.channels, &b.channels))).collect()
}

fn all_cp() -> Vec<String> {
    (1..=12).map(|tap| format!("cp{tap:02}")).collect()
}

fn cl_and_cp() -> Vec<String> {
    let mut columns = vec!["cl".to_owned()];
    columns.extend(all_cp());
    columns
}

/// The moment and the taps of the port half-wing (`cp01`..`cp06`), which is the blown side of
/// the default campaign.
fn cl_and_port_cp() -> Vec<String> {
    let mut columns = vec!["cl".to_owned()];
    columns.extend((1..=6).map(|tap| format!("cp{tap:02}")));
    columns
}

/// Asserts that `effect` changes exactly `expected` in the runs of the kinds listed, and
/// nothing in the others.
fn assert_effect(effect: &str, alpha_deg: f64, expected: &[String], kinds: &[RunKind]) {
    assert_effect_by_kind(effect, alpha_deg, |kind| if kinds.contains(&kind) { expected.to_vec() } else { Vec::new() });
}

/// Asserts that `effect` changes exactly `expected(kind)` in the run of each kind.
fn assert_effect_by_kind(effect: &str, alpha_deg: f64, expected: impl Fn(RunKind) -> Vec<String>) {
    for (kind, mut changed) in changes_by_kind(effect, alpha_deg) {
        changed.sort();
        let mut want = expected(kind);
        want.sort();
        assert_eq!(changed, want, "effect {effect} in the {kind} run at alpha {alpha_deg}");
    }
}

const BLOWN: [RunKind; 2] = [RunKind::Actuation, RunKind::RollActuation];
const ROLLED: [RunKind; 2] = [RunKind::Roll, RunKind::RollActuation];
const ALL: [RunKind; 3] = [RunKind::Roll, RunKind::Actuation, RunKind::RollActuation];

#[test]
fn actuator_delay_changes_moment_and_blown_side_pressures_of_blown_runs_only() {
    assert_effect("actuator_delay", 20.0, &cl_and_port_cp(), &BLOWN);
}

#[test]
fn actuator_lag_changes_moment_and_blown_side_pressures_of_blown_runs_only() {
    assert_effect("actuator_lag", 20.0, &cl_and_port_cp(), &BLOWN);
}

#[test]
fn inertial_tare_changes_the_balance_of_rolled_runs_only() {
    assert_effect("inertial_tare", 10.0, &["cl".to_owned()], &ROLLED);
}

#[test]
fn gravity_tare_changes_the_balance_of_rolled_runs_only() {
    assert_effect("gravity_tare", 0.0, &["cl".to_owned()], &ROLLED);
}

#[test]
fn roll_damping_changes_the_moment_of_rolled_runs_only() {
    assert_effect("roll_damping", 0.0, &["cl".to_owned()], &ROLLED);
}

#[test]
fn vortex_lag_changes_moment_and_pressures_where_the_vortex_moves() {
    // At alpha = 20 deg roll moves both vortex states; port blowing alone moves the port one.
    assert_effect_by_kind("vortex_lag:tau_s=0.8,weight=0.6", 20.0, |kind| match kind {
        RunKind::Actuation => cl_and_port_cp(),
        _ => cl_and_cp(),
    });
}

#[test]
fn coupling_changes_only_the_roll_plus_actuation_moment() {
    assert_effect("coupling", 10.0, &["cl".to_owned()], &[RunKind::RollActuation]);
}

#[test]
fn pressure_lag_changes_only_pressures() {
    assert_effect("pressure_lag", 10.0, &all_cp(), &ALL);
    assert_effect("pressure_lag:tau_s=0.01,channels=[3]", 10.0, &["cp03".to_owned()], &ALL);
}

#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn pressure_fault_changes_only_its_channel() {
    for mode in ["stuck", "dead", "bias", "spike"] {
        assert_effect(&format!("pressure_fault:channel=5,mode={mode}"), 10.0, &["cp05".to_owned()], &ALL);
    }
}

#[test]
fn dead_pressure_channel_is_missing_not_zero() {
    let mut scenario = short_scenario(0.0);
    scenario.apply_effect_arg("pressure_fault:channel=2,mode=dead,start_s=3").expect("parses");
    let dataset = simulate(&scenario);
    let cp02 = &dataset.runs[0].channels.cp[1];
    assert!(cp02[..3000].iter().all(|value| value.is_finite()));
    assert!(cp02[3000..].iter().all(|value| value.is_nan()));
}

#[test]
fn balance_resonance_changes_only_the_balance() {
    assert_effect("balance_resonance", 10.0, &["cl".to_owned()], &ALL);
}

#[test]
fn bias_drift_changes_only_the_balance() {
    assert_effect("bias_drift", 0.0, &["cl".to_owned()], &ALL);
}

#[test]
fn outside_vocabulary_effects_reach_the_aerodynamics() {
    assert_effect("q_fluctuation", 10.0, &cl_and_cp(), &ALL);
    assert_effect("cubic_stiffness", 10.0, &["cl".to_owned()], &ROLLED);
}

#[test]
fn every_named_effect_is_switchable_by_name() {
    for effect in Effect::ALL {
        let mut scenario = Scenario::default();
        scenario.apply_effect_arg(effect.name()).expect("every effect has a moderate default");
        assert_eq!(scenario.effects.on(), vec![effect]);
    }
}

#[test]
fn unknown_effect_or_key_is_refused_with_its_name() {
    let mut scenario = Scenario::default();
    let error = scenario.apply_effect_arg("warp_drive").expect_err("not an effect").to_string();
    assert!(error.contains("warp_drive"), "{error}");
    let error = scenario.apply_effect_arg("actuator_delay:delay_ms=3").expect_err("wrong key").to_string();
    assert!(error.contains("delay_ms"), "{error}");
}

#[test]
fn scenario_file_switches_effects_and_overrides_parameters() {
    let scenario = Scenario::from_toml(
        "seed = 9\nalphas_deg = [5]\n[aero]\nclp = -0.2\n[effects.actuator_delay]\ndelay_s = 0.04\n[effects.bias_drift]\n",
    )
    .expect("valid scenario");
    assert_eq!(scenario.seed, 9);
    assert_eq!(scenario.aero.clp, -0.2);
    assert_eq!(scenario.effects.actuator_delay.map(|delay| delay.delay_s), Some(0.04));
    assert_eq!(scenario.effects.on(), vec![Effect::ActuatorDelay, Effect::BiasDrift]);
    let error = Scenario::from_toml("[aero]\nclp_typo = 1\n").expect_err("unknown key");
    assert!(error.contains("clp_typo"), "{error}");
}

/// The scenario files the docs tell users to simulate (firmware-sim/scenarios) load, and the
/// mismatched-eGK one is the default wing with only its vortex slowed: its pressure taps and
/// everything else stay the default campaign's, so the eGK fitted there is wrong for it alone.
#[test]
fn committed_scenario_files_load_and_the_mismatched_egk_one_slows_only_the_vortex() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware-sim/scenarios");
    let mut loaded = std::collections::BTreeMap::new();
    for entry in std::fs::read_dir(&dir).expect("the scenarios folder") {
        let path = entry.expect("a folder entry").path();
        let scenario = Scenario::from_file(&path).unwrap_or_else(|err| panic!("{}: {err}", path.display()));
        loaded.insert(path.file_name().expect("a file name").to_string_lossy().into_owned(), scenario);
    }
    let names: Vec<&String> = loaded.keys().collect();
    let mismatched = loaded.get("mismatched-egk.toml").cloned().unwrap_or_else(|| panic!("{names:?}"));
    let default = Scenario::default();
    assert!(mismatched.aero.tau1_s > 1.5 * default.aero.tau1_s, "{}", mismatched.aero.tau1_s);
    let slowed_back = Scenario {
        seed: default.seed,
        aero: firmware_sim::tunnel::params::AeroParams { tau1_s: default.aero.tau1_s, ..mismatched.aero },
        ..mismatched
    };
    assert_eq!(slowed_back, default);
}

#[test]
fn default_scenario_has_no_effect_and_is_deterministic() {
    assert!(Scenario::default().effects.on().is_empty());
    let mut scenario = short_scenario(10.0);
    scenario.duration_s = 3.0;
    assert_eq!(simulate(&scenario), simulate(&scenario));
    let mut other_seed = scenario.clone();
    other_seed.seed += 1;
    assert_ne!(simulate(&scenario).runs[0].channels.cl, simulate(&other_seed).runs[0].channels.cl);
}

#[test]
fn kinds_at_one_alpha_share_their_inputs() {
    let dataset = simulate(&short_scenario(10.0));
    let [roll, actuation, both] = [&dataset.runs[0], &dataset.runs[1], &dataset.runs[2]];
    assert_eq!(roll.channels.phi_cmd_deg, both.channels.phi_cmd_deg);
    assert_eq!(actuation.channels.cmu_port_cmd, both.channels.cmu_port_cmd);
    assert!(actuation.channels.phi_deg.iter().all(|&phi| phi == 0.0));
    assert!(roll.channels.cmu_port.iter().all(|&cmu| cmu == 0.0));
    // Blowing is delayed from the roll signal, as in the paper.
    assert!(both.channels.cmu_port_cmd.as_ref().is_some_and(|cmd| cmd[..1000].iter().all(|&c| c == 0.0)));
}

/// The paper's Table 1 on the default campaign: sigma(Delta C_l) / mean(C_l,RollAFC) rises with
/// alpha and lies within 20 % of 11 %, 15 % and 30 % (measured 12.6, 13.8 and 28.1 %,
/// docs/results.md): the tunnel's interaction is calibrated to the paper's, and a change that
/// moves it by a fifth is a change of the experiment.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn default_campaign_reproduces_table_1_within_20_percent() {
    let rows =
        superposition_table(crate::fixture::default_campaign()).expect("the default campaign has the three kinds");
    let paper = [0.11, 0.15, 0.30];
    assert_eq!(rows.len(), 3);
    for (row, target) in rows.iter().zip(paper) {
        assert!(
            (row.ratio_to_mean / target - 1.0).abs() <= 0.2,
            "alpha {}: {:.3} vs paper {target}",
            row.alpha_deg,
            row.ratio_to_mean
        );
    }
    assert!(rows[0].ratio_to_mean < rows[1].ratio_to_mean && rows[1].ratio_to_mean < rows[2].ratio_to_mean);
}
