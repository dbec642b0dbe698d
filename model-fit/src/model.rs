//! Model folders: what `fit` writes and what every command's `--model` reads.
//!
//! A model folder holds `model.bin` (the postcard coefficient blob with its header), `model.md`
//! (the model card: equations with their coefficients, fit metrics, plots), `model.json` (the
//! same numbers, machine-readable) and SVG plots. `--model` accepts the folder or `model.bin`
//! itself; without it, commands use the tables compiled into the estimator.

use std::path::{Path, PathBuf};

use estimator_core::CoefficientSet;
use estimator_core::blob::{self, DecodeError, EncodeError, InvalidSet, MAX_BLOB_LEN};

/// The blob's file name in a model folder.
pub const BLOB_FILE: &str = "model.bin";

/// Why a model could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The blob was refused (wrong, truncated or corrupted).
    #[error("{path}: not a usable coefficient blob: {error}")]
    Blob {
        /// The file.
        path: PathBuf,
        /// Why.
        error: DecodeError,
    },
    /// The set could not be written as a blob.
    #[error("{path}: the coefficient set cannot be written as a blob: {error}")]
    ToBlob {
        /// The file it was to be written to.
        path: PathBuf,
        /// Why.
        error: ToBlobError,
    },
    /// Writing the folder failed.
    #[error(transparent)]
    Folder(#[from] firmware_sim::atomic::FolderError),
}

/// Where a model came from, for reports.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelSource {
    /// The tables compiled into the estimator.
    BuiltIn,
    /// A blob file.
    File(PathBuf),
}

impl std::fmt::Display for ModelSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::BuiltIn => f.write_str("built-in default tables (estimator_core::coeffs::DEFAULT)"),
            Self::File(path) => write!(f, "{}", path.display()),
        }
    }
}

/// Loads `--model` (a model folder or its `model.bin`), or the built-in tables when `None`.
pub fn load(model: Option<&Path>) -> Result<(CoefficientSet, ModelSource), ModelError> {
    let Some(path) = model else {
        return Ok((estimator_core::coeffs::DEFAULT, ModelSource::BuiltIn));
    };
    let file = if path.is_dir() { path.join(BLOB_FILE) } else { path.to_path_buf() };
    let bytes = std::fs::read(&file).map_err(|source| ModelError::Io { path: file.clone(), source })?;
    let set = blob::decode(&bytes).map_err(|error| ModelError::Blob { path: file.clone(), error })?;
    Ok((set, ModelSource::File(file)))
}

/// The blob bytes of `--model` (a model folder or its blob), checked: they decode to a valid set.
///
/// # Errors
///
/// [`ModelError`] naming the file when it cannot be read or is not a usable blob.
pub fn blob_bytes(model: &Path) -> Result<Vec<u8>, ModelError> {
    let file = if model.is_dir() { model.join(BLOB_FILE) } else { model.to_path_buf() };
    let bytes = std::fs::read(&file).map_err(|source| ModelError::Io { path: file.clone(), source })?;
    blob::decode(&bytes).map_err(|error| ModelError::Blob { path: file.clone(), error })?;
    Ok(bytes)
}

/// Why a coefficient set could not become blob bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ToBlobError {
    /// The set is not usable by the estimator: it is not written.
    #[error(transparent)]
    Invalid(#[from] InvalidSet),
    /// The blob could not be written.
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// The blob bytes of a (valid) coefficient set.
///
/// # Errors
///
/// [`ToBlobError`] when the set is not valid or does not serialize.
pub fn encode(set: &CoefficientSet) -> Result<Vec<u8>, ToBlobError> {
    blob::validate(set)?;
    let mut buffer = vec![0u8; MAX_BLOB_LEN];
    let length = blob::encode(set, &mut buffer)?;
    buffer.truncate(length);
    Ok(buffer)
}
