//! Replay and evaluation: the replay writes every stage's estimate per run, the evaluation
//! writes a complete report, and both degrade gracefully on datasets with fewer kinds of run.

use evaluation::evaluate::{EvaluationConfig, evaluate, evaluation_report, figures};
use firmware_sim::campaign::{KindName, Scenario};
use firmware_sim::dataset::{RunKind, load_dataset, write_dataset};
use model_fit::replay::{REPLAY_COLUMNS, write_replay};

fn short(kinds: &[RunKind]) -> firmware_sim::dataset::Dataset {
    let mut scenario = Scenario {
        duration_s: 12.0,
        alphas_deg: vec![0.0, 20.0],
        kinds: kinds.iter().map(|&kind| KindName(kind)).collect(),
        ..Scenario::default()
    };
    scenario.excitation.blowing.delay_s = 1.0;
    scenario.simulate(&|| {}).expect("simulates")
}

#[test]
fn replay_writes_every_stage_for_every_sample() {
    let dataset = short(&[RunKind::Roll, RunKind::Actuation]);
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("replay");
    let n_runs = write_replay(&out, &dataset, &estimator_core::coeffs::DEFAULT, "test").expect("writes");
    assert_eq!(n_runs, 4);
    let text = std::fs::read_to_string(out.join("runs/roll_a20.csv")).expect("per-run csv");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(REPLAY_COLUMNS.join(",").as_str()));
    assert_eq!(
        REPLAY_COLUMNS[5..16].join(","),
        "cl,cl_egk,cl_pressure,cl_roll,cl_afc_port,cl_afc_stbd,cl_afc,cl_linear,coupling,cl_est,phi_dot_rad_s"
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), 12_000);
    let last: Vec<&str> = rows[rows.len() - 1].split(',').collect();
    assert_eq!(last.len(), REPLAY_COLUMNS.len());
    let cl_est: f64 = last[14].parse().expect("a finite estimate");
    assert!(cl_est.is_finite());
    assert!(out.join("replay.toml").is_file());
    // The written estimate follows the balance: the roll run's moment spans about +-0.05, the
    // balance's noise is 3e-4, and the built-in model's error is near that noise. An estimate
    // of the wrong sign, scale or column would err by the moment itself.
    let column =
        |row: &str, idx: usize| -> f64 { row.split(',').nth(idx).and_then(|v| v.parse().ok()).unwrap_or(f64::NAN) };
    let (cl_idx, est_idx) = (5, 14);
    let pairs: Vec<(f64, f64)> = rows.iter().map(|row| (column(row, cl_idx), column(row, est_idx))).collect();
    let rms = |values: &mut dyn Iterator<Item = f64>| {
        let (sum, n) = values.fold((0.0, 0usize), |(sum, n), v| (sum + v * v, n + 1));
        (sum / n.max(1) as f64).sqrt()
    };
    let error = rms(&mut pairs.iter().filter(|(cl, _)| cl.is_finite()).map(|(cl, est)| est - cl));
    let spread = rms(&mut pairs.iter().filter(|(cl, _)| cl.is_finite()).map(|(cl, _)| *cl));
    assert!(error < 0.1 * spread, "replayed C_l errs {error:.2e} against a moment of {spread:.2e}");
}

#[test]
fn evaluation_report_is_complete_on_the_three_kinds() {
    let dataset = short(&[RunKind::Roll, RunKind::Actuation, RunKind::RollActuation]);
    let config = EvaluationConfig { noise_levels: vec![0.001, 0.004], ..EvaluationConfig::default() };
    let (evaluation, replayed) = evaluate(&dataset, &estimator_core::coeffs::DEFAULT, &config).expect("evaluates");
    assert_eq!(evaluation.table1.len(), 2);
    assert_eq!(evaluation.coupling.len(), 2);
    assert_eq!(evaluation.noise_robustness.len(), 2);
    assert_eq!(evaluation.blocks.len(), 12, "six blocks at two angles of attack");
    for row in &evaluation.coupling {
        assert!(row.ratio.is_finite() && row.ratio > 0.0 && row.corr_linear.is_finite(), "{row:?}");
        // Every comparison carries its bootstrap interval, and the interval holds the estimate
        // it is drawn around (an interval resampled from other samples, or of another
        // statistic, need not).
        let [low, high] = row.ratio_ci95.expect("ratio interval");
        assert!(low.is_finite() && row.bootstrap_block >= 1, "{row:?}");
        assert!(low <= row.ratio && row.ratio <= high, "ratio outside its interval: {row:?}");
        let [low, high] = row.corr_change_ci95.expect("correlation-change interval");
        let change = row.corr_operator - row.corr_linear;
        assert!(low.is_finite() && low <= change && change <= high, "change outside its interval: {row:?}");
    }
    assert_eq!(evaluation.fusion.len(), 2, "the fusion against its sources at both angles");
    for row in &evaluation.fusion {
        let [low, high] = row.over_egk_ci95.expect("interval against the eGK");
        assert!(low <= row.over_egk && row.over_egk <= high && row.over_egk > 0.0, "{row:?}");
        let [low, high] = row.over_pressure_ci95.expect("interval against the pressure path");
        assert!(low <= row.over_pressure && row.over_pressure <= high, "{row:?}");
        // The Kalman fusion weighs its sources by their noise: not worse than the better one by
        // more than 2 %, and better than the worse one.
        assert!(row.over_egk < 1.02 && row.over_pressure < 1.0, "{row:?}");
    }
    // The built-in model on recordings of the wing it was fitted to: every block follows the
    // balance (measured 0.86 to 0.99; a block with a wrong sign or a missing input correlates
    // far less), and its error is a few balance-noise RMS (measured 1.0 to 3.9), not the
    // moment's (|C_l| up to 0.05, a hundred times the noise).
    for row in &evaluation.blocks {
        assert!(row.correlation > 0.8, "{row:?}");
        let bound = if row.block == "pressure" { 6.0 } else { 3.0 };
        assert!(row.rms_over_noise < bound, "{row:?}");
    }
    // More balance noise never makes the refitted estimate follow the balance better.
    for pair in evaluation.noise_robustness.windows(2) {
        for (quiet, noisy) in pair[0].per_alpha.iter().zip(&pair[1].per_alpha) {
            assert!(noisy.corr_operator <= quiet.corr_operator + 1e-3, "{quiet:?} {noisy:?}");
        }
    }
    let figures = figures(&dataset, &replayed, &config.split, &evaluation, None);
    assert!(figures.iter().any(|figure| figure.file == "fig10_operator.svg" && figure.svg.starts_with("<svg")));
    let report = evaluation_report(&evaluation, figures, "test");
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("report");
    let json = serde_json::to_value(&evaluation).expect("serialises");
    reports::write_report(&dir, &report, "evaluation.json", &json).expect("writes");
    for file in ["report.html", "report.md", "evaluation.json", "fig07_plant.svg", "blocks.svg"] {
        assert!(dir.join(file).is_file(), "{file}");
    }
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert!(html.contains("Table 2: error with the coupling operator"));
}

#[test]
fn evaluation_without_roll_plus_actuation_runs_says_what_is_missing() {
    let dataset = short(&[RunKind::Roll, RunKind::Actuation]);
    let config = EvaluationConfig { noise_levels: vec![0.001, 0.004], ..EvaluationConfig::default() };
    let (evaluation, _) = evaluate(&dataset, &estimator_core::coeffs::DEFAULT, &config).expect("evaluates");
    assert!(evaluation.coupling.is_empty() && evaluation.table1.is_empty());
    assert!(evaluation.notes.iter().any(|note| note.contains("roll+actuation")), "{:?}", evaluation.notes);
}

#[test]
fn model_argument_accepts_the_folder_or_the_blob_and_refuses_garbage() {
    let root = tempfile::tempdir().unwrap();
    let default = model_fit::codegen::default_model();
    let (from_folder, _) = model_fit::model::load(Some(&default)).expect("folder");
    let (from_blob, _) = model_fit::model::load(Some(&default.join("model.bin"))).expect("blob");
    assert_eq!(from_folder, from_blob);
    let garbage = root.path().join("model.bin");
    std::fs::write(&garbage, b"not a blob").unwrap();
    let error = model_fit::model::load(Some(&garbage)).expect_err("garbage").to_string();
    assert!(error.contains("model.bin") && error.contains("not a usable coefficient blob"), "{error}");
}

#[test]
fn replayed_dataset_round_trips_through_disk() {
    // Replay reads what the dataset writer wrote: the same estimates from memory and from disk.
    let dataset = short(&[RunKind::Roll]);
    let root = tempfile::tempdir().unwrap();
    write_dataset(&root.path().join("data"), &dataset).unwrap();
    let loaded = load_dataset(&root.path().join("data")).unwrap();
    let set = estimator_core::coeffs::DEFAULT;
    let from_memory = model_fit::replay::replay_run(&set, &dataset.runs[0]);
    let from_disk = model_fit::replay::replay_run(&set, &loaded.runs[0]);
    assert_eq!(from_memory, from_disk);
}

/// The pressure-information bound finds what the pressures know: with a moment that only one
/// tap sees added to the balance, the eGK's error grows by a third or more, and the best linear
/// use of the pressures takes it back to within 5 % of the eGK's error on the clean recording.
#[test]
fn pressure_information_finds_a_moment_only_the_taps_see() {
    let config = EvaluationConfig { noise_levels: vec![], ..EvaluationConfig::default() };
    let mut dataset = short(&[RunKind::Roll]);
    let (clean, _) = evaluate(&dataset, &estimator_core::coeffs::DEFAULT, &config).expect("evaluates");
    for run in &mut dataset.runs {
        let tap = &run.channels.cp[2];
        let mean = tap.iter().sum::<f64>() / tap.len() as f64;
        let added: Vec<f64> = tap.iter().map(|cp| 0.05 * (cp - mean)).collect();
        for (cl, added) in run.channels.cl.iter_mut().zip(added) {
            *cl += added;
        }
    }
    let (with_tap, _) = evaluate(&dataset, &estimator_core::coeffs::DEFAULT, &config).expect("evaluates");
    assert_eq!(with_tap.pressure_information.len(), 2, "one row per angle of attack");
    for (clean, row) in clean.pressure_information.iter().zip(&with_tap.pressure_information) {
        assert!(row.egk_rms > 1.3 * clean.egk_rms, "{clean:?} {row:?}");
        assert!(row.best_linear_rms < 1.05 * clean.egk_rms, "{clean:?} {row:?}");
    }
}
