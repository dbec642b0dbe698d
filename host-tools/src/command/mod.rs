//! Every subcommand of `host-tools` as a library function: it takes the command's arguments
//! (the same `clap` structs the command line parses, so there is one definition of each flag)
//! and a [`Progress`], does the work, and returns a typed summary whose `Display` is what the
//! command prints. The binary only parses and dispatches (`src/bin/host-tools/main.rs`); the
//! integration tests call these functions directly (`tests/tests/command.rs`).
//!
//! The layout follows ripgrep's split of a thin `main.rs` from its flags and its search
//! functions (`crates/core/main.rs`, `crates/core/flags/`).

pub mod closed_loop;
pub mod data;
pub mod diagnosis;
#[cfg(feature = "rigs")]
pub mod firmware;
pub mod model;
pub mod reliability;

use std::path::{Path, PathBuf};

use ::diagnosis::diagnose::{DiagnoseError, SignatureFileError};
use ::diagnosis::validate::external::ExternalError;
use evaluation::analysis::superposition::SuperpositionError;
use evaluation::fault_study::StudyError;
use firmware_sim::campaign::ScenarioError;
use firmware_sim::dataset::DatasetError;
#[cfg(feature = "rigs")]
use firmware_sim::dataset::{Dataset, Run};
use firmware_sim::sil::SilError;
use model_fit::codegen::CodegenError;
use model_fit::fit::FitError;
use model_fit::model::ModelError;
use model_fit::replay::ReplayError;

/// Where a long command reports how far it is (a progress bar on the command line, nothing in
/// tests). Called from worker threads, hence `Sync`.
pub trait Progress: Sync {
    /// A new stage of the command, with its number of steps when they are counted.
    fn stage(&self, message: &str, steps: Option<u64>);
    /// One step of the present stage done.
    fn step(&self);
}

/// A [`Progress`] that shows nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {
    fn stage(&self, _message: &str, _steps: Option<u64>) {}
    fn step(&self) {}
}

/// Why a command failed; each variant names the file, flag or run it failed on.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// A flag's value is outside its range.
    #[error("{flag} {expected}")]
    Flag {
        /// The flag, as written on the command line.
        flag: &'static str,
        /// What was expected and what was found.
        expected: String,
    },
    /// A dataset could not be read or written.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// A scenario file or `--effect` is invalid, or the tunnel failed.
    #[error(transparent)]
    Scenario(#[from] ScenarioError),
    /// A model could not be loaded or written.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The fit of a dataset failed.
    #[error("fitting {}", data.display())]
    Fit {
        /// The dataset.
        data: PathBuf,
        /// Why.
        #[source]
        source: FitError,
    },
    /// The evaluation of a dataset failed.
    #[error("evaluating {}", data.display())]
    Evaluate {
        /// The dataset.
        data: PathBuf,
        /// Why.
        #[source]
        source: FitError,
    },
    /// The superposition table could not be formed.
    #[error(transparent)]
    Superposition(#[from] SuperpositionError),
    /// The generated tables could not be written or are stale.
    #[error(transparent)]
    Codegen(#[from] CodegenError),
    /// A replay could not be written.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// The diagnosis failed.
    #[error(transparent)]
    Diagnose(#[from] DiagnoseError),
    /// A model's diagnosis signature is unreadable.
    #[error(transparent)]
    Signature(#[from] SignatureFileError),
    /// A campaign written by another program could not be run.
    #[error(transparent)]
    Campaign(#[from] ExternalError),
    /// The sensor-fault study failed.
    #[error(transparent)]
    Study(#[from] StudyError),
    /// The closed loop failed.
    #[error(transparent)]
    Sil(#[from] SilError),
    /// A run named on the command line is not in the dataset.
    #[error("no run {} in {}", run.display(), data.display())]
    NoRun {
        /// The run's file, as named.
        run: PathBuf,
        /// The dataset.
        data: PathBuf,
    },
    /// An output folder could not be replaced (nothing is left half-written).
    #[error(transparent)]
    Folder(#[from] firmware_sim::atomic::FolderError),
    /// A report or output folder could not be written (nothing is left half-written).
    #[error("writing {}", path.display())]
    Write {
        /// The folder or file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The firmware could not be built or run in QEMU.
    #[error("{what}")]
    Firmware {
        /// What was being done.
        what: String,
        /// Why.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl CommandError {
    /// A write error for `path`.
    pub fn write(path: &Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        move |source| Self::Write { path: path.to_path_buf(), source }
    }

    /// A firmware error while doing `what`.
    #[cfg(feature = "rigs")]
    fn firmware(what: impl Into<String>) -> impl FnOnce(anyhow::Error) -> Self {
        let what = what.into();
        move |error| Self::Firmware { what, source: error.into() }
    }
}

/// Checks a `--holdout-fraction`: in `[0, 1)`.
pub fn holdout_split(holdout_fraction: f64) -> Result<model_fit::fit::split::Split, CommandError> {
    if !(0.0..1.0).contains(&holdout_fraction) {
        return Err(CommandError::Flag {
            flag: "--holdout-fraction",
            expected: format!("must be in [0, 1), found {holdout_fraction}"),
        });
    }
    Ok(model_fit::fit::split::Split::with_holdout(holdout_fraction))
}

/// The run of `dataset` whose file is `file` (the rigs' subcommands fly one).
#[cfg(feature = "rigs")]
fn run_named<'a>(dataset: &'a Dataset, file: &Path, data: &Path) -> Result<&'a Run, CommandError> {
    dataset
        .runs
        .iter()
        .find(|run| run.meta.file == file)
        .ok_or_else(|| CommandError::NoRun { run: file.to_path_buf(), data: data.to_path_buf() })
}
