//! Replay of recorded channels through the estimator that flies: estimator-core's f32
//! [`Estimator`], stepped once per recorded sample, exactly as the firmware steps it.

use estimator_core::coeffs::N_TAPS;
use estimator_core::{CoefficientSet, Estimator, Input, Output};
use firmware_sim::campaign::mix_seed;
use firmware_sim::dataset::Run;
use firmware_sim::fault::{FaultSpec, apply_to_run};

/// The core's input at one recorded sample (f64 channels narrowed to f32; missing stays NaN).
#[must_use]
pub fn input_at(run: &Run, sample_idx: usize) -> Input {
    let channels = &run.channels;
    let narrow = |column: &[f64]| column.get(sample_idx).map_or(f32::NAN, |&value| value as f32);
    let cp: [f32; N_TAPS] = std::array::from_fn(|tap| narrow(&channels.cp[tap]));
    Input {
        phi_deg: narrow(&channels.phi_deg),
        alpha_deg: channels.alpha_at(sample_idx, run.meta.alpha_deg) as f32,
        cmu_port: narrow(&channels.cmu_port),
        cmu_stbd: narrow(&channels.cmu_stbd),
        cp,
    }
}

/// The controller's demand at one recorded sample: the recorded commands `cmu_port_cmd` and
/// `cmu_stbd_cmd` (f32), `None` when the run has neither. A run with one of them commands the
/// other jet 0.
#[must_use]
pub fn demand_at(run: &Run, sample_idx: usize) -> Option<[f32; 2]> {
    let channels = &run.channels;
    if channels.cmu_port_cmd.is_none() && channels.cmu_stbd_cmd.is_none() {
        return None;
    }
    let narrow = |column: &Option<Vec<f64>>| {
        column.as_ref().map_or(0.0, |column| column.get(sample_idx).map_or(f32::NAN, |&value| value as f32))
    };
    Some([narrow(&channels.cmu_port_cmd), narrow(&channels.cmu_stbd_cmd)])
}

/// One replay step at `sample_idx`: the estimator's step on the recorded input, then the recorded
/// demand noted as the controller's ([`Estimator::note_demand`]), as the firmware's loop does.
pub fn replay_step(estimator: &mut Estimator<'_>, run: &Run, sample_idx: usize) -> Output {
    let output = estimator.step(&input_at(run, sample_idx));
    if let Some(demand) = demand_at(run, sample_idx) {
        estimator.note_demand(demand);
    }
    output
}

/// Steps a fresh estimator over every sample of `run` ([`replay_step`]).
#[must_use]
pub fn replay_run(set: &CoefficientSet, run: &Run) -> Vec<Output> {
    let mut estimator = Estimator::new(set);
    (0..run.channels.len()).map(|sample_idx| replay_step(&mut estimator, run, sample_idx)).collect()
}

/// The marker file of a replay folder.
pub const REPLAY_MARKER: &str = "replay.toml";

/// The columns of a replay CSV: the recorded inputs the estimate depends on, the balance, every
/// stage's output and the health flags.
pub const REPLAY_COLUMNS: [&str; 20] = replay_columns();

/// The recorded columns a replay file repeats ([`recorded_at`]).
pub const RECORDED_COLUMNS: [&str; 6] = ["t_s", "phi_deg", "alpha_deg", "cmu_port", "cmu_stbd", "cl"];

/// The estimates' columns: [`Output::ESTIMATE_NAMES`], the estimate `cl` renamed `cl_est` so it
/// does not clash with the balance's `cl`.
pub const ESTIMATE_COLUMNS: [&str; 10] = estimate_columns();

/// The health columns ([`health_at`]).
pub const HEALTH_COLUMNS: [&str; 4] = ["health_flags", "cp_missing", "cp_rejected", "cp_isolated"];

/// The recorded values of sample `k` a replay file repeats, in the order of [`RECORDED_COLUMNS`]
/// (the angle of attack per sample: the column where finite, else the run's).
#[must_use]
pub fn recorded_at(run: &Run, k: usize) -> [f64; 6] {
    let channels = &run.channels;
    [
        channels.t_s[k],
        channels.phi_deg[k],
        channels.alpha_at(k, run.meta.alpha_deg),
        channels.cmu_port[k],
        channels.cmu_stbd[k],
        channels.cl[k],
    ]
}

/// The health fields of a step, in the order of [`HEALTH_COLUMNS`].
#[must_use]
pub const fn health_at(output: &Output) -> [u16; 4] {
    let health = output.health;
    [health.flags, health.cp_missing, health.cp_rejected, health.cp_isolated]
}

const fn estimate_columns() -> [&'static str; 10] {
    let mut columns = Output::ESTIMATE_NAMES;
    let mut idx = 0;
    while idx < columns.len() {
        let name = columns[idx].as_bytes();
        if name.len() == 2 && name[0] == b'c' && name[1] == b'l' {
            columns[idx] = "cl_est";
        }
        idx += 1;
    }
    columns
}

/// [`RECORDED_COLUMNS`], [`ESTIMATE_COLUMNS`], [`HEALTH_COLUMNS`].
const fn replay_columns() -> [&'static str; 20] {
    let mut columns = [""; 20];
    let mut idx = 0;
    while idx < RECORDED_COLUMNS.len() {
        columns[idx] = RECORDED_COLUMNS[idx];
        idx += 1;
    }
    let mut estimate = 0;
    while estimate < ESTIMATE_COLUMNS.len() {
        columns[idx] = ESTIMATE_COLUMNS[estimate];
        idx += 1;
        estimate += 1;
    }
    let mut health = 0;
    while health < HEALTH_COLUMNS.len() {
        columns[idx] = HEALTH_COLUMNS[health];
        idx += 1;
        health += 1;
    }
    columns
}

/// Why a replay could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// Writing the folder failed.
    #[error(transparent)]
    Folder(#[from] firmware_sim::atomic::FolderError),
    /// Writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// Replays every run of `dataset` and writes one CSV per run (same relative path as the run
/// file) into `dir`, with `replay.toml` naming the data and the model. Complete or absent.
pub fn write_replay(
    dir: &std::path::Path,
    dataset: &firmware_sim::dataset::Dataset,
    set: &CoefficientSet,
    source: &str,
) -> Result<usize, ReplayError> {
    write_replay_with_faults(dir, dataset, set, source, &[], 0)
}

/// [`write_replay`] with the sensor `faults` injected into every run (the random choices of
/// run `i` seeded by `mix_seed(seed, i)`); the replay files then hold the faulty inputs and
/// balance, and `replay.toml` lists the faults.
pub fn write_replay_with_faults(
    dir: &std::path::Path,
    dataset: &firmware_sim::dataset::Dataset,
    set: &CoefficientSet,
    source: &str,
    faults: &[FaultSpec],
    seed: u64,
) -> Result<usize, ReplayError> {
    use rayon::prelude::*;
    let tables: Vec<String> = dataset
        .runs
        .par_iter()
        .enumerate()
        .map(|(run_idx, run)| {
            if faults.is_empty() {
                return replay_csv(run, &replay_run(set, run));
            }
            let faulty = apply_to_run(run, faults, mix_seed(seed, run_idx as u64));
            replay_csv(&faulty, &replay_run(set, &faulty))
        })
        .collect();
    let mut manifest = format!("# Written by host-tools replay\nsource = {source:?}\ncolumns = {:?}\n", REPLAY_COLUMNS);
    if !faults.is_empty() {
        let names: Vec<String> = faults.iter().map(ToString::to_string).collect();
        manifest.push_str(&format!("faults = {names:?}\nfault_seed = {seed}\n"));
    }
    for run in &dataset.runs {
        manifest.push_str(&format!(
            "\n[[run]]\nfile = {:?}\nkind = {:?}\nalpha_deg = {}\n",
            run.meta.file.display().to_string(),
            run.meta.kind.as_str(),
            run.meta.alpha_deg
        ));
    }
    firmware_sim::atomic::write_folder::<ReplayError>(dir, REPLAY_MARKER, |tmp| {
        let io = |path: &std::path::Path| {
            let path = dir.join(path.strip_prefix(tmp).unwrap_or(path));
            move |source| ReplayError::Io { path, source }
        };
        std::fs::write(tmp.join(REPLAY_MARKER), &manifest).map_err(io(&tmp.join(REPLAY_MARKER)))?;
        for (run, table) in dataset.runs.iter().zip(&tables) {
            let path = tmp.join(&run.meta.file);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(io(parent))?;
            }
            std::fs::write(&path, table).map_err(io(&path))?;
        }
        Ok(())
    })?;
    Ok(dataset.runs.len())
}

/// One run's replay as CSV text.
fn replay_csv(run: &Run, outputs: &[Output]) -> String {
    use std::fmt::Write as _;
    let mut text = REPLAY_COLUMNS.join(",");
    text.push('\n');
    let number = |value: f64| if value.is_finite() { format!("{value}") } else { String::new() };
    for (k, output) in outputs.iter().enumerate() {
        let cells: Vec<String> = recorded_at(run, k)
            .into_iter()
            .map(number)
            .chain(output.estimates().into_iter().map(|value| number(f64::from(value))))
            .chain(health_at(output).map(|bits| bits.to_string()))
            .collect();
        let _ = writeln!(text, "{}", cells.join(","));
    }
    text
}
