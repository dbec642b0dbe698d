//! The sim-to-real gap diagnosis (docs/spec/diagnosis.md): the contract's JSON,
//! named effects on recordings with a known effect, nothing named on clean ones, and a small
//! fixed slice of the blind campaign.

use std::sync::OnceLock;

use diagnosis::diagnose::{DiagnoseConfig, Signature, diagnose, signature};
use diagnosis::validate::{CampaignConfig, effect_ratio, run_campaign, score};
use estimator_core::CoefficientSet;
use firmware_sim::campaign::Scenario;
use firmware_sim::dataset::Dataset;
use firmware_sim::tunnel::effects::{Effects, FaultMode, InertialTare, PressureFault, PressureLag};
use model_fit::fit::pipeline::{FitConfig, fit_dataset};

/// Runs of 20 s at one angle of attack (roll, actuation, roll+actuation).
fn scenario(seed: u64) -> Scenario {
    Scenario { seed, duration_s: 20.0, alphas_deg: vec![10.0], ..Scenario::default() }
}

/// The sim: fitted on a clean recording (40 s runs, another seed), with its signature.
fn clean_model() -> &'static (CoefficientSet, Signature) {
    static MODEL: OnceLock<(CoefficientSet, Signature)> = OnceLock::new();
    MODEL.get_or_init(|| {
        let clean = Scenario { duration_s: 40.0, ..scenario(101) }.simulate(&|| {}).expect("simulates");
        let set = fit_dataset(&clean, &FitConfig::default(), &|_| {}).expect("fits").set;
        let signature = signature(&clean, &set, FitConfig::default().split).expect("signature");
        (set, signature)
    })
}

fn record(effects: Effects) -> Dataset {
    let mut scenario = scenario(7);
    scenario.effects = effects;
    let mut dataset = scenario.simulate(&|| {}).expect("simulates");
    dataset.extra.clear();
    dataset
}

fn run(dataset: &Dataset) -> diagnosis::diagnose::result::Diagnosis {
    let (set, signature) = clean_model();
    let config = DiagnoseConfig { signature: Some(signature.clone()), ..DiagnoseConfig::default() };
    diagnose(dataset, Some((set, "clean fit".into())), &config, &|_| {}).expect("diagnoses").0
}

/// Every number in a JSON value is finite (serde_json writes NaN and infinities as null, so a
/// null where the contract has a number would show a non-finite value).
fn assert_contract_numbers(value: &serde_json::Value, path: &str) {
    match value {
        serde_json::Value::Number(n) => assert!(n.as_f64().is_some_and(f64::is_finite), "{path}"),
        serde_json::Value::Array(items) => {
            items.iter().enumerate().for_each(|(i, v)| assert_contract_numbers(v, &format!("{path}[{i}]")));
        }
        serde_json::Value::Object(map) => {
            map.iter().for_each(|(k, v)| assert_contract_numbers(v, &format!("{path}.{k}")))
        }
        _ => {}
    }
}

/// A recording without any effect: nothing is named and the verdict is the contract's `none`
/// (the gap at the noise floor), not `unattributed`.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn clean_recording_is_at_the_noise_floor() {
    let diagnosis = run(&record(Effects::default()));
    assert!(diagnosis.effects.is_empty(), "{:?}", diagnosis.effects);
    assert_eq!(diagnosis.verdict.as_str(), "none", "{:?}", diagnosis.gap);
}

/// An untared inertial reaction at a few times the balance noise: named first, with its
/// inertia, and the held-out gap shrinks; the JSON has the contract's fields, all finite.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn inertial_tare_is_named_with_its_inertia_and_the_gap_shrinks() {
    let ixx_kgm2 = 4e-5;
    let effects = Effects { inertial_tare: Some(InertialTare { ixx_kgm2 }), ..Effects::default() };
    let dataset = record(effects.clone());
    let ratio =
        effect_ratio(firmware_sim::effect::Effect::InertialTare, &scenario(7), &record(Effects::default()), &dataset)
            .unwrap();
    assert!(ratio > 1.5, "the test's effect must stand above the noise: {ratio}");
    let diagnosis = run(&dataset);
    let json = serde_json::to_value(&diagnosis).unwrap();
    for key in ["verdict", "gap", "where", "effects"] {
        assert!(json.get(key).is_some(), "{key}");
    }
    for key in ["heldout_rms", "noise_rms"] {
        assert!(json["gap"].get(key).is_some(), "gap.{key}");
    }
    assert_contract_numbers(&json["gap"], "gap");
    assert_contract_numbers(&json["effects"], "effects");
    assert_eq!(diagnosis.verdict.as_str(), "effect");
    let top = &diagnosis.effects[0];
    assert_eq!(top.name, "inertial_tare", "{:?}", diagnosis.effects);
    assert_eq!(diagnosis.where_.block.as_deref(), Some("balance"));
    let fitted = top.params["ixx_kgm2"].as_f64().unwrap();
    assert!((fitted / ixx_kgm2 - 1.0).abs() < 0.3, "fitted inertia {fitted} vs {ixx_kgm2}");
    assert!(top.shrink > 0.5 && top.shrink_total > 0.3, "{top:?}");
    assert!((top.shrink - (1.0 - top.heldout_rms_after / top.heldout_rms_before)).abs() < 1e-12);
}

/// The white noise of a balance record: first differences over sqrt(2) (von Neumann), on the
/// first run, whose moment is smooth at the sample rate.
fn balance_noise(dataset: &Dataset) -> f64 {
    let cl = &dataset.runs[0].channels.cl;
    let diffs: Vec<f64> = cl.windows(2).map(|w| w[1] - w[0]).collect();
    (diffs.iter().map(|d| d * d).sum::<f64>() / diffs.len() as f64 / 2.0).sqrt()
}

/// RMS of `added` over the runs it touches, over the balance noise.
fn added_ratio(added: &[Vec<f64>], noise: f64) -> f64 {
    let touched: Vec<f64> = added.iter().filter(|a| a.iter().any(|v| *v != 0.0)).flatten().copied().collect();
    (touched.iter().map(|v| v * v).sum::<f64>() / touched.len() as f64).sqrt() / noise
}

/// A balance zero that settles exponentially in every run (`A_k (1 - exp(-t / 4 s))`, its size
/// and sign per run), one of the contract's forms of `bias_drift`, written here apart from the
/// family: named `bias_drift`.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn exponentially_settling_zero_is_named_bias_drift() {
    let mut dataset = record(Effects::default());
    let noise = balance_noise(&dataset);
    let added: Vec<Vec<f64>> = dataset
        .runs
        .iter()
        .enumerate()
        .map(|(k, run)| {
            let start = run.channels.t_s[0];
            let size = 3.0 * noise * if k % 2 == 0 { 1.0 } else { -1.4 };
            run.channels.t_s.iter().map(|t| size * (1.0 - (-(t - start) / 4.0).exp())).collect()
        })
        .collect();
    for (run, drift) in dataset.runs.iter_mut().zip(&added) {
        run.channels.cl.iter_mut().zip(drift).for_each(|(cl, d)| *cl += d);
    }
    assert!(added_ratio(&added, noise) > 1.5);
    let diagnosis = run(&dataset);
    assert_eq!(diagnosis.verdict.as_str(), "effect", "{:?}", diagnosis.effects);
    assert_eq!(diagnosis.effects[0].name, "bias_drift", "{:?}", diagnosis.effects);
}

/// A dead pressure channel: `pressure_fault` in the sensor block, naming the channel.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn dead_pressure_channel_is_named_with_its_channel() {
    let fault = PressureFault { channel: 5, mode: FaultMode::Dead, value: 0.0, spike_rate_hz: 0.0, start_s: 6.0 };
    let diagnosis = run(&record(Effects { pressure_fault: Some(fault), ..Effects::default() }));
    assert_eq!(diagnosis.effects.first().map(|e| e.name.as_str()), Some("pressure_fault"));
    assert_eq!(diagnosis.where_.block.as_deref(), Some("sensor"));
    assert_eq!(diagnosis.where_.channel.as_deref(), Some("cp05"));
}

/// A channel stuck from the middle of every run: named on its channel, and the fault runs on
/// into the held-out part, where it must account for most of the gap. In 30 s runs the
/// selection blocks hold 9 to 10 s, so the samples the fault is fitted on cannot tell an onset
/// at 9 s from one at 10 s: the fault's interval is taken from the samples that chose it, not
/// from the scan's grid.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn channel_stuck_from_mid_run_is_named_with_its_channel() {
    let fault = PressureFault { channel: 5, mode: FaultMode::Stuck, value: 0.0, spike_rate_hz: 0.0, start_s: 10.0 };
    let mut scenario = Scenario { duration_s: 30.0, ..scenario(77) };
    scenario.effects = Effects { pressure_fault: Some(fault), ..Effects::default() };
    let mut dataset = scenario.simulate(&|| {}).expect("simulates");
    dataset.extra.clear();
    let diagnosis = run(&dataset);
    let first = diagnosis.effects.first().expect("an effect is named");
    assert_eq!(first.name, "pressure_fault");
    assert_eq!(diagnosis.where_.channel.as_deref(), Some("cp05"));
    assert!(first.shrink > 0.5, "held-out shrink {}", first.shrink);
}

/// A small fixed slice of the blind campaign: the truth is sealed, the scorer reads it after
/// the diagnosis, no effect is named on the clean case, and the summary counts every case.
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn blind_campaign_slice_runs_and_scores() {
    let config = CampaignConfig {
        cases: 3,
        seed: 5,
        duration_s: 20.0,
        alphas_deg: vec![10.0],
        ratio_range: [2.0, 4.0],
        classes: vec!["none".into(), "inertial_tare".into(), "pressure_fault".into()],
        keep: None,
        only: Vec::new(),
    };
    let records = run_campaign(&config, &|| {});
    assert_eq!(records.len(), 3);
    for record in &records {
        assert_eq!(record.truth_sha256, model_fit::digest::sha256_hex(record.truth.as_bytes()));
        // The scorer's verdict against the contract's, worked out here from the sealed truth
        // alone: the class is the one effect the truth holds (none for a clean case); a clean
        // case is right only as `none`, an effect only when named first, a sensor effect only
        // on its own channel.
        let held: Vec<&str> = ["inertial_tare", "pressure_fault"]
            .into_iter()
            .filter(|name| record.truth.contains(&format!("{name}: Some")))
            .collect();
        let expected = match record.class.as_str() {
            "none" => {
                assert!(held.is_empty(), "{}", record.truth);
                record.verdict == "none" && record.named.is_empty()
            }
            class => {
                assert_eq!(held, [class], "{}", record.truth);
                let first = record.named.first().is_some_and(|name| name == class);
                first && (class != "pressure_fault" || record.named_channels == record.truth_channels)
            }
        };
        assert_eq!(record.correct, expected, "{record:#?}");
    }
    let summary = score::summarise(&records);
    assert_eq!(summary.cases, 3);
    assert_eq!(summary.none_false_name_rate, Some(0.0));
    let right = records.iter().filter(|r| r.correct).count();
    assert!(right >= 2, "{records:#?}");
    // One case drawn again alone is the campaign's case: its draw depends on the seed and its id.
    let alone = run_campaign(&CampaignConfig { only: vec![2], ..config }, &|| {});
    let (again, before) = (&alone[0], &records[2]);
    assert_eq!(alone.len(), 1);
    assert_eq!(
        (again.id, &again.truth_sha256, &again.verdict, &again.named, &again.named_channels),
        (before.id, &before.truth_sha256, &before.verdict, &before.named, &before.named_channels)
    );
}

/// A recording at another sample rate than the sim's step is refused with the run named, not
/// diagnosed on a wrong time scale.
#[test]
fn recording_at_another_rate_is_refused_naming_the_run() {
    let dataset = Scenario { sample_hz: 500.0, duration_s: 2.0, ..scenario(3) }.simulate(&|| {}).expect("simulates");
    let set = estimator_core::coeffs::DEFAULT;
    let error = diagnose(&dataset, Some((&set, "built-in".into())), &DiagnoseConfig::default(), &|_| {}).unwrap_err();
    let message = error.to_string();
    assert!(message.contains("runs/") && message.contains("500") && message.contains("1000"), "{message}");
}

/// `scenario` recorded without its provenance and diagnosed against the built-in model and its
/// signature.
fn diagnose_against_built_in(scenario: &Scenario) -> diagnosis::diagnose::result::Diagnosis {
    let mut dataset = scenario.simulate(&|| {}).expect("simulates");
    dataset.extra.clear();
    let set = estimator_core::coeffs::DEFAULT;
    let config =
        DiagnoseConfig { signature: Some(diagnosis::diagnose::default_signature()), ..DiagnoseConfig::default() };
    diagnose(&dataset, Some((&set, "built-in".into())), &config, &|_| {}).expect("diagnoses").0
}

/// The default campaign (seed 1, three angles of attack, 50 s runs) with every pressure channel
/// lagged by 50 ms (tubing), diagnosed against the built-in model and its signature:
/// `pressure_lag` is named with all twelve channels and a time constant within 20 %. The
/// filter's innovations alone cannot see such a lag (the filter follows the lagged readings).
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn lag_of_every_pressure_channel_is_named_with_all_channels_and_its_time_constant() {
    let tau_s = 0.05;
    let mut scenario = Scenario::default();
    scenario.effects.pressure_lag = Some(PressureLag { tau_s, channels: Vec::new() });
    let diagnosis = diagnose_against_built_in(&scenario);
    assert_eq!(diagnosis.verdict.as_str(), "effect");
    let top = &diagnosis.effects[0];
    assert_eq!(top.name, "pressure_lag", "{:?}", diagnosis.effects);
    assert_eq!(diagnosis.where_.block.as_deref(), Some("sensor"));
    let expected: Vec<String> = (1..=12).map(|tap| format!("cp{tap:02}")).collect();
    assert_eq!(diagnosis.where_.channels, expected);
    let fitted = top.params["tau_s"].as_f64().unwrap();
    assert!((fitted / tau_s - 1.0).abs() < 0.2, "fitted {fitted} s vs {tau_s} s");
    assert!(top.shrink > 0.5, "{top:?}");
}

/// Three of the twelve channels lagged by 40 ms, 30 s runs of another seed: `pressure_lag` is
/// named with exactly those three channels. The innovations singled out one of them (the
/// filter's modes follow the lagged readings), and a healthy channel's innovation carried
/// their footprint, named a bias fault before. Each channel's time constant is within 40 %
/// (measured 43 ms each, judged without the group; 43, 28.5 and 43 ms on what the filter
/// without each channel alone expects, which still carries the other two's lag).
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn lag_of_three_pressure_channels_is_named_with_those_channels() {
    assert_group_lag_named(5, 0.04, &[2, 6, 10], 0.4, 0.5);
}

/// A lag of `tau_s` on `channels` (1-based) in 30 s runs of `seed`: `pressure_lag` is named
/// first with exactly those channels, each time constant within `tolerance` of the truth, and a
/// held-out shrink above `min_shrink`.
fn assert_group_lag_named(seed: u64, tau_s: f64, channels: &[usize], tolerance: f64, min_shrink: f64) {
    let mut scenario = Scenario { seed, duration_s: 30.0, ..Scenario::default() };
    scenario.effects.pressure_lag = Some(PressureLag { tau_s, channels: channels.to_vec() });
    let diagnosis = diagnose_against_built_in(&scenario);
    assert_eq!(diagnosis.verdict.as_str(), "effect");
    let top = &diagnosis.effects[0];
    assert_eq!(top.name, "pressure_lag", "{:?}", diagnosis.effects);
    let expected: Vec<String> = channels.iter().map(|tap| format!("cp{tap:02}")).collect();
    assert_eq!(diagnosis.where_.channels, expected);
    for channel in &diagnosis.where_.channels {
        let fitted = top.params[&format!("tau_s_{channel}")].as_f64().unwrap();
        assert!((fitted / tau_s - 1.0).abs() < tolerance, "{channel}: fitted {fitted} s vs {tau_s} s");
    }
    assert!(top.shrink > min_shrink, "{top:?}");
}

/// Five of the twelve channels lagged by 30 ms (tubes of one length): what the other channels
/// expect of each carries much of the group's lag, so the group is judged again without
/// itself. Named with exactly those channels (before: a bias fault of cp06, a healthy channel
/// carrying the group's footprint), each time constant within half of the truth (the fit
/// trades part of the lag that the filter's expectation still carries for a longer time
/// constant at a smaller gain).
#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn lag_of_five_pressure_channels_is_named_with_all_five() {
    assert_group_lag_named(6, 0.03, &[2, 4, 5, 8, 11], 0.5, 0.2);
}
