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
#[ignore = "slow tier: ./ci.sh test runs it"]
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

/// Every `host-tools` command the README, the usage guide and the command line's contract
/// show, with the flags they show it with: the subcommand exists and its `--help` lists each
/// flag (a renamed flag or subcommand would leave the documents telling users a command that
/// fails).
#[test]
fn every_command_the_documents_show_exists_with_the_flags_they_show() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("host-tools sits in the workspace");
    let mut shown: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> = Default::default();
    for doc in ["README.md", "docs/usage.md", "docs/spec/cli.md"] {
        let text = std::fs::read_to_string(root.join(doc)).unwrap_or_else(|e| panic!("{doc}: {e}"));
        for line in text.lines() {
            for (idx, _) in line.match_indices("host-tools ") {
                // The command runs to the end of its code span or of the line.
                let rest = &line[idx + "host-tools ".len()..];
                let rest = rest.split(['`', '|']).next().unwrap_or_default();
                let mut words = rest.split_whitespace();
                let Some(sub) = words.next().map(|w| w.trim_end_matches(|c: char| !c.is_ascii_alphanumeric())) else {
                    continue;
                };
                if sub.is_empty() || !sub.chars().all(|c| c.is_ascii_lowercase() || c == '-') {
                    continue;
                }
                let flags = shown.entry(sub.to_owned()).or_default();
                for word in words {
                    let flag = word.trim_start_matches('[');
                    if let Some(name) = flag.strip_prefix("--") {
                        let name: String =
                            name.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
                        flags.insert(format!("--{name}"));
                    }
                }
            }
        }
    }
    assert!(shown.len() >= 10, "the documents show too few commands: {shown:?}");
    for (sub, flags) in &shown {
        let help = succeeded(&host_tools(&[sub, "--help"]), &format!("host-tools {sub} --help"));
        for flag in flags {
            assert!(
                help.contains(flag.as_str()),
                "host-tools {sub}: the documents show {flag}, its help has no such flag"
            );
        }
    }
}
