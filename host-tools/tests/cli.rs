//! The built `host-tools` binary end to end, as a user runs it: a small campaign of the
//! synthetic tunnel is simulated, fitted, replayed and diagnosed, and a bad path is refused.
//! (The workspace's topic tests live in the `tests` crate; this one needs the binary itself,
//! which only this package's integration tests are given, `CARGO_BIN_EXE_host-tools`.)

use std::path::Path;
use std::process::{Command, Output};

fn host_tools(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host-tools")).args(args).output().expect("the binary runs")
}

fn succeeded(output: &Output, what: &str) -> String {
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(output.status.success(), "{what} failed:\n{stdout}\n{}", String::from_utf8_lossy(&output.stderr));
    stdout
}

/// The fit's held-out table: per angle of attack, the fused disturbance estimate's error and
/// the balance's white noise, and the coupling operator's `E_SINDy/E_lin`.
fn heldout_rows(stdout: &str) -> Vec<(f64, f64, f64, f64)> {
    stdout
        .lines()
        .filter_map(|line| {
            let cells: Vec<f64> = line.split_whitespace().map(str::parse).collect::<Result<_, _>>().ok()?;
            (cells.len() == 9).then(|| (cells[0], cells[3], cells[7], cells[8]))
        })
        .collect()
}

#[test]
fn a_small_campaign_is_simulated_fitted_replayed_and_diagnosed() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let path = |name: &str| dir.path().join(name).display().to_string();
    let (data, model, replay, diagnosis) = (path("data"), path("model"), path("replay"), path("diagnosis"));

    succeeded(&host_tools(&["simulate", "--duration-s", "20", "--out", &data]), "simulate");
    let runs = std::fs::read_dir(Path::new(&data).join("runs")).expect("runs written").count();
    assert_eq!(runs, 9, "three kinds of run at three angles of attack");

    let fitted = succeeded(&host_tools(&["fit", "--data", &data, "--out", &model]), "fit");
    assert!(Path::new(&model).join("model.bin").is_file() && Path::new(&model).join("model.md").is_file());
    let rows = heldout_rows(&fitted);
    assert_eq!(rows.iter().map(|row| row.0).collect::<Vec<_>>(), vec![0.0, 10.0, 20.0], "{fitted}");
    for (alpha_deg, fused_rms, coupling_ratio, noise_rms) in rows {
        // A fit that missed the wing errs by its whole moment (|C_l| up to 0.05), two orders
        // above the balance's noise; the fitted disturbance model is within twice that noise.
        assert!(fused_rms < 2.0 * noise_rms, "alpha {alpha_deg}: fused {fused_rms} vs noise {noise_rms}");
        assert!(coupling_ratio <= 1.0, "alpha {alpha_deg}: the operator made it worse ({coupling_ratio})");
    }

    succeeded(&host_tools(&["replay", "--data", &data, "--model", &model, "--out", &replay]), "replay");
    let estimates = std::fs::read_to_string(Path::new(&replay).join("runs/rollact_a20.csv")).expect("a replayed run");
    assert_eq!(estimates.lines().count(), 20_000 + 1, "every sample and the header");

    let diagnosed =
        succeeded(&host_tools(&["diagnose", "--real", &data, "--model", &model, "--report", &diagnosis]), "diagnose");
    assert!(diagnosed.starts_with("verdict: none"), "the recording the sim was fitted on: {diagnosed}");
    assert!(Path::new(&diagnosis).join("diagnosis.json").is_file());
}

#[test]
fn a_missing_dataset_is_refused_naming_its_path() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let missing = dir.path().join("no-such-campaign");
    let output = host_tools(&[
        "fit",
        "--data",
        &missing.display().to_string(),
        "--out",
        &dir.path().join("model").display().to_string(),
    ]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("no-such-campaign") && stderr.contains("manifest"), "{stderr}");
    assert!(!dir.path().join("model").exists(), "nothing is written");
}
