//! The model folder `fit` writes: `model.bin` (the coefficient blob), `model.json` (the fit
//! report and the tables), `model.md` (the model card: equations with their coefficients like
//! the paper's eqs. 6, 7 and 12, fit metrics, the lambda sweeps as SVG plots).

use std::fmt::Write as _;
use std::path::Path;

use estimator_core::CoefficientSet;
use serde::Serialize;

use super::pipeline::{FitOutcome, FitReport};
use super::sparse_fit::SparseFit;
use crate::model::{BLOB_FILE, ModelError};
use reports::plot::{Axes, Series, svg};

/// What `model.json` holds.
#[derive(Debug, Serialize)]
struct ModelJson<'a> {
    /// Where the data came from.
    dataset: &'a str,
    /// The fit's numbers.
    report: &'a FitReport,
    /// The tables, as the core holds them (its serde form, the one the blob's postcard
    /// payload carries, field by field).
    coefficients: &'a CoefficientSet,
}

/// Writes the model folder `dir` completely or not at all, with `companions` (name, bytes):
/// further files the caller made from the fit, such as the model's diagnosis signature on its
/// own held-out data, that must land in the same folder or not at all.
pub fn write_model_folder(
    dir: &Path,
    outcome: &FitOutcome,
    dataset: &str,
    companions: &[(&str, Vec<u8>)],
) -> Result<(), ModelError> {
    let files = model_files(outcome, dataset, companions)
        .map_err(|error| ModelError::ToBlob { path: dir.join(BLOB_FILE), error })?;
    write_model_files(dir, &files)
}

/// Writes a model folder's `files` (name, bytes) into `dir`, completely or not at all (an
/// existing model folder is replaced only once the new one is whole).
pub fn write_model_files(dir: &Path, files: &[(String, Vec<u8>)]) -> Result<(), ModelError> {
    firmware_sim::atomic::write_folder(dir, BLOB_FILE, |tmp| {
        for (name, bytes) in files {
            std::fs::write(tmp.join(name), bytes).map_err(|source| ModelError::Io { path: dir.join(name), source })?;
        }
        Ok(())
    })
}

/// The files of a model folder (name, bytes), in the order they are written: the blob,
/// `model.json`, the card, the `companions`, the sweep plots. What [`write_model_folder`]
/// writes, held in memory by a caller that may never write it (a notebook's fit).
///
/// # Errors
/// The blob's encoding error.
pub fn model_files(
    outcome: &FitOutcome,
    dataset: &str,
    companions: &[(&str, Vec<u8>)],
) -> Result<Vec<(String, Vec<u8>)>, crate::model::ToBlobError> {
    let blob = crate::model::encode(&outcome.set)?;
    let json = ModelJson { dataset, report: &outcome.report, coefficients: &outcome.set };
    let json = serde_json::to_string_pretty(&json).unwrap_or_else(|error| format!("{{\"error\": \"{error}\"}}"));
    let card = model_card(&outcome.set, &outcome.report, dataset);
    let mut files = vec![
        (BLOB_FILE.to_owned(), blob),
        ("model.json".to_owned(), json.into_bytes()),
        ("model.md".to_owned(), card.into_bytes()),
    ];
    files.extend(companions.iter().map(|(name, bytes)| ((*name).to_owned(), bytes.clone())));
    files.extend(sweep_plots(&outcome.report).into_iter().map(|(name, plot)| (name, plot.into_bytes())));
    Ok(files)
}

/// The sweep plots: held-out error against the number of terms, selected model marked.
fn sweep_plots(report: &FitReport) -> Vec<(String, String)> {
    let mut plots = Vec::new();
    for (side, name) in [(0usize, "port"), (1, "starboard")] {
        if let Some(fit) = &report.plant[side] {
            let error = |row: &super::sparse_fit::SweepRow| row.validation_free_run_rms.unwrap_or(f64::NAN);
            plots.push((
                format!("plant_{name}_sweep.svg"),
                sweep_svg(&format!("plant ({name} jet): lambda sweep"), fit, "held-out free-run RMS of C_l", &error),
            ));
        }
    }
    if let Some(fit) = &report.coupling {
        let error = |row: &super::sparse_fit::SweepRow| row.validation_one_step_rms;
        plots.push((
            "coupling_sweep.svg".into(),
            sweep_svg("coupling operator: lambda sweep", fit, "held-out RMS of the correction error", &error),
        ));
    }
    plots
}

fn sweep_svg(
    title: &str,
    fit: &SparseFit,
    y_label: &str,
    error: &dyn Fn(&super::sparse_fit::SweepRow) -> f64,
) -> String {
    let point = |row: &super::sparse_fit::SweepRow| (row.n_terms as f64, error(row));
    let all: Vec<(f64, f64)> = fit.sweep.iter().map(point).collect();
    let pareto: Vec<(f64, f64)> = fit.sweep.iter().filter(|row| row.pareto).map(point).collect();
    let selected: Vec<(f64, f64)> = fit.selected_row().map(point).into_iter().collect();
    let axes = Axes { title: title.into(), x_label: "number of terms".into(), y_label: y_label.into(), log_y: true };
    svg(
        &axes,
        &[
            Series { name: "sweep models".into(), points: all, line: false },
            Series { name: "Pareto front (held-out one-step)".into(), points: pareto, line: false },
            Series { name: "selected".into(), points: selected, line: false },
        ],
    )
}

/// The model card in Markdown.
#[must_use]
pub fn model_card(set: &CoefficientSet, report: &FitReport, dataset: &str) -> String {
    let mut md = String::new();
    let _ = writeln!(md, "# Model card\n\nFitted on `{dataset}` ({}); step {} s.\n", report.split, report.dt_s);
    egk_section(&mut md, report);
    pressure_section(&mut md, report);
    let fusion = &report.fusion;
    let _ = writeln!(
        md,
        "## Fusion\n\n`C_l,roll = C_l,eGK + e`, `e[k] = rho e[k-1] + w` observed as `C_l,p - C_l,eGK`: correlation time {:.3} s (rho = {:.6}), gain {:.3e}. Training RMS: eGK {:.3e}, pressure path {:.3e}, fused {:.3e}.\n",
        fusion.correlation_time_s, fusion.rho, fusion.gain, fusion.rms_egk, fusion.rms_pressure, fusion.rms_fused
    );
    for (side, name) in [(0usize, "port"), (1, "starboard")] {
        let _ = writeln!(md, "## Plant, {name} jet (paper eq. 5)\n");
        let pole = f64::from(set.plant[side].slow_pole);
        if pole > 0.0 {
            let _ = writeln!(
                md,
                "Slow state `C_l,slow[k+1] = p C_l,slow[k] + (1 - p) C_l,AFC[k]`: p = {pole:.6}, time constant {:.3} s (profiled over {:?} s).\n",
                -report.dt_s / pole.ln(),
                super::plant::SLOW_TAU_GRID_S
            );
        } else {
            let _ = writeln!(md, "No slow state selected: the paper's first-order form.\n");
        }
        match &report.plant[side] {
            Some(fit) => sparse_section(&mut md, "C_l,AFC[k+1]", fit, &format!("plant_{name}_sweep.svg")),
            None => {
                let _ = writeln!(md, "Mirrored from the other jet ({} terms).\n", set.plant[side].model.n_terms);
            }
        }
    }
    let _ = writeln!(md, "## Coupling operator (paper eqs. 9-12)\n");
    match &report.coupling {
        Some(fit) => sparse_section(&mut md, "C_l - C_l,roll - C_l,AFC", fit, "coupling_sweep.svg"),
        None => {
            let _ = writeln!(md, "Zero (no roll+actuation runs).\n");
        }
    }
    let _ = writeln!(
        md,
        "Indicator thresholds: `[cmu]` = |Cmu| > {:.3e}, `[phi]` = |phi| > {:.3e} rad.\n",
        report.coupling_gates[0], report.coupling_gates[1]
    );
    actuator_section(&mut md, report);
    envelope_section(&mut md, report);
    heldout_section(&mut md, report);
    for note in &report.notes {
        let _ = writeln!(md, "- Note: {note}");
    }
    let timing: Vec<String> = report.timing_s.iter().map(|(stage, s)| format!("{stage} {s:.2} s")).collect();
    let _ = writeln!(md, "\nTime: {}.", timing.join(", "));
    md
}

/// The jets' actuator responses: what the plant runs on while the blowing
/// measurement is missing.
fn actuator_section(md: &mut String, report: &FitReport) {
    let _ = writeln!(
        md,
        "## Actuator response (demand to Cmu)\n\nWhile a jet's measured Cmu is missing, the core predicts it from the controller's demands: `Cmu[k] = p Cmu[k-1] + (1 - p) g cmd[k - 1 - d]`. Dead time by one-step least squares over 0 to {} steps, pole and gain for the free run; on the training part of the runs that command the jet.\n\n| jet | source | dead time d (steps) | pole p | time constant (s) | gain g | samples | RMS Cmu | RMS one-step | RMS free run | RMS free run, identity |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        estimator_core::coeffs::DEMAND_SLOTS - 1
    );
    let figure = |value: Option<f64>| value.map_or_else(|| "-".to_owned(), |value| format!("{value:.3e}"));
    for (fit, name) in report.actuator.iter().zip(["port", "starboard"]) {
        let tau_s = if fit.pole > 0.0 { format!("{:.4}", -report.dt_s / fit.pole.ln()) } else { "0".to_owned() };
        let source = match fit.source {
            super::actuator::ResponseSource::Fitted => "fitted",
            super::actuator::ResponseSource::Mirrored => "the other jet's",
            super::actuator::ResponseSource::Identity => "identity (no command columns)",
        };
        let _ = writeln!(
            md,
            "| {name} | {source} | {} | {:.6} | {tau_s} | {:.4} | {} | {:.3e} | {} | {} | {} |",
            fit.delay_steps,
            fit.pole,
            fit.gain,
            fit.n_samples,
            fit.rms_cmu,
            figure(fit.rms_one_step),
            figure(fit.rms_free_run),
            figure(fit.rms_identity)
        );
    }
    md.push('\n');
}

/// The estimate envelope: the range the core keeps its estimates within.
fn envelope_section(md: &mut String, report: &FitReport) {
    let envelope = &report.envelope;
    let _ = writeln!(
        md,
        "## Estimate envelope\n\nThe balance's range over the training part; the core keeps its estimates within it widened by {} of its span on each side (`estimator_core::coeffs::ENVELOPE_MARGIN`), and flags every step it limits.\n\n| estimate | measured range | bounds applied |\n| --- | --- | --- |\n| `C_l,roll` (roll runs) | [{:.4e}, {:.4e}] | [{:.4e}, {:.4e}] |\n| `C_l,linear`, `C_l` (every run) | [{:.4e}, {:.4e}] | [{:.4e}, {:.4e}] |\n",
        envelope.margin,
        envelope.cl_roll[0],
        envelope.cl_roll[1],
        envelope.cl_roll_bounds[0],
        envelope.cl_roll_bounds[1],
        envelope.cl[0],
        envelope.cl[1],
        envelope.cl_bounds[0],
        envelope.cl_bounds[1]
    );
}

fn egk_section(md: &mut String, report: &FitReport) {
    let _ = writeln!(
        md,
        "## Disturbance model: extended Goman-Khrabrov\n\n`tau1 x' + x = x0(a - tau2 a')`, `x0(a) = (1 - tanh(k (a - a*))) / 2` per half-wing at `a = atan(tan alpha cos phi) -+ kb asin(sin alpha sin phi)`; `C_l = C_l,beta beta + C_l,p p_hat + C_l,pdot p_hat_dot + C_l,p|p| p_hat |p_hat| + K_v (x_L - x_R) + C_l,0`.\n\n| alpha (deg) | tau1 (s) | tau2 (s) | a* (deg) | k (1/deg) | kb | C_l,beta | C_l,p | C_l,pdot | C_l,p\\|p\\| | K_v | C_l,0 | train RMS prior | train RMS fit |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    for egk in &report.egk {
        let p = &egk.params;
        let _ = writeln!(
            md,
            "| {} | {:.4} | {:.4} | {:.2} | {:.3} | {:.3} | {:.4} | {:.4} | {:.4} | {:.3} | {:.4} | {:.2e} | {:.3e} | {:.3e} |",
            egk.alpha_deg,
            p[0],
            p[1],
            p[2],
            p[3],
            p[4],
            p[5],
            p[6],
            p[7],
            p[8],
            p[9],
            p[10],
            egk.rms_prior,
            egk.rms_fit
        );
    }
    let _ = writeln!(md);
}

fn pressure_section(md: &mut String, report: &FitReport) {
    let p = &report.pressure;
    let _ = writeln!(
        md,
        "## Disturbance model: time-shifted pressure model and Kalman filter\n\nRank {} of {} ({:.4} of the energy), spectral radius {:.5}{}; steady-state gain from the DARE ({} iterations, residual {:.1e}). Training RMS: Cp one-step prediction {:.3e}, filtered Cp {:.3e}; map to C_l {:.3e} (C_l standard deviation {:.3e}). The innovation gate is armed {} steps after the start, once the filter has settled from the mean pressures.\n",
        p.rank,
        p.data_rank,
        p.energy_kept,
        p.spectral_radius,
        if p.stabilised { " (stabilised)" } else { "" },
        p.dare_iterations,
        p.dare_residual,
        p.cp_prediction_rms,
        p.cp_filtered_rms,
        p.cl_rms,
        p.cl_std,
        p.settle_steps
    );
    if !p.dead_taps.is_empty() {
        let names: Vec<String> = p.dead_taps.iter().map(|tap| format!("cp{tap:02}")).collect();
        let _ = writeln!(
            md,
            "Taps without data in at least half of the training samples, fitted as absent (zero row of C, zero column of K): {}.\n",
            names.join(", ")
        );
    }
}

fn sparse_section(md: &mut String, lhs: &str, fit: &SparseFit, plot: &str) {
    let rhs: Vec<String> = fit.terms.iter().map(|(name, c)| format!("{c:+.6e} {name}")).collect();
    let _ = writeln!(md, "`{lhs} = {}`\n", if rhs.is_empty() { "0".to_owned() } else { rhs.join(" ") });
    if let Some(row) = fit.selected_row() {
        let free_run = row.validation_free_run_rms.map_or(String::new(), |fr| format!(", free run {fr:.3e}"));
        let _ = writeln!(
            md,
            "{} terms selected from {} distinct sweep models by BIC with {} effective validation samples (the end of the training part); validation RMS: one step {:.3e}{free_run}; refitted on {} training samples.\n\n![sweep]({plot})\n",
            row.n_terms,
            fit.sweep.len(),
            row.validation_effective_samples,
            row.validation_one_step_rms,
            fit.n_train
        );
    }
}

fn heldout_section(md: &mut String, report: &FitReport) {
    use super::heldout::HeldoutAlpha;
    let _ = writeln!(
        md,
        "## Held-out errors (replay through the fitted core)\n\n| {} |\n|{}",
        HeldoutAlpha::COLUMNS.join(" | "),
        " --- |".repeat(HeldoutAlpha::COLUMNS.len())
    );
    for row in &report.heldout.per_alpha {
        let _ = writeln!(md, "| {} |", row.cells().join(" | "));
    }
    let _ = writeln!(md);
}
