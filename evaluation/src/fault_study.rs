//! The fault study (`host-tools faults`): every sensor fault of [`firmware_sim::fault`] injected
//! at the start of the held-out part of every run (the split of `fit` and `evaluate`), on every
//! pressure channel for the pressure faults. Per fault type it measures how fast the estimator
//! flags the faulty channel (goal: within 50 ms) and the held-out RMS error of the full estimate
//! `C_l` against the balance, relative to the fault-free replay (goal: at most 1.5 times).
//!
//! The estimator notes the run's recorded commands as the controller's demand after every step
//! (`model_fit::replay::replay_step`), as the firmware's loop notes its controller's: with the
//! blowing measurement missing, the plant runs on the Cmu the fitted actuator response predicts.
//!
//! The estimator is stepped over the run's training part once, fault-free, and its state cloned
//! at the split: every fault case continues from that state, so the cases differ only by the
//! fault (and the study costs one held-out replay per case).

use estimator_core::coeffs::N_TAPS;
use estimator_core::{CoefficientSet, Estimator, Output};
use firmware_sim::campaign::mix_seed;
use firmware_sim::dataset::{Dataset, Run};
use firmware_sim::fault::{FaultKind, FaultSpec, apply_to_run};
use rayon::prelude::*;
use serde::Serialize;

use model_fit::fit::split::Split;
use model_fit::replay::replay_step;

/// Goal: a faulty pressure channel is flagged within this time of its fault, ms.
pub const DETECTION_GOAL_MS: f64 = 50.0;
/// Goal: the held-out RMS error with one fault, relative to the fault-free one.
pub const RMS_RATIO_GOAL: f64 = 1.5;

/// The faults the study injects and their sizes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StudyConfig {
    /// The training/held-out split; faults start at the first held-out sample.
    #[serde(skip)]
    pub split: Split,
    /// Offset of a biased channel, Cp.
    pub bias_cp: f64,
    /// Height of a spike, Cp.
    pub spike_cp: f64,
    /// Share of dropped balance and roll-encoder samples.
    pub drop_fraction: f64,
    /// Seed of the faults' random choices (run `i` uses `mix_seed(seed, i)`).
    pub seed: u64,
}

/// One fault type's results over every run (and every channel for pressure faults).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultTypeResult {
    /// The fault as a spec, `cpNN` standing for every channel.
    pub fault: String,
    /// Pressure faults: (channel, run) pairs in which the channel was flagged after the onset.
    pub flagged: Option<usize>,
    /// Pressure faults: (channel, run) pairs tried.
    pub cases: usize,
    /// Largest time from the onset to the first flag of the faulty channel, ms (pressure faults
    /// that were flagged in every case).
    pub worst_latency_ms: Option<f64>,
    /// Median of those times, ms.
    pub median_latency_ms: Option<f64>,
    /// Worst (over channels) held-out RMS error of `C_l` with the fault / without.
    pub worst_rms_ratio: f64,
    /// The same for the pressure path's `C_l,roll,p` alone (how much the fault hurt before
    /// fusion).
    pub worst_pressure_rms_ratio: f64,
    /// Both goals met (flag within [`DETECTION_GOAL_MS`] where a channel is faulty, RMS ratio
    /// within [`RMS_RATIO_GOAL`]).
    pub meets_goals: bool,
}

/// The whole study.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultStudy {
    /// The sizes of the faults.
    pub config: StudyConfig,
    /// Fault-free held-out RMS error of `C_l` against the balance, pooled over every run.
    pub clean_rms: f64,
    /// Fault-free held-out RMS error of the pressure path's `C_l,roll,p`.
    pub clean_pressure_rms: f64,
    /// One row per fault type.
    pub rows: Vec<FaultTypeResult>,
}

/// Why the study could not run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StudyError {
    /// No run has held-out samples.
    #[error("no run has held-out samples to inject faults into")]
    NoHeldout,
}

/// A run's held-out part, ready for fault cases.
struct Prepared<'a> {
    run: &'a Run,
    run_idx: usize,
    /// The estimator's state at the split, after a fault-free training part.
    warm: Estimator<'a>,
    /// First held-out sample.
    onset_idx: usize,
    onset_s: f64,
}

/// Sums of one replay of the held-out part.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    sum_sq: f64,
    sum_sq_pressure: f64,
    n: usize,
    /// Samples from the onset to the first flag of the watched channel.
    latency_samples: Option<usize>,
}

/// Runs the study on `dataset` with the tables `set`.
///
/// # Errors
/// [`StudyError::NoHeldout`] when the split leaves no held-out sample.
pub fn fault_study(dataset: &Dataset, set: &CoefficientSet, config: &StudyConfig) -> Result<FaultStudy, StudyError> {
    let prepared: Vec<Prepared<'_>> =
        dataset.runs.par_iter().enumerate().filter_map(|(run_idx, run)| prepare(set, run, run_idx, config)).collect();
    if prepared.is_empty() {
        return Err(StudyError::NoHeldout);
    }
    let clean = pool(prepared.par_iter().map(|p| replay_heldout(p, p.run, None)).collect());
    let rows = fault_types(config)
        .par_iter()
        .map(|(label, make)| study_type(&prepared, config, label, make.as_ref(), &clean))
        .collect();
    Ok(FaultStudy { config: *config, clean_rms: clean.rms(), clean_pressure_rms: clean.pressure_rms(), rows })
}

/// A fault type: its label and the spec on a channel (ignored by non-pressure faults) at an
/// onset.
type MakeSpec = Box<dyn Fn(usize, f64) -> FaultSpec + Sync + Send>;

fn fault_types(config: &StudyConfig) -> Vec<(String, MakeSpec)> {
    let (bias, spike, drop) = (config.bias_cp, config.spike_cp, config.drop_fraction);
    let spec = |kind: FaultKind, start_s: f64| FaultSpec { kind, start_s };
    vec![
        ("stuck:cpNN".into(), Box::new(move |tap, t| spec(FaultKind::Stuck { tap }, t)) as MakeSpec),
        ("dead:cpNN".into(), Box::new(move |tap, t| spec(FaultKind::Dead { tap }, t))),
        (format!("bias:cpNN={bias}"), Box::new(move |tap, t| spec(FaultKind::Bias { tap, offset: bias }, t))),
        (format!("spike:cpNN={spike}"), Box::new(move |tap, t| spec(FaultKind::Spike { tap, amplitude: spike }, t))),
        (format!("drop:cl={drop}"), Box::new(move |_, t| spec(FaultKind::DropBalance { fraction: drop }, t))),
        (format!("drop:phi={drop}"), Box::new(move |_, t| spec(FaultKind::DropRoll { fraction: drop }, t))),
        ("missing:cmu".into(), Box::new(move |_, t| spec(FaultKind::MissingCmu, t))),
    ]
}

/// One fault type on every channel (pressure faults) or once, over every run.
fn study_type(
    prepared: &[Prepared<'_>],
    config: &StudyConfig,
    label: &str,
    make: &(dyn Fn(usize, f64) -> FaultSpec + Sync + Send),
    clean: &Sums,
) -> FaultTypeResult {
    let is_pressure = make(0, 0.0).tap().is_some();
    let taps: Vec<usize> = if is_pressure { (0..N_TAPS).collect() } else { vec![0] };
    let (mut worst_ratio, mut worst_pressure_ratio) = (0.0f64, 0.0f64);
    let mut latencies_ms = Vec::new();
    for &tap in &taps {
        let per_run: Vec<Sums> = prepared
            .par_iter()
            .map(|p| {
                let spec = make(tap, p.onset_s);
                let faulty = apply_to_run(p.run, &[spec], mix_seed(config.seed, p.run_idx as u64));
                replay_heldout(p, &faulty, spec.tap())
            })
            .collect();
        let dt_ms = prepared.first().map_or(1.0, |p| 1e3 / p.run.meta.sample_hz);
        latencies_ms.extend(per_run.iter().filter_map(|sums| sums.latency_samples).map(|n| n as f64 * dt_ms));
        let pooled = pool(per_run);
        worst_ratio = worst_ratio.max(pooled.rms() / clean.rms());
        worst_pressure_ratio = worst_pressure_ratio.max(pooled.pressure_rms() / clean.pressure_rms());
    }
    let cases = taps.len() * prepared.len();
    latencies_ms.sort_by(f64::total_cmp);
    let all_flagged = latencies_ms.len() == cases;
    let worst_latency_ms = (is_pressure && all_flagged).then(|| latencies_ms.last().copied().unwrap_or(0.0));
    let median_latency_ms = (is_pressure && all_flagged).then(|| latencies_ms[latencies_ms.len() / 2]);
    let detected = !is_pressure || worst_latency_ms.is_some_and(|worst| worst <= DETECTION_GOAL_MS);
    FaultTypeResult {
        fault: label.to_owned(),
        flagged: is_pressure.then_some(latencies_ms.len()),
        cases,
        worst_latency_ms,
        median_latency_ms,
        worst_rms_ratio: worst_ratio,
        worst_pressure_rms_ratio: worst_pressure_ratio,
        meets_goals: detected && worst_ratio <= RMS_RATIO_GOAL,
    }
}

/// Steps a fresh estimator over the training part of `run`; `None` without held-out samples.
fn prepare<'a>(set: &'a CoefficientSet, run: &'a Run, run_idx: usize, config: &StudyConfig) -> Option<Prepared<'a>> {
    let heldout = config.split.heldout(run.channels.len());
    if heldout.is_empty() {
        return None;
    }
    let mut warm = Estimator::new(set);
    for sample_idx in 0..heldout.start {
        let _ = replay_step(&mut warm, run, sample_idx);
    }
    let onset_s = run.channels.t_s[heldout.start];
    Some(Prepared { run, run_idx, warm, onset_idx: heldout.start, onset_s })
}

/// Replays the held-out part of `faulty` (the prepared run with faults applied) from the warm
/// state; `watched` is the faulty pressure channel whose first flag is timed.
fn replay_heldout(prepared: &Prepared<'_>, faulty: &Run, watched: Option<usize>) -> Sums {
    let mut estimator = prepared.warm.clone();
    let mut sums = Sums::default();
    for sample_idx in prepared.onset_idx..faulty.channels.len() {
        let output = replay_step(&mut estimator, faulty, sample_idx);
        if let Some(tap) = watched
            && sums.latency_samples.is_none()
            && flagged(&output, tap)
        {
            sums.latency_samples = Some(sample_idx - prepared.onset_idx);
        }
        // The truth is the fault-free balance (a dropped balance sample is a fault of the
        // measurement, not of the estimate).
        let truth = prepared.run.channels.cl[sample_idx];
        if truth.is_finite() {
            sums.sum_sq += (f64::from(output.cl) - truth).powi(2);
            sums.sum_sq_pressure += (f64::from(output.cl_pressure) - truth).powi(2);
            sums.n += 1;
        }
    }
    sums
}

/// True when the step's health marks channel `tap` as missing, rejected or isolated.
fn flagged(output: &Output, tap: usize) -> bool {
    output.health.channel_faulty(tap) || (output.health.cp_missing >> tap) & 1 != 0
}

fn pool(per_run: Vec<Sums>) -> Sums {
    per_run.into_iter().fold(Sums::default(), |acc, sums| Sums {
        sum_sq: acc.sum_sq + sums.sum_sq,
        sum_sq_pressure: acc.sum_sq_pressure + sums.sum_sq_pressure,
        n: acc.n + sums.n,
        latency_samples: None,
    })
}

impl Sums {
    fn rms(&self) -> f64 {
        (self.sum_sq / self.n.max(1) as f64).sqrt()
    }

    fn pressure_rms(&self) -> f64 {
        (self.sum_sq_pressure / self.n.max(1) as f64).sqrt()
    }
}

impl Default for StudyConfig {
    fn default() -> Self {
        Self { split: Split::default(), bias_cp: 0.3, spike_cp: 2.0, drop_fraction: 0.2, seed: 1 }
    }
}

/// Column headers of [`table_rows`].
pub const COLUMNS: [&str; 6] = [
    "fault",
    "flagged (channel x run)",
    "latency worst / median, ms",
    "RMS ratio C_l",
    "RMS ratio pressure path",
    "goals met",
];

/// The study as table rows (see [`COLUMNS`]).
#[must_use]
pub fn table_rows(study: &FaultStudy) -> Vec<Vec<String>> {
    study
        .rows
        .iter()
        .map(|row| {
            let latency = match (row.worst_latency_ms, row.median_latency_ms) {
                (Some(worst), Some(median)) => format!("{worst:.0} / {median:.0}"),
                _ if row.flagged.is_some() => "not always flagged".to_owned(),
                _ => "-".to_owned(),
            };
            vec![
                row.fault.clone(),
                row.flagged.map_or_else(|| "-".to_owned(), |flagged| format!("{flagged} / {}", row.cases)),
                latency,
                format!("{:.3}", row.worst_rms_ratio),
                format!("{:.3}", row.worst_pressure_rms_ratio),
                if row.meets_goals { "yes" } else { "no" }.to_owned(),
            ]
        })
        .collect()
}

/// The study as a report (Markdown and HTML through [`reports`]).
#[must_use]
pub fn study_report(study: &FaultStudy, described: &str) -> reports::Report {
    use reports::{Report, Section, Table};
    let intro = vec![
        format!("{described}. {}.", study.config.split.describe()),
        format!(
            "Each fault starts at the first held-out sample of every run; pressure faults are tried on every \
             channel. Goals: the faulty channel flagged (missing, rejected or isolated) within {DETECTION_GOAL_MS} ms, \
             and the held-out RMS error of `C_l` against the balance at most {RMS_RATIO_GOAL} times the fault-free \
             one. Worst values over channels and runs."
        ),
        format!(
            "Fault-free held-out RMS error: `C_l` {:.3e}, pressure path {:.3e}.",
            study.clean_rms, study.clean_pressure_rms
        ),
    ];
    let table = Table {
        caption: "Per fault type".into(),
        header: COLUMNS.iter().map(|&column| column.to_owned()).collect(),
        rows: table_rows(study),
    };
    Report {
        title: "Sensor faults on held-out data".into(),
        intro,
        sections: vec![Section { heading: "Detection and error".into(), tables: vec![table], ..Section::default() }],
    }
}
