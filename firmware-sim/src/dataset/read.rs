//! Loading a dataset: the manifest, then every run file (in parallel), all or nothing.

use std::fs;
use std::path::Path;

use csv::{ByteRecord, Position, ReaderBuilder};
use rayon::prelude::*;

use super::manifest::{Manifest, parse_manifest};
use super::{Channels, Dataset, DatasetError, N_TAPS, Run, RunMeta, Tunnel, Wing};

/// Name of the manifest inside a dataset folder.
pub(super) const MANIFEST: &str = "manifest.toml";

/// Index of `t_s` in [`COLUMNS`].
pub(super) const T_S: usize = 0;
/// Index of `phi_deg` in [`COLUMNS`].
const PHI_DEG: usize = 1;
/// Index of `cmu_port` in [`COLUMNS`].
const CMU_PORT: usize = 2;
/// Index of `cmu_stbd` in [`COLUMNS`].
const CMU_STBD: usize = 3;
/// Index of `cp01` in [`COLUMNS`]; the other taps follow.
const CP01: usize = 4;
/// Index of `cl` in [`COLUMNS`].
const CL: usize = CP01 + N_TAPS;
/// Index of `mx_nm` in [`COLUMNS`].
const MX_NM: usize = CL + 1;
/// Index of `alpha_deg` in [`COLUMNS`]; the commanded values follow.
const ALPHA_DEG: usize = MX_NM + 1;
/// Number of known columns.
const N_COLUMNS: usize = ALPHA_DEG + 4;

/// The columns this reader knows, by name; other columns are ignored.
pub(super) const COLUMNS: [&str; N_COLUMNS] = [
    "t_s",
    "phi_deg",
    "cmu_port",
    "cmu_stbd",
    "cp01",
    "cp02",
    "cp03",
    "cp04",
    "cp05",
    "cp06",
    "cp07",
    "cp08",
    "cp09",
    "cp10",
    "cp11",
    "cp12",
    "cl",
    "mx_nm",
    "alpha_deg",
    "phi_cmd_deg",
    "cmu_port_cmd",
    "cmu_stbd_cmd",
];

/// The columns that must be in every run file (besides `cl` or `mx_nm`).
const REQUIRED: [usize; 3 + N_TAPS] = {
    let mut required = [0; 3 + N_TAPS];
    let mut i = 0;
    while i < required.len() {
        required[i] = if i < 3 { i } else { CP01 + i - 3 };
        i += 1;
    }
    required
};

/// Tolerated deviation of a sample time from the uniform grid, as a fraction of the step.
const JITTER: f64 = 0.01;

/// Loads a whole dataset: `dir_or_manifest` is the dataset folder or its `manifest.toml`.
///
/// Run files are resolved relative to the manifest and loaded with [`load_run`], in parallel;
/// the runs keep the manifest's order. Nothing is returned partially: when several run files
/// are faulty, the error of the first one in manifest order is returned.
///
/// # Errors
/// Any [`DatasetError`] of the manifest or of a run file.
pub fn load_dataset(dir_or_manifest: &Path) -> Result<Dataset, DatasetError> {
    let manifest_path =
        if dir_or_manifest.is_dir() { dir_or_manifest.join(MANIFEST) } else { dir_or_manifest.to_path_buf() };
    let bytes = fs::read(&manifest_path).map_err(DatasetError::io(&manifest_path, "cannot read the manifest"))?;
    let manifest = parse_manifest_bytes(&manifest_path, &bytes)?;
    let base = manifest_path.parent().unwrap_or_else(|| Path::new(""));
    let (tunnel, wing) = (manifest.tunnel, manifest.wing);
    let loaded: Vec<Result<Run, DatasetError>> =
        manifest.runs.into_par_iter().map(|meta| load_run(&base.join(&meta.file), meta, &tunnel, &wing)).collect();
    let runs = loaded.into_iter().collect::<Result<Vec<Run>, DatasetError>>()?;
    Ok(Dataset { tunnel, wing, extra: manifest.extra, runs })
}

/// Loads one run file at `path` (the manifest's `meta.file` resolved against the manifest's
/// folder).
///
/// Columns are found by their trimmed header names, in any order; unknown columns are ignored.
/// A missing value (empty field, `nan` in any case, `-nan`) becomes `f64::NAN`. An absent
/// `cmu_stbd` column gives zeros. When `cl` is absent, `mx_nm` is converted with
/// `cl = mx_nm / (q S b)` (`q` from `tunnel`, `S` and `b` from `wing`). Every row must have a
/// sample time on the grid `t0 + k / meta.sample_hz` within 1 % of the step, where `t0` is the
/// first row's time and `k` the sample's index.
///
/// # Errors
/// [`DatasetError::Io`], [`DatasetError::MissingColumn`], [`DatasetError::MissingRollMoment`],
/// [`DatasetError::DuplicateColumn`], [`DatasetError::RaggedRow`], [`DatasetError::BadNumber`],
/// [`DatasetError::MissingTime`], [`DatasetError::NonUniformTime`], [`DatasetError::EmptyRun`].
pub fn load_run(path: &Path, meta: RunMeta, tunnel: &Tunnel, wing: &Wing) -> Result<Run, DatasetError> {
    let bytes = fs::read(path).map_err(DatasetError::io(path, "cannot read the run file"))?;
    parse_run(path, &bytes, meta, tunnel, wing)
}

/// The bytes of a manifest, read from `file` (named in errors), as [`load_dataset`] parses them:
/// the fuzzer's entry point (`cargo xtask fuzz --target manifest`).
///
/// # Errors
/// [`DatasetError::Io`] for text that is not UTF-8, and every error of the manifest's syntax,
/// keys and values.
pub fn parse_manifest_bytes(file: &Path, bytes: &[u8]) -> Result<Manifest, DatasetError> {
    let text = std::str::from_utf8(bytes).map_err(|err| {
        DatasetError::io(file, "cannot read the manifest")(std::io::Error::new(std::io::ErrorKind::InvalidData, err))
    })?;
    parse_manifest(file, text)
}

/// The bytes of a run file, read from `path` (named in errors), as [`load_run`] parses them:
/// the fuzzer's entry point (`cargo xtask fuzz --target dataset-csv`).
///
/// # Errors
/// As [`load_run`], except [`DatasetError::Io`].
pub fn parse_run(path: &Path, bytes: &[u8], meta: RunMeta, tunnel: &Tunnel, wing: &Wing) -> Result<Run, DatasetError> {
    let mut reader = ReaderBuilder::new().has_headers(false).flexible(true).from_reader(bytes);
    let mut header = ByteRecord::new();
    next_record(path, &mut reader, &mut header)?;
    let slots = map_header(path, &header)?;
    let rows_hint = bytes.iter().filter(|&&byte| byte == b'\n').count();
    let columns = read_rows(path, &mut reader, &slots, header.len(), meta.sample_hz, rows_hint)?;
    if columns[T_S].is_empty() {
        return Err(DatasetError::EmptyRun { file: path.to_path_buf() });
    }
    let channels = into_channels(columns, &slots, tunnel, wing);
    Ok(Run { meta, channels })
}

/// Reads the next record into `record`; false at the end of the file.
fn next_record(file: &Path, reader: &mut csv::Reader<&[u8]>, record: &mut ByteRecord) -> Result<bool, DatasetError> {
    reader.read_byte_record(record).map_err(|err| DatasetError::Csv {
        file: file.to_path_buf(),
        row: err.position().map_or(0, Position::line),
        message: err.to_string(),
    })
}

/// A run's channels from named columns held in memory (a notebook's arrays or DataFrame), taken
/// as a run file's header and columns are: known names only (others are ignored, as the format
/// says), each once, the required ones present, `cl` converted from `mx_nm` when only that is
/// given, `cmu_stbd` zero when absent. `file` is the run's file, named in errors. Lengths, times
/// and values are [`check_dataset`](super::check_dataset)'s.
///
/// # Errors
/// [`DatasetError::DuplicateColumn`], [`DatasetError::MissingColumn`] or
/// [`DatasetError::MissingRollMoment`], naming `file` and the column.
pub fn channels_from_columns(
    file: &Path,
    columns: Vec<(String, Vec<f64>)>,
    tunnel: &Tunnel,
    wing: &Wing,
) -> Result<Channels, DatasetError> {
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); N_COLUMNS];
    let names: Vec<String> = columns.iter().map(|(name, _)| name.clone()).collect();
    let slots = map_names(file, names.iter().map(String::as_str))?;
    for (name, column) in columns {
        if let Some(slot) = COLUMNS.iter().position(|known| *known == name.trim()) {
            values[slot] = column;
        }
    }
    Ok(into_channels(values, &slots, tunnel, wing))
}

/// For each known column, the index of its field in the header, checking the required ones.
fn map_header(file: &Path, header: &ByteRecord) -> Result<[Option<usize>; N_COLUMNS], DatasetError> {
    // The CSV reader has already dropped a UTF-8 byte order mark at the start of the file.
    let names: Vec<String> = header.iter().map(|raw| String::from_utf8_lossy(raw).into_owned()).collect();
    map_names(file, names.iter().map(String::as_str))
}

/// For each known column, the index of its name in `names`, checking the required ones.
fn map_names<'a>(
    file: &Path,
    names: impl Iterator<Item = &'a str>,
) -> Result<[Option<usize>; N_COLUMNS], DatasetError> {
    let mut slots = [None; N_COLUMNS];
    for (field, name) in names.enumerate() {
        let Some(slot) = COLUMNS.iter().position(|column| *column == name.trim()) else {
            continue;
        };
        if slots[slot].replace(field).is_some() {
            return Err(DatasetError::DuplicateColumn { file: file.to_path_buf(), column: COLUMNS[slot] });
        }
    }
    if let Some(&slot) = REQUIRED.iter().find(|&&slot| slots[slot].is_none()) {
        return Err(DatasetError::MissingColumn { file: file.to_path_buf(), column: COLUMNS[slot] });
    }
    if slots[CL].is_none() && slots[MX_NM].is_none() {
        return Err(DatasetError::MissingRollMoment { file: file.to_path_buf() });
    }
    Ok(slots)
}

/// Reads all data rows into one vector per known column (empty for absent columns).
fn read_rows(
    file: &Path,
    reader: &mut csv::Reader<&[u8]>,
    slots: &[Option<usize>; N_COLUMNS],
    n_fields: usize,
    sample_hz: f64,
    rows_hint: usize,
) -> Result<Vec<Vec<f64>>, DatasetError> {
    let present: Vec<(usize, usize)> =
        slots.iter().enumerate().filter_map(|(slot, field)| field.map(|field| (slot, field))).collect();
    let mut columns: Vec<Vec<f64>> =
        slots.iter().map(|field| Vec::with_capacity(if field.is_some() { rows_hint } else { 0 })).collect();
    let mut clock = Clock::new(sample_hz);
    let mut record = ByteRecord::new();
    while next_record(file, reader, &mut record)? {
        let row = record.position().map_or(0, Position::line);
        if record.len() != n_fields {
            return Err(DatasetError::RaggedRow {
                file: file.to_path_buf(),
                row,
                expected: n_fields,
                found: record.len(),
            });
        }
        for &(slot, field) in &present {
            let value = parse_field(file, row, slot, &record[field])?;
            if slot == T_S {
                clock.check(file, row, value)?;
            }
            columns[slot].push(value);
        }
    }
    Ok(columns)
}

/// Parses one field of column `slot`; see [`parse_value`].
fn parse_field(file: &Path, row: u64, slot: usize, raw: &[u8]) -> Result<f64, DatasetError> {
    parse_value(raw).ok_or_else(|| DatasetError::BadNumber {
        file: file.to_path_buf(),
        row,
        column: COLUMNS[slot],
        text: String::from_utf8_lossy(raw).into_owned(),
    })
}

/// A finite number, or `NaN` for a missing value (an empty field or `nan` in any case, with an
/// optional sign), after trimming whitespace; `None` for anything else (including infinities).
pub(super) fn parse_value(raw: &[u8]) -> Option<f64> {
    let text = std::str::from_utf8(raw).ok()?.trim();
    let unsigned = text.strip_prefix(['+', '-']).unwrap_or(text);
    if text.is_empty() || unsigned.eq_ignore_ascii_case("nan") {
        return Some(f64::NAN);
    }
    text.parse::<f64>().ok().filter(|value| value.is_finite())
}

/// Checks that sample times lie on the uniform grid `t0 + k / sample_hz`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Clock {
    /// The step, s.
    step_s: f64,
    /// Time of the first sample, s; `None` before the first sample.
    t0_s: Option<f64>,
    /// Index of the next sample.
    next: u64,
}

impl Clock {
    /// A clock for samples at `sample_hz`.
    pub(super) fn new(sample_hz: f64) -> Self {
        Self { step_s: sample_hz.recip(), t0_s: None, next: 0 }
    }

    /// Checks the next sample time `t_s`, found in `row` of `file`.
    pub(super) fn check(&mut self, file: &Path, row: u64, t_s: f64) -> Result<(), DatasetError> {
        if t_s.is_nan() {
            return Err(DatasetError::MissingTime { file: file.to_path_buf(), row });
        }
        let t0_s = *self.t0_s.get_or_insert(t_s);
        #[allow(clippy::cast_precision_loss, reason = "sample counts stay far below 2^52")]
        let expected_s = t0_s + self.next as f64 * self.step_s;
        let deviation_s = (t_s - expected_s).abs();
        // A NaN deviation comes from an invalid sample rate and is refused too.
        if deviation_s.is_nan() || deviation_s > JITTER * self.step_s {
            return Err(DatasetError::NonUniformTime { file: file.to_path_buf(), row, expected_s, found_s: t_s });
        }
        self.next += 1;
        Ok(())
    }
}

/// Moves the parsed columns into [`Channels`], filling `cmu_stbd` and converting `mx_nm`.
fn into_channels(
    mut columns: Vec<Vec<f64>>,
    slots: &[Option<usize>; N_COLUMNS],
    tunnel: &Tunnel,
    wing: &Wing,
) -> Channels {
    let len = columns[T_S].len();
    let mut take = |slot: usize| std::mem::take(&mut columns[slot]);
    let optional = |slot: usize, take: &mut dyn FnMut(usize) -> Vec<f64>| slots[slot].map(|_| take(slot));
    let cl = if slots[CL].is_some() {
        take(CL)
    } else {
        let denominator = tunnel.dynamic_pressure_pa() * wing.area_m2 * wing.span_m;
        take(MX_NM).into_iter().map(|mx_nm| mx_nm / denominator).collect()
    };
    Channels {
        t_s: take(T_S),
        phi_deg: take(PHI_DEG),
        cmu_port: take(CMU_PORT),
        cmu_stbd: optional(CMU_STBD, &mut take).unwrap_or_else(|| vec![0.0; len]),
        cp: std::array::from_fn(|tap| take(CP01 + tap)),
        cl,
        alpha_deg: optional(ALPHA_DEG, &mut take),
        phi_cmd_deg: optional(ALPHA_DEG + 1, &mut take),
        cmu_port_cmd: optional(ALPHA_DEG + 2, &mut take),
        cmu_stbd_cmd: optional(ALPHA_DEG + 3, &mut take),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_table_is_consistent() {
        assert_eq!(COLUMNS[CP01 + 11], "cp12");
        assert_eq!(COLUMNS[CL], "cl");
        assert_eq!(COLUMNS[MX_NM], "mx_nm");
        assert_eq!(COLUMNS[ALPHA_DEG + 3], "cmu_stbd_cmd");
        let names: Vec<&str> = REQUIRED.iter().map(|&slot| COLUMNS[slot]).collect();
        assert_eq!(names[..4], ["t_s", "phi_deg", "cmu_port", "cp01"]);
        assert_eq!(names.last(), Some(&"cp12"));
    }

    #[test]
    fn parse_value_reads_numbers_and_missing_values() {
        assert_eq!(parse_value(b" 1.5 "), Some(1.5));
        assert_eq!(parse_value(b"-2e-3"), Some(-2e-3));
        assert_eq!(parse_value(b"10"), Some(10.0));
        for missing in [&b""[..], b"  ", b"nan", b"NaN", b"NAN", b"-nan", b"+NaN"] {
            assert!(parse_value(missing).is_some_and(f64::is_nan), "{missing:?}");
        }
        for bad in [&b"abc"[..], b"inf", b"-infinity", b"1,5", b"1.5.2", b"\xff", b"nan1"] {
            assert_eq!(parse_value(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn clock_accepts_jitter_below_one_percent_and_names_the_row() {
        let file = Path::new("r.csv");
        let mut clock = Clock::new(100.0);
        for (k, jitter) in [0.0, 0.009, -0.009, 0.0].into_iter().enumerate() {
            let t = 5.0 + (k as f64 + jitter) * 0.01;
            clock.check(file, k as u64 + 2, t).unwrap();
        }
        let err = clock.check(file, 6, 5.0 + 4.02 * 0.01).unwrap_err();
        assert!(err.to_string().starts_with("r.csv: row 6, column t_s: expected 5.04 s"), "{err}");
        let err = Clock::new(100.0).check(file, 2, f64::NAN).unwrap_err();
        assert!(matches!(err, DatasetError::MissingTime { row: 2, .. }), "{err}");
    }

    #[test]
    fn clock_refuses_an_invalid_rate() {
        let mut clock = Clock::new(f64::NAN);
        assert!(clock.check(Path::new("r.csv"), 2, 0.0).is_err());
    }
}
