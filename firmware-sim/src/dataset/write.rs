//! Writing a dataset atomically: everything goes into a temporary sibling folder that is then
//! renamed into place.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Component, Path};

use rayon::prelude::*;

use super::manifest::{manifest_text, validate};
use super::read::{COLUMNS, Clock, MANIFEST};
use super::{Channels, Dataset, DatasetError, Run};

/// Writes `dataset` into the folder `dir`: `manifest.toml` and one CSV file per run at the run's
/// `file` (relative to `dir`; parent folders such as `runs/` are created).
///
/// The dataset is checked first so that what is written loads again with
/// [`load_dataset`](super::load_dataset) (positive tunnel and wing values, finite angles,
/// positive sample rates, channels as long as `t_s`, at least one sample per run, sample times
/// on the uniform grid, relative and distinct run files, no extra key named like a key of the
/// format). Floats are written in their shortest round-trip form, so reading back is bit-exact;
/// `NaN` is written as an empty field, and an infinite sample is an error.
///
/// The write is atomic for readers of `dir`: everything is written into a temporary sibling
/// folder `.{name}.tmp-{pid}-{n}`, which is then renamed to `dir`. An existing `dir` is replaced
/// only once the new folder is complete (it is renamed to a backup, the new folder renamed in,
/// the backup removed); it must be empty or contain a `manifest.toml`, so that a folder that is
/// not a dataset is never deleted. On any error the temporary folder is removed and an existing
/// `dir` is left as it was. Files are not synced to disk. If removing the backup fails after the
/// new dataset is in place, the hidden backup folder is left behind and the write still succeeds.
///
/// # Errors
/// A [`DatasetError`] naming the file and the key or row that is invalid, or the I/O failure.
pub fn write_dataset(dir: &Path, dataset: &Dataset) -> Result<(), DatasetError> {
    let run_files = checked_run_files(dir, dataset)?;
    let text = manifest_text(&dir.join(MANIFEST), dataset, &run_files)?;
    crate::atomic::write_folder(dir, MANIFEST, |tmp| fill(tmp, dir, dataset, &run_files, &text))
}

/// Checks a dataset built in memory (from a notebook's arrays, say) as
/// [`load_dataset`](super::load_dataset) checks a folder, so that it holds only what a folder
/// of the format can: positive tunnel and wing values, finite angles, positive sample rates,
/// channels as long as `t_s`, at least one sample per run, sample times on the uniform grid, no
/// infinite sample, relative and distinct run files, no extra key named like a key of the
/// format. `dir` is where the dataset would lie: errors name its manifest, or a run's file in
/// it, with the key, row and column.
///
/// # Errors
/// The first [`DatasetError`] in manifest order.
pub fn check_dataset(dir: &Path, dataset: &Dataset) -> Result<(), DatasetError> {
    checked_run_files(dir, dataset).map(drop)
}

/// The runs' files as the manifest names them, once the dataset is checked ([`check_dataset`]).
fn checked_run_files(dir: &Path, dataset: &Dataset) -> Result<Vec<String>, DatasetError> {
    let manifest_file = dir.join(MANIFEST);
    validate(&manifest_file, dataset)?;
    let run_files = run_files(&manifest_file, dataset)?;
    for (run, run_file) in dataset.runs.iter().zip(&run_files) {
        check_run(&dir.join(run_file), run)?;
    }
    Ok(run_files)
}

/// The runs' files as written in the manifest: relative, `/`-separated, distinct, not the
/// manifest.
fn run_files(manifest_file: &Path, dataset: &Dataset) -> Result<Vec<String>, DatasetError> {
    let mut files: Vec<String> = Vec::with_capacity(dataset.runs.len());
    for (index, run) in dataset.runs.iter().enumerate() {
        let bad = |expected| DatasetError::BadRunFile {
            file: manifest_file.to_path_buf(),
            run_index: index + 1,
            expected,
            found: run.meta.file.display().to_string(),
        };
        let file = normalized(&run.meta.file)
            .ok_or_else(|| bad("a relative path inside the dataset folder, without \"..\", in UTF-8"))?;
        if file == MANIFEST {
            return Err(bad("a path other than the manifest's"));
        }
        if files.contains(&file) {
            return Err(bad("a file that no other run uses"));
        }
        files.push(file);
    }
    Ok(files)
}

/// `path` with `/` separators when it is relative, non-empty, without `..` and in UTF-8.
fn normalized(path: &Path) -> Option<String> {
    let mut parts = Vec::new();
    for component in path.components() {
        match component {
            Component::Normal(part) => parts.push(part.to_str()?),
            Component::CurDir => {}
            Component::ParentDir | Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    (!parts.is_empty()).then(|| parts.join("/"))
}

/// The columns written for `channels`, in order: the required ones, then the optional ones that
/// are present.
fn columns_of(channels: &Channels) -> Vec<(&'static str, &[f64])> {
    let mut columns = vec![
        (COLUMNS[0], channels.t_s.as_slice()),
        (COLUMNS[1], channels.phi_deg.as_slice()),
        (COLUMNS[2], channels.cmu_port.as_slice()),
        (COLUMNS[3], channels.cmu_stbd.as_slice()),
    ];
    columns.extend(COLUMNS[4..].iter().zip(&channels.cp).map(|(name, cp)| (*name, cp.as_slice())));
    columns.push(("cl", channels.cl.as_slice()));
    let optional = [
        ("alpha_deg", &channels.alpha_deg),
        ("phi_cmd_deg", &channels.phi_cmd_deg),
        ("cmu_port_cmd", &channels.cmu_port_cmd),
        ("cmu_stbd_cmd", &channels.cmu_stbd_cmd),
    ];
    columns.extend(optional.into_iter().filter_map(|(name, values)| Some((name, values.as_deref()?))));
    columns
}

/// Checks that a run would load again: equal channel lengths, samples, uniform times, finite or
/// missing values. `file` is the run's file in the destination.
fn check_run(file: &Path, run: &Run) -> Result<(), DatasetError> {
    let channels = &run.channels;
    let len = channels.t_s.len();
    for (column, values) in columns_of(channels) {
        if values.len() != len {
            let found = values.len();
            return Err(DatasetError::ChannelLength { file: file.to_path_buf(), column, expected: len, found });
        }
    }
    if len == 0 {
        return Err(DatasetError::EmptyRun { file: file.to_path_buf() });
    }
    let mut clock = Clock::new(run.meta.sample_hz);
    (2..).zip(&channels.t_s).try_for_each(|(row, &t_s)| clock.check(file, row, t_s))?;
    // The format has no spelling for an infinity (a reader refuses one), so a run holding one
    // would not load again.
    for (column, values) in columns_of(channels) {
        if let Some((row, value)) = (2_u64..).zip(values).find(|(_, value)| value.is_infinite()) {
            return Err(DatasetError::BadNumber { file: file.to_path_buf(), row, column, text: value.to_string() });
        }
    }
    Ok(())
}

/// Writes the manifest and all run files into the new folder `tmp`. `dir` is the destination,
/// named in errors about the data.
fn fill(tmp: &Path, dir: &Path, dataset: &Dataset, run_files: &[String], text: &str) -> Result<(), DatasetError> {
    let manifest = tmp.join(MANIFEST);
    fs::write(&manifest, text).map_err(DatasetError::io(&manifest, "cannot write"))?;
    let written: Vec<Result<(), DatasetError>> = dataset
        .runs
        .par_iter()
        .zip(run_files)
        .map(|(run, file)| write_run(&tmp.join(file), &dir.join(file), &run.channels))
        .collect();
    written.into_iter().collect()
}

/// Writes one run file at `path`; `shown` is its path in the destination, named in data errors.
fn write_run(path: &Path, shown: &Path, channels: &Channels) -> Result<(), DatasetError> {
    if let Some(parent) = path.parent() {
        fs::create_dir_all(parent).map_err(DatasetError::io(parent, "cannot create the folder"))?;
    }
    let file = File::create(path).map_err(DatasetError::io(path, "cannot create"))?;
    let mut out = BufWriter::with_capacity(1 << 16, file);
    let columns = columns_of(channels);
    let header: Vec<&str> = columns.iter().map(|(name, _)| *name).collect();
    let write_err = DatasetError::io(path, "cannot write");
    out.write_all(format!("{}\n", header.join(",")).as_bytes()).map_err(write_err)?;
    let mut line = Vec::with_capacity(32 * columns.len());
    let mut number = ryu::Buffer::new();
    for (index, row) in (0..channels.len()).zip(2_u64..) {
        line.clear();
        for (position, &(column, values)) in columns.iter().enumerate() {
            if position > 0 {
                line.push(b',');
            }
            let value = values.get(index).copied().unwrap_or(f64::NAN);
            if value.is_infinite() {
                let text = value.to_string();
                return Err(DatasetError::BadNumber { file: shown.to_path_buf(), row, column, text });
            }
            if !value.is_nan() {
                line.extend_from_slice(number.format_finite(value).as_bytes());
            }
        }
        line.push(b'\n');
        out.write_all(&line).map_err(DatasetError::io(path, "cannot write"))?;
    }
    out.flush().map_err(DatasetError::io(path, "cannot write"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalized_accepts_relative_paths_only() {
        assert_eq!(normalized(Path::new("runs/a.csv")).as_deref(), Some("runs/a.csv"));
        assert_eq!(normalized(Path::new("./runs/./a.csv")).as_deref(), Some("runs/a.csv"));
        assert_eq!(normalized(Path::new("../a.csv")), None);
        assert_eq!(normalized(Path::new("runs/../../a.csv")), None);
        assert_eq!(normalized(Path::new("/tmp/a.csv")), None);
        assert_eq!(normalized(Path::new("")), None);
    }

    #[test]
    fn columns_follow_the_documented_order() {
        let mut channels = Channels { phi_cmd_deg: Some(Vec::new()), ..Channels::default() };
        channels.alpha_deg = Some(Vec::new());
        let names: Vec<&str> = columns_of(&channels).iter().map(|(name, _)| *name).collect();
        let expected = "t_s,phi_deg,cmu_port,cmu_stbd,cp01,cp02,cp03,cp04,cp05,cp06,cp07,cp08,\
                        cp09,cp10,cp11,cp12,cl,alpha_deg,phi_cmd_deg";
        assert_eq!(names.join(","), expected);
    }
}
