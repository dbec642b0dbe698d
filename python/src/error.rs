//! Rust errors as Python exceptions: a [`DatasetError`] carries the file, row, column and
//! manifest key the loader named, so a notebook can point at the bad cell without parsing text.

use std::path::PathBuf;

use firmware_sim::dataset::DatasetError as LoadError;
use host_tools::command::CommandError;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

pyo3::create_exception!(
    rollest._rollest,
    RollestError,
    PyException,
    "A rollest call failed; the message names the file, flag or run, and why."
);
pyo3::create_exception!(
    rollest._rollest,
    DatasetError,
    RollestError,
    "A dataset could not be read or written. Attributes: `file` (path or None), `row` (1-based, \
     header = row 1, or None), `column` (or None), `key` (manifest key such as `run[2].sample_hz`, \
     or None)."
);

/// The message of an error with its chain of causes (`a: b: c`).
fn chained(error: &dyn std::error::Error) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let text = cause.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        source = cause.source();
    }
    message
}

/// Where a dataset error points: file, row, column, key.
#[derive(Debug, Default)]
struct Location {
    file: Option<PathBuf>,
    row: Option<u64>,
    column: Option<String>,
    key: Option<String>,
}

fn locate(error: &LoadError) -> Location {
    let at = |file: &PathBuf| Location { file: Some(file.clone()), ..Location::default() };
    let header = |file: &PathBuf, column: &str| Location {
        file: Some(file.clone()),
        row: Some(1),
        column: Some(column.to_owned()),
        key: None,
    };
    let keyed =
        |file: &PathBuf, key: String| Location { file: Some(file.clone()), key: Some(key), ..Location::default() };
    match error {
        LoadError::Io { path, .. } | LoadError::NotADatasetFolder { path, .. } => at(path),
        LoadError::ManifestSyntax { file, .. }
        | LoadError::EmptyRun { file }
        | LoadError::ManifestWrite { file, .. } => at(file),
        LoadError::MissingKey { file, key }
        | LoadError::BadValue { file, key, .. }
        | LoadError::ReservedKey { file, key } => keyed(file, key.clone()),
        LoadError::WrongFormat { file, .. } => keyed(file, "format".to_owned()),
        LoadError::UnknownKind { file, run_index, .. } => keyed(file, format!("run[{run_index}].kind")),
        LoadError::BadRunFile { file, run_index, .. } => keyed(file, format!("run[{run_index}].file")),
        LoadError::NoRuns { file } => keyed(file, "run".to_owned()),
        LoadError::MissingColumn { file, column } | LoadError::DuplicateColumn { file, column } => header(file, column),
        LoadError::MissingRollMoment { file } => header(file, "cl"),
        LoadError::BadNumber { file, row, column, .. } => {
            Location { file: Some(file.clone()), row: Some(*row), column: Some((*column).to_owned()), key: None }
        }
        LoadError::MissingTime { file, row } | LoadError::NonUniformTime { file, row, .. } => {
            Location { file: Some(file.clone()), row: Some(*row), column: Some("t_s".to_owned()), key: None }
        }
        LoadError::RaggedRow { file, row, .. } => Location { file: Some(file.clone()), row: Some(*row), ..at(file) },
        LoadError::Csv { file, row, .. } => Location { row: (*row > 0).then_some(*row), ..at(file) },
        LoadError::ChannelLength { file, column, .. } => Location { column: Some((*column).to_owned()), ..at(file) },
        _ => Location::default(),
    }
}

/// A dataset error as a [`DatasetError`] with its location attributes.
pub fn dataset_error(error: &LoadError) -> PyErr {
    let location = locate(error);
    let exception = DatasetError::new_err(chained(error));
    Python::attach(|py| {
        let value = exception.value(py);
        // Setting attributes on a fresh exception object cannot fail short of memory exhaustion;
        // the message alone still names everything if it does.
        let _ = value.setattr("file", location.file.map(|file| file.display().to_string()));
        let _ = value.setattr("row", location.row);
        let _ = value.setattr("column", location.column);
        let _ = value.setattr("key", location.key);
    });
    exception
}

/// A command's error: [`DatasetError`] for the data, [`RollestError`] for the rest.
pub fn command_error(error: CommandError) -> PyErr {
    match &error {
        CommandError::Dataset(load) => dataset_error(load),
        _ => RollestError::new_err(chained(&error)),
    }
}

/// Any other error as a [`RollestError`].
pub fn other_error(error: &dyn std::error::Error) -> PyErr {
    RollestError::new_err(chained(error))
}
