//! The command line's library functions (`host_tools::command`) on a small campaign, each
//! checked on its typed summary: the numbers a user reads, with bounds a wrong result breaks.

use std::path::{Path, PathBuf};

use host_tools::command::data::{ScenarioArgs, SimulateArgs, SuperpositionArgs, simulate, superposition};
use host_tools::command::diagnosis::{DiagnoseArgs, SignatureSource, diagnose};
use host_tools::command::model::{CodegenArgs, EvaluateArgs, FitArgs, ReplayArgs, codegen, evaluate, fit, replay};
use host_tools::command::reliability::{FaultsArgs, faults};
use host_tools::command::{CommandError, Silent};
use model_fit::fit::split::DEFAULT_HOLDOUT_FRACTION;

fn scenario(duration_s: f64) -> ScenarioArgs {
    ScenarioArgs { scenario: None, seed: Some(7), duration_s: Some(duration_s), effects: Vec::new() }
}

fn path(dir: &Path, name: &str) -> PathBuf {
    dir.join(name)
}

#[test]
#[ignore = "slow tier: ./ci.sh test runs it"]
fn every_data_and_model_command_returns_its_numbers() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let (data, model) = (path(dir.path(), "data"), path(dir.path(), "model"));

    let simulated =
        simulate(&SimulateArgs { out: data.clone(), scenario: scenario(20.0) }, &Silent).expect("simulates");
    assert_eq!(simulated.n_runs, 9, "three kinds of run at three angles of attack");

    // The paper's Table 1: the superposition's error is a fraction of the moment's spread.
    let table = superposition(&SuperpositionArgs { data: data.clone(), json: false }).expect("Table 1");
    assert_eq!(table.rows.iter().map(|row| row.alpha_deg).collect::<Vec<_>>(), [0.0, 10.0, 20.0]);
    for row in &table.rows {
        assert!(row.ratio_to_std > 0.0 && row.ratio_to_std < 0.5, "{row:?}");
    }

    let fit_args =
        FitArgs { data: data.clone(), out: model.clone(), seed: 7, holdout_fraction: DEFAULT_HOLDOUT_FRACTION };
    let fitted = fit(&fit_args, &Silent).expect("fits");
    assert!(model.join("model.bin").is_file());
    assert_eq!(fitted.report.heldout.per_alpha.len(), 3);
    for row in &fitted.report.heldout.per_alpha {
        let noise = row.noise_rms.expect("balance noise");
        // A fit that missed the wing errs by its whole moment (|C_l| up to 0.05), two orders
        // above the balance's noise.
        assert!(row.fused_rms.expect("fused") < 2.0 * noise, "{row:?}");
        assert!(row.plant_rms.expect("plant") < 2.0 * noise, "{row:?}");
        assert!(row.coupled_rms.expect("coupled") < 3.0 * noise, "{row:?}");
    }
    assert!(fitted.to_string().starts_with("held-out RMS of C_l"), "{fitted}");

    // The tables generated from the fit, then checked against a changed copy.
    let generated = path(dir.path(), "generated");
    let mut codegen_args =
        CodegenArgs { model: model.clone(), check: false, out: Some(generated.clone()), provenance: None };
    assert!(!codegen(&codegen_args).expect("generates").checked);
    codegen_args.check = true;
    assert!(codegen(&codegen_args).expect("up to date").checked);
    let module = generated.join("mod.rs");
    let text = std::fs::read_to_string(&module).expect("generated");
    std::fs::write(&module, text.replacen("pub const", "pub(crate) const", 1)).expect("altered");
    assert!(matches!(codegen(&codegen_args), Err(CommandError::Codegen(_))), "a stale file is an error");
    // Generated again, then a file the generator does not write is found too.
    codegen_args.check = false;
    codegen(&codegen_args).expect("generates again");
    std::fs::write(generated.join("old.rs"), "").expect("a leftover");
    codegen_args.check = true;
    assert!(matches!(codegen(&codegen_args), Err(CommandError::Codegen(_))), "a leftover file is an error");

    let replayed = replay(
        &ReplayArgs {
            data: data.clone(),
            model: Some(model.clone()),
            out: path(dir.path(), "replay"),
            faults: Vec::new(),
            fault_seed: 1,
        },
        &Silent,
    )
    .expect("replays");
    assert_eq!(replayed.n_runs, 9);

    let evaluate_args = EvaluateArgs {
        data: data.clone(),
        model: Some(model.clone()),
        report: path(dir.path(), "evaluation"),
        seed: 1,
        holdout_fraction: DEFAULT_HOLDOUT_FRACTION,
    };
    let evaluated = evaluate(&evaluate_args, &Silent).expect("evaluates");
    assert!(evaluated.report.is_file() && evaluated.warnings.is_empty(), "{:?}", evaluated.warnings);
    for row in &evaluated.evaluation.coupling {
        // The operator was chosen on other samples; on the held-out ones it may not make the
        // superposition worse.
        assert!(row.ratio <= 1.05, "{row:?}");
    }

    let diagnosed = diagnose(
        &DiagnoseArgs {
            real: data.clone(),
            model: Some(model.clone()),
            report: path(dir.path(), "diagnosis"),
            holdout_fraction: DEFAULT_HOLDOUT_FRACTION,
        },
        &Silent,
    )
    .expect("diagnoses");
    assert_eq!(diagnosed.diagnosis.verdict.as_str(), "none", "the recording the sim was fitted on");
    assert_eq!(diagnosed.signature, SignatureSource::Model(model.clone()), "fit wrote the model's signature");

    let studied = faults(
        &FaultsArgs {
            data,
            model: Some(model),
            report: path(dir.path(), "faults"),
            seed: 1,
            holdout_fraction: DEFAULT_HOLDOUT_FRACTION,
        },
        &Silent,
    )
    .expect("the fault study");
    let noise = fitted.report.heldout.per_alpha.iter().filter_map(|row| row.noise_rms).fold(0.0, f64::max);
    assert!(studied.study.clean_rms < 3.0 * noise, "{} against noise {noise}", studied.study.clean_rms);
    for row in &studied.study.rows {
        assert!(row.meets_goals, "{row:?}");
    }
}

#[test]
fn a_holdout_outside_its_range_is_refused_before_anything_is_read_or_written() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let out = path(dir.path(), "model");
    let args = FitArgs { data: path(dir.path(), "no-data"), out: out.clone(), seed: 1, holdout_fraction: 1.0 };
    let error = fit(&args, &Silent).expect_err("a holdout of 1 leaves nothing to fit");
    assert!(matches!(error, CommandError::Flag { flag: "--holdout-fraction", .. }), "{error}");
    assert!(error.to_string().contains("[0, 1)"), "{error}");
    assert!(!out.exists());
}
