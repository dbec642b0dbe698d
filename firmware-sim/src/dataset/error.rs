//! The error of loading or writing a dataset.
//!
//! Every message names the file, then the row (1-based, header = row 1) or the manifest key, then
//! what was expected and what was found. Keys of run tables are written `run[N].key` with `N`
//! counted from 1 in manifest order, like rows.

use std::path::PathBuf;

/// Why a dataset could not be loaded or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// Reading, writing, creating, renaming or removing a file or folder failed.
    #[error("{}: {action}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What was being done (`"cannot read"`, `"cannot create the folder"`, ...).
        action: &'static str,
        /// The underlying error.
        source: std::io::Error,
    },

    /// The manifest is not valid TOML.
    #[error("{}: line {line}: expected valid TOML, found a syntax error: {message}", file.display())]
    ManifestSyntax {
        /// The manifest.
        file: PathBuf,
        /// Line of the error, 1-based.
        line: usize,
        /// The parser's description.
        message: String,
    },

    /// A required manifest key is absent.
    #[error("{}: key {key}: expected a value, found no such key", file.display())]
    MissingKey {
        /// The manifest.
        file: PathBuf,
        /// The key (`"tunnel.u_inf_mps"`, `"run[2].sample_hz"`, ...).
        key: String,
    },

    /// The `format` key is not exactly `"roll-dataset/1"`.
    #[error("{}: key format: expected \"{}\", found {found}", file.display(), super::FORMAT)]
    WrongFormat {
        /// The manifest.
        file: PathBuf,
        /// The value found, written as TOML.
        found: String,
    },

    /// A run's `kind` is not one of the four kinds.
    #[error(
        "{}: key run[{run_index}].kind: expected one of \"roll\", \"actuation\", \
         \"roll+actuation\", \"static\", found {found:?}",
        file.display()
    )]
    UnknownKind {
        /// The manifest.
        file: PathBuf,
        /// Index of the `[[run]]` table, 1-based, in manifest order.
        run_index: usize,
        /// The kind found.
        found: String,
    },

    /// A manifest key has a value of the wrong type or out of range.
    #[error("{}: key {key}: expected {expected}, found {found}", file.display())]
    BadValue {
        /// The manifest.
        file: PathBuf,
        /// The key (`"tunnel.u_inf_mps"`, `"run[2].sample_hz"`, ...).
        key: String,
        /// What the key must hold.
        expected: &'static str,
        /// The value found, written as TOML.
        found: String,
    },

    /// The manifest has no `[[run]]` table.
    #[error("{}: key run: expected at least one [[run]] table, found none", file.display())]
    NoRuns {
        /// The manifest.
        file: PathBuf,
    },

    /// A required column is absent from the header.
    #[error("{}: row 1 (header): expected a column named {column:?}, found none", file.display())]
    MissingColumn {
        /// The run file.
        file: PathBuf,
        /// The column's name.
        column: &'static str,
    },

    /// Neither `cl` nor `mx_nm` is in the header.
    #[error(
        "{}: row 1 (header): expected a column named \"cl\" or \"mx_nm\", found neither",
        file.display()
    )]
    MissingRollMoment {
        /// The run file.
        file: PathBuf,
    },

    /// A known column appears more than once in the header, so which one to use is ambiguous.
    #[error("{}: row 1 (header): expected column {column:?} once, found it twice", file.display())]
    DuplicateColumn {
        /// The run file.
        file: PathBuf,
        /// The column's name.
        column: &'static str,
    },

    /// A field is neither a finite number nor a missing value.
    #[error(
        "{}: row {row}, column {column}: expected a number or an empty field, found {text:?}",
        file.display()
    )]
    BadNumber {
        /// The run file.
        file: PathBuf,
        /// Row, 1-based, header = row 1 (the line of the file where the row starts).
        row: u64,
        /// The column's name.
        column: &'static str,
        /// The field as found (lossily decoded when it is not UTF-8).
        text: String,
    },

    /// A sample time is missing (empty or `nan`): `t_s` must be present in every row.
    #[error(
        "{}: row {row}, column t_s: expected a sample time, found a missing value",
        file.display()
    )]
    MissingTime {
        /// The run file.
        file: PathBuf,
        /// Row, 1-based, header = row 1 (the line of the file where the row starts).
        row: u64,
    },

    /// A sample time is off the uniform grid `t0 + k / sample_hz` by more than 1 % of the step.
    #[error(
        "{}: row {row}, column t_s: expected {expected_s} s (uniform steps of 1/sample_hz, \
         jitter up to 1 % of the step), found {found_s} s",
        file.display()
    )]
    NonUniformTime {
        /// The run file.
        file: PathBuf,
        /// Row, 1-based, header = row 1 (the line of the file where the row starts).
        row: u64,
        /// The time on the uniform grid.
        expected_s: f64,
        /// The time found.
        found_s: f64,
    },

    /// A row has a different number of fields than the header.
    #[error("{}: row {row}: expected {expected} fields like the header, found {found}", file.display())]
    RaggedRow {
        /// The run file.
        file: PathBuf,
        /// Row, 1-based, header = row 1 (the line of the file where the row starts).
        row: u64,
        /// Number of fields of the header.
        expected: usize,
        /// Number of fields of the row.
        found: usize,
    },

    /// A run file has a header but no samples.
    #[error("{}: expected at least one data row after the header, found none", file.display())]
    EmptyRun {
        /// The run file.
        file: PathBuf,
    },

    /// The CSV reader failed on a file that is not valid CSV.
    #[error("{}: row {row}: expected valid CSV, found an error: {message}", file.display())]
    Csv {
        /// The run file.
        file: PathBuf,
        /// Row, 1-based, header = row 1 (0 when unknown).
        row: u64,
        /// The reader's description.
        message: String,
    },

    /// Writing: a channel's length differs from the length of `t_s`.
    #[error("{}: column {column}: expected {expected} samples like t_s, found {found}", file.display())]
    ChannelLength {
        /// The run file that would have been written.
        file: PathBuf,
        /// The column's name.
        column: &'static str,
        /// Length of `t_s`.
        expected: usize,
        /// Length of the channel.
        found: usize,
    },

    /// Writing: a run's file is not a relative path inside the dataset folder, or is used twice.
    #[error("{}: key run[{run_index}].file: expected {expected}, found {found:?}", file.display())]
    BadRunFile {
        /// The manifest that would have been written.
        file: PathBuf,
        /// Index of the `[[run]]` table, 1-based, in manifest order.
        run_index: usize,
        /// What the path must be.
        expected: &'static str,
        /// The path found.
        found: String,
    },

    /// Writing: an extra key has the name of a key that the format defines.
    #[error("{}: key {key}: expected an extra key, found a key reserved by the format", file.display())]
    ReservedKey {
        /// The manifest that would have been written.
        file: PathBuf,
        /// The key.
        key: String,
    },

    /// Writing: the manifest could not be serialized as TOML.
    #[error("{}: expected serializable TOML, found an error: {message}", file.display())]
    ManifestWrite {
        /// The manifest that would have been written.
        file: PathBuf,
        /// The serializer's description.
        message: String,
    },

    /// Writing: the destination exists but does not look like a dataset, so it is not replaced.
    #[error(
        "{}: expected no folder, an empty folder or a dataset folder with manifest.toml, \
         found {found}; refusing to replace it",
        path.display()
    )]
    NotADatasetFolder {
        /// The destination.
        path: PathBuf,
        /// What is there (`"a file"`, `"a folder without manifest.toml"`).
        found: &'static str,
    },
}

impl DatasetError {
    /// An [`DatasetError::Io`] for `path`; for use with `map_err`.
    pub(super) fn io(path: impl Into<PathBuf>, action: &'static str) -> impl FnOnce(std::io::Error) -> Self {
        let path = path.into();
        move |source| Self::Io { path, action, source }
    }
}

impl From<crate::atomic::FolderError> for DatasetError {
    fn from(error: crate::atomic::FolderError) -> Self {
        match error {
            crate::atomic::FolderError::Refused { path, found } => Self::NotADatasetFolder {
                path,
                found: if found == "a file" { "a file" } else { "a folder without manifest.toml" },
            },
            crate::atomic::FolderError::Io { path, action, source } => Self::Io { path, action, source },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_number_message_names_file_row_column_and_text() {
        let err = DatasetError::BadNumber {
            file: PathBuf::from("runs/roll_a10.csv"),
            row: 17,
            column: "cp03",
            text: "abc".into(),
        };
        assert_eq!(
            err.to_string(),
            "runs/roll_a10.csv: row 17, column cp03: expected a number or an empty field, \
             found \"abc\""
        );
    }

    #[test]
    fn wrong_format_message_quotes_the_expected_string() {
        let err = DatasetError::WrongFormat { file: "m.toml".into(), found: "\"x/2\"".into() };
        assert_eq!(err.to_string(), "m.toml: key format: expected \"roll-dataset/1\", found \"x/2\"");
    }

    #[test]
    fn io_message_names_path_and_action() {
        let source = std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        let err = DatasetError::io("a/b.csv", "cannot read")(source);
        assert_eq!(err.to_string(), "a/b.csv: cannot read: gone");
        assert!(std::error::Error::source(&err).is_some());
    }

    #[test]
    fn messages_are_lowercase_without_trailing_period() {
        let errors = [
            DatasetError::NoRuns { file: "m.toml".into() },
            DatasetError::EmptyRun { file: "r.csv".into() },
            DatasetError::MissingRollMoment { file: "r.csv".into() },
            DatasetError::MissingTime { file: "r.csv".into(), row: 3 },
            DatasetError::RaggedRow { file: "r.csv".into(), row: 4, expected: 17, found: 16 },
        ];
        for err in errors {
            let text = err.to_string();
            assert!(!text.ends_with('.'), "{text}");
            let after_file = text.split_once(": ").map_or("", |(_, rest)| rest);
            assert!(after_file.starts_with(|c: char| c.is_lowercase()), "{text}");
        }
    }
}
