//! Parsing and writing `manifest.toml`: the format string, `[tunnel]`, `[wing]`, extra top-level
//! keys and the `[[run]]` tables.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::{Table, Value};

use super::{Dataset, DatasetError, FORMAT, RunKind, RunMeta, Tunnel, Wing};

/// Top-level keys defined by the format; all others are extra keys.
const TOP_KEYS: [&str; 4] = ["format", "tunnel", "wing", "run"];

/// Keys of a `[[run]]` table defined by the format; all others are extra keys.
const RUN_KEYS: [&str; 4] = ["file", "kind", "alpha_deg", "sample_hz"];

/// The contents of a manifest, without the run data.
#[derive(Debug, Clone, PartialEq)]
pub struct Manifest {
    /// Free-stream conditions.
    pub tunnel: Tunnel,
    /// Wing geometry.
    pub wing: Wing,
    /// Extra top-level keys.
    pub extra: Table,
    /// The `[[run]]` tables, in manifest order.
    pub runs: Vec<RunMeta>,
}

/// The range a number must lie in.
#[derive(Debug, Clone, Copy)]
pub(super) enum Rule {
    /// Any finite number.
    Finite,
    /// A finite number greater than zero.
    Positive,
}

impl Rule {
    /// What the rule expects, for error messages.
    const fn expected(self) -> &'static str {
        match self {
            Self::Finite => "a finite number",
            Self::Positive => "a finite number greater than zero",
        }
    }

    /// True when `value` satisfies the rule.
    fn accepts(self, value: f64) -> bool {
        match self {
            Self::Finite => value.is_finite(),
            Self::Positive => value.is_finite() && value > 0.0,
        }
    }
}

/// Checks `value` of `key` against `rule`.
pub(super) fn check_number(file: &Path, key: &str, value: f64, rule: Rule) -> Result<f64, DatasetError> {
    if rule.accepts(value) {
        Ok(value)
    } else {
        Err(DatasetError::BadValue {
            file: file.to_path_buf(),
            key: key.to_owned(),
            expected: rule.expected(),
            found: Value::Float(value).to_string(),
        })
    }
}

/// The key of a run table's entry in error messages: `run[N].key`, `N` 1-based.
pub(super) fn run_key(run_index: usize, key: &str) -> String {
    format!("run[{run_index}].{key}")
}

/// The manifest's format keys as serde reads them, each with its type; other keys are ignored
/// here and kept from the parsed table (the extra keys). Absent keys are `None` here and become
/// [`DatasetError::MissingKey`] or the paper's value after reading; numbers are checked against
/// their [`Rule`] after reading too. No `#[serde(flatten)]`: it would read the fields through a
/// buffer that `serde_path_to_error` cannot see into, and a wrong value would lose its key.
#[derive(Debug, Deserialize)]
struct RawManifest {
    tunnel: Option<RawTunnel>,
    wing: Option<RawWing>,
    run: Option<Vec<RawRun>>,
}

#[derive(Debug, Deserialize)]
struct RawTunnel {
    u_inf_mps: Option<Number>,
    rho_kgm3: Option<Number>,
}

#[derive(Debug, Deserialize)]
struct RawWing {
    chord_m: Option<Number>,
    span_m: Option<Number>,
    area_m2: Option<Number>,
    ixx_kgm2: Option<Number>,
    mass_kg: Option<Number>,
}

#[derive(Debug, Deserialize)]
struct RawRun {
    file: Option<String>,
    kind: Option<String>,
    alpha_deg: Option<Number>,
    sample_hz: Option<Number>,
}

/// A TOML number, integer or float (the format accepts both wherever it asks for a number).
#[derive(Debug, Clone, Copy)]
struct Number(f64);

impl<'de> Deserialize<'de> for Number {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = Number;
            fn expecting(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                formatter.write_str("a number")
            }
            fn visit_f64<E>(self, value: f64) -> Result<Number, E> {
                Ok(Number(value))
            }
            #[allow(clippy::cast_precision_loss, reason = "manifest integers are small")]
            fn visit_i64<E>(self, value: i64) -> Result<Number, E> {
                Ok(Number(value as f64))
            }
            #[allow(clippy::cast_precision_loss, reason = "manifest integers are small")]
            fn visit_u64<E>(self, value: u64) -> Result<Number, E> {
                Ok(Number(value as f64))
            }
        }
        deserializer.deserialize_any(Visitor)
    }
}

/// Parses the text of the manifest `file`: TOML syntax first (the line of an error), then the
/// format string, then the format's keys through serde, whose path names the key of a value of
/// the wrong type (`serde_path_to_error`), then each number's range.
///
/// # Errors
/// Syntax errors, a wrong or missing format string, missing or ill-typed keys, out-of-range
/// numbers, unknown run kinds, and a manifest without runs.
pub(super) fn parse_manifest(file: &Path, text: &str) -> Result<Manifest, DatasetError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let top: Table = text.parse().map_err(|err: toml::de::Error| {
        let line = err.span().map_or(1, |span| line_of(text, span.start));
        DatasetError::ManifestSyntax {
            file: file.to_path_buf(),
            line,
            message: err.message().trim_end_matches('.').to_owned(),
        }
    })?;
    check_format(file, top.get("format"))?;
    let raw: RawManifest = serde_path_to_error::deserialize(Value::Table(top.clone()))
        .map_err(|err| type_error(file, &top, err.path()))?;
    let missing = |key: &str| DatasetError::MissingKey { file: file.to_path_buf(), key: key.to_owned() };
    let checked = |key: &str, value: Option<Number>, rule: Rule| -> Result<Option<f64>, DatasetError> {
        value.map(|Number(value)| check_number(file, key, value, rule)).transpose()
    };
    let tunnel = raw.tunnel.ok_or_else(|| missing("tunnel"))?;
    let tunnel = Tunnel {
        u_inf_mps: checked("tunnel.u_inf_mps", tunnel.u_inf_mps, Rule::Positive)?
            .ok_or_else(|| missing("tunnel.u_inf_mps"))?,
        rho_kgm3: checked("tunnel.rho_kgm3", tunnel.rho_kgm3, Rule::Positive)?
            .ok_or_else(|| missing("tunnel.rho_kgm3"))?,
    };
    let wing = match raw.wing {
        None => Wing::PAPER,
        Some(wing) => {
            let paper = Wing::PAPER;
            let get = |name: &str, value: Option<Number>, default: f64| {
                Ok::<_, DatasetError>(checked(&format!("wing.{name}"), value, Rule::Positive)?.unwrap_or(default))
            };
            Wing {
                chord_m: get("chord_m", wing.chord_m, paper.chord_m)?,
                span_m: get("span_m", wing.span_m, paper.span_m)?,
                area_m2: get("area_m2", wing.area_m2, paper.area_m2)?,
                ixx_kgm2: get("ixx_kgm2", wing.ixx_kgm2, paper.ixx_kgm2)?,
                mass_kg: get("mass_kg", wing.mass_kg, paper.mass_kg)?,
            }
        }
    };
    let runs =
        raw.run.filter(|runs| !runs.is_empty()).ok_or_else(|| DatasetError::NoRuns { file: file.to_path_buf() })?;
    let tables = top.get("run").and_then(Value::as_array).map_or(&[][..], Vec::as_slice);
    let runs = runs
        .into_iter()
        .zip(tables)
        .enumerate()
        .map(|(index, (run, table))| run_meta(file, index + 1, run, extra_keys(table, &RUN_KEYS)))
        .collect::<Result<_, _>>()?;
    let extra = extra_keys(&Value::Table(top), &TOP_KEYS);
    Ok(Manifest { tunnel, wing, extra, runs })
}

/// The keys of `table` other than the format's `keys`.
fn extra_keys(table: &Value, keys: &[&str]) -> Table {
    let mut extra = table.as_table().cloned().unwrap_or_default();
    extra.retain(|key, _| !keys.contains(&key));
    extra
}

/// The `run_index`-th (1-based) `[[run]]` table, checked.
fn run_meta(file: &Path, run_index: usize, run: RawRun, extra: Table) -> Result<RunMeta, DatasetError> {
    let key = |name: &str| run_key(run_index, name);
    let missing = |name: &str| DatasetError::MissingKey { file: file.to_path_buf(), key: key(name) };
    let run_file = run.file.ok_or_else(|| missing("file"))?;
    if run_file.trim().is_empty() {
        return Err(DatasetError::BadValue {
            file: file.to_path_buf(),
            key: key("file"),
            expected: "a path relative to the manifest",
            found: Value::String(run_file).to_string(),
        });
    }
    let kind_text = run.kind.ok_or_else(|| missing("kind"))?;
    let kind = RunKind::parse(&kind_text).ok_or_else(|| DatasetError::UnknownKind {
        file: file.to_path_buf(),
        run_index,
        found: kind_text.clone(),
    })?;
    let number = |name: &str, value: Option<Number>, rule: Rule| {
        let Number(value) = value.ok_or_else(|| missing(name))?;
        check_number(file, &key(name), value, rule)
    };
    Ok(RunMeta {
        file: PathBuf::from(run_file),
        kind,
        alpha_deg: number("alpha_deg", run.alpha_deg, Rule::Finite)?,
        sample_hz: number("sample_hz", run.sample_hz, Rule::Positive)?,
        extra,
    })
}

/// The error for a value of the wrong type at serde's `path`: the key as the format names it
/// (`run[N].key`, `N` 1-based), what the key must hold, and the value as written.
fn type_error(file: &Path, top: &Table, path: &serde_path_to_error::Path) -> DatasetError {
    use serde_path_to_error::Segment;
    let mut key = String::new();
    let mut value: Option<&Value> = None;
    let mut in_run = false;
    for segment in path.iter() {
        match segment {
            Segment::Seq { index } => {
                key.push_str(&format!("[{}]", index + 1));
                value = value.and_then(|v| v.as_array()).and_then(|items| items.get(*index));
            }
            Segment::Map { key: name } | Segment::Enum { variant: name } => {
                if !key.is_empty() {
                    key.push('.');
                }
                key.push_str(name);
                value = match value {
                    None if key == *name => top.get(name),
                    Some(Value::Table(table)) => table.get(name),
                    _ => None,
                };
                in_run |= name == "run";
            }
            Segment::Unknown => {}
        }
    }
    let name = key.rsplit(['.', '[']).next().unwrap_or_default();
    let expected = match name {
        "tunnel" | "wing" => "a table",
        "run" => "an array of [[run]] tables",
        _ if key.ends_with(']') => "a [[run]] table",
        "file" | "kind" if in_run => "a string",
        "u_inf_mps" | "rho_kgm3" | "sample_hz" => Rule::Positive.expected(),
        "alpha_deg" => Rule::Finite.expected(),
        _ if key.starts_with("wing.") => Rule::Positive.expected(),
        _ => "a value of the format's type",
    };
    let found = value.map_or_else(|| "a value of another type".to_owned(), Value::to_string);
    DatasetError::BadValue { file: file.to_path_buf(), key, expected, found }
}

/// The 1-based line of byte offset `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    let offset = offset.min(text.len());
    text.as_bytes()[..offset].iter().filter(|&&byte| byte == b'\n').count() + 1
}

/// Checks that `format` is exactly [`FORMAT`].
fn check_format(file: &Path, value: Option<&Value>) -> Result<(), DatasetError> {
    match value {
        None => Err(DatasetError::MissingKey { file: file.to_path_buf(), key: "format".into() }),
        Some(Value::String(text)) if text == FORMAT => Ok(()),
        Some(other) => Err(DatasetError::WrongFormat { file: file.to_path_buf(), found: other.to_string() }),
    }
}

/// Checks the numbers and extra keys of `dataset` by the rules of [`parse_manifest`], so that
/// what is written loads again. `file` is the manifest that would be written.
///
/// # Errors
/// Out-of-range numbers, extra keys named like format keys, and a dataset without runs.
pub(super) fn validate(file: &Path, dataset: &Dataset) -> Result<(), DatasetError> {
    let Tunnel { u_inf_mps, rho_kgm3 } = dataset.tunnel;
    check_number(file, "tunnel.u_inf_mps", u_inf_mps, Rule::Positive)?;
    check_number(file, "tunnel.rho_kgm3", rho_kgm3, Rule::Positive)?;
    for (name, value) in wing_entries(&dataset.wing) {
        check_number(file, &format!("wing.{name}"), value, Rule::Positive)?;
    }
    reserved(file, &dataset.extra, &TOP_KEYS, "")?;
    if dataset.runs.is_empty() {
        return Err(DatasetError::NoRuns { file: file.to_path_buf() });
    }
    for (index, run) in dataset.runs.iter().enumerate() {
        let meta = &run.meta;
        check_number(file, &run_key(index + 1, "alpha_deg"), meta.alpha_deg, Rule::Finite)?;
        check_number(file, &run_key(index + 1, "sample_hz"), meta.sample_hz, Rule::Positive)?;
        reserved(file, &meta.extra, &RUN_KEYS, &format!("run[{}].", index + 1))?;
    }
    Ok(())
}

/// Refuses an extra key of `extra` named like one of `keys`.
fn reserved(file: &Path, extra: &Table, keys: &[&str], prefix: &str) -> Result<(), DatasetError> {
    match extra.keys().find(|key| keys.contains(&key.as_str())) {
        Some(key) => Err(DatasetError::ReservedKey { file: file.to_path_buf(), key: format!("{prefix}{key}") }),
        None => Ok(()),
    }
}

/// The `[wing]` keys and values, in the spec's order.
fn wing_entries(wing: &Wing) -> [(&'static str, f64); 5] {
    [
        ("chord_m", wing.chord_m),
        ("span_m", wing.span_m),
        ("area_m2", wing.area_m2),
        ("ixx_kgm2", wing.ixx_kgm2),
        ("mass_kg", wing.mass_kg),
    ]
}

/// Serializes the manifest of `dataset`; `run_files` are the runs' files as written in the
/// manifest (relative, `/`-separated). `file` is the manifest, for error messages.
///
/// # Errors
/// [`DatasetError::ManifestWrite`] when an extra value cannot be serialized.
pub(super) fn manifest_text(file: &Path, dataset: &Dataset, run_files: &[String]) -> Result<String, DatasetError> {
    let mut out = format!("format = {}\n", Value::String(FORMAT.into()));
    out.push_str(&to_toml(file, &dataset.extra)?);
    let Tunnel { u_inf_mps, rho_kgm3 } = dataset.tunnel;
    out.push_str("\n[tunnel]\n");
    push_entries(&mut out, &[("u_inf_mps", u_inf_mps), ("rho_kgm3", rho_kgm3)]);
    out.push_str("\n[wing]\n");
    push_entries(&mut out, &wing_entries(&dataset.wing));
    for (run, run_file) in dataset.runs.iter().zip(run_files) {
        push_run(file, &mut out, &run.meta, run_file)?;
    }
    Ok(out)
}

/// Serializes `table` as a TOML document.
fn to_toml(file: &Path, table: &Table) -> Result<String, DatasetError> {
    toml::to_string(table)
        .map_err(|err| DatasetError::ManifestWrite { file: file.to_path_buf(), message: err.to_string() })
}

/// Appends the `[[run]]` table of `meta`, whose file is written as `run_file`.
fn push_run(file: &Path, out: &mut String, meta: &RunMeta, run_file: &str) -> Result<(), DatasetError> {
    out.push_str("\n[[run]]\n");
    out.push_str(&format!("file = {}\n", Value::String(run_file.into())));
    out.push_str(&format!("kind = {}\n", Value::String(meta.kind.as_str().into())));
    push_entries(out, &[("alpha_deg", meta.alpha_deg), ("sample_hz", meta.sample_hz)]);
    // The extra keys are serialized inside a one-element `run` array so that nested tables come
    // out as `[run.name]`; its leading `[[run]]` header is the one written above.
    let mut wrapper = Table::new();
    let tables = vec![Value::Table(meta.extra.clone())];
    wrapper.insert("run".into(), Value::Array(tables));
    let extra = to_toml(file, &wrapper)?;
    let keys = extra.strip_prefix("[[run]]\n").ok_or_else(|| DatasetError::ManifestWrite {
        file: file.to_path_buf(),
        message: format!("unexpected serialization of run keys: {extra:?}"),
    })?;
    out.push_str(keys);
    Ok(())
}

/// Appends `key = value` lines of floats.
fn push_entries(out: &mut String, entries: &[(&str, f64)]) {
    for (key, value) in entries {
        out.push_str(&format!("{key} = {}\n", Value::Float(*value)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "data/manifest.toml";

    fn parse(text: &str) -> Result<Manifest, DatasetError> {
        parse_manifest(Path::new(FILE), text)
    }

    fn message(text: &str) -> String {
        match parse(text) {
            Ok(manifest) => panic!("expected an error, parsed {manifest:?}"),
            Err(err) => err.to_string(),
        }
    }

    const MINIMAL: &str = r#"
format = "roll-dataset/1"
[tunnel]
u_inf_mps = 6.5
rho_kgm3 = 1.2
[[run]]
file = "runs/roll_a10.csv"
kind = "roll"
alpha_deg = 10
sample_hz = 1000.0
"#;

    /// A value of the wrong type is named by its key as the format writes it (`run[N]`
    /// 1-based), with what the key must hold and the value as written.
    #[test]
    fn a_value_of_the_wrong_type_is_named_by_its_key() {
        let cases = [
            (
                MINIMAL.replace("rho_kgm3 = 1.2", "rho_kgm3 = \"dense\""),
                "key tunnel.rho_kgm3: expected a finite number greater than zero, found \"dense\"",
            ),
            (
                MINIMAL.replace("[tunnel]\nu_inf_mps = 6.5\nrho_kgm3 = 1.2\n", "tunnel = 5\n"),
                "key tunnel: expected a table, found 5",
            ),
            (
                MINIMAL.replace("[[run]]", "[wing]\nspan_m = [1]\n[[run]]"),
                "key wing.span_m: expected a finite number greater than zero, found [1]",
            ),
            (
                format!("{MINIMAL}[[run]]\nfile = 7\nkind = \"roll\"\nalpha_deg = 0\nsample_hz = 1000\n"),
                "key run[2].file: expected a string, found 7",
            ),
            (
                MINIMAL.replace("sample_hz = 1000.0", "sample_hz = true"),
                "key run[1].sample_hz: expected a finite number greater than zero, found true",
            ),
        ];
        for (text, expected) in cases {
            assert_eq!(message(&text), format!("{FILE}: {expected}"));
        }
        let runs = MINIMAL.split("[[run]]").next().unwrap().replace("[tunnel]", "run = 3\n[tunnel]");
        assert_eq!(message(&runs), format!("{FILE}: key run: expected an array of [[run]] tables, found 3"));
    }

    #[test]
    fn minimal_manifest_defaults_wing_and_accepts_integers() {
        let manifest = parse(MINIMAL).unwrap();
        assert_eq!(manifest.tunnel, Tunnel { u_inf_mps: 6.5, rho_kgm3: 1.2 });
        assert_eq!(manifest.wing, Wing::PAPER);
        assert!(manifest.extra.is_empty());
        assert_eq!(manifest.runs.len(), 1);
        let run = &manifest.runs[0];
        assert_eq!(run.file, PathBuf::from("runs/roll_a10.csv"));
        assert_eq!(run.kind, RunKind::Roll);
        assert_eq!(run.alpha_deg.to_bits(), 10.0_f64.to_bits());
        assert_eq!(run.sample_hz.to_bits(), 1000.0_f64.to_bits());
    }

    #[test]
    fn partial_wing_keeps_paper_values_for_absent_keys() {
        let text = MINIMAL.replace("[[run]]", "[wing]\nspan_m = 0.5\nmass_kg = 1\n[[run]]");
        let wing = parse(&text).unwrap().wing;
        assert_eq!(wing, Wing { span_m: 0.5, mass_kg: 1.0, ..Wing::PAPER });
    }

    #[test]
    fn extra_keys_are_kept_at_top_level_and_in_runs() {
        let text = format!("campaign = \"c1\"\n{MINIMAL}notes = \"gusty\"\nseed = 7\n");
        let manifest = parse(&text).unwrap();
        assert_eq!(manifest.extra.get("campaign"), Some(&Value::String("c1".into())));
        assert_eq!(manifest.extra.len(), 1);
        let extra = &manifest.runs[0].extra;
        assert_eq!(extra.get("notes"), Some(&Value::String("gusty".into())));
        assert_eq!(extra.get("seed"), Some(&Value::Integer(7)));
        assert_eq!(extra.len(), 2);
    }

    #[test]
    fn bom_is_ignored() {
        assert!(parse(&format!("\u{feff}{MINIMAL}")).is_ok());
    }

    #[test]
    fn syntax_error_names_line() {
        let text = MINIMAL.replace("rho_kgm3 = 1.2", "rho_kgm3 = = 1.2");
        let msg = message(&text);
        assert!(msg.starts_with("data/manifest.toml: line 5: expected valid TOML"), "{msg}");
    }

    #[test]
    fn missing_and_wrong_format() {
        let msg = message(&MINIMAL.replace("format = \"roll-dataset/1\"", ""));
        assert_eq!(msg, "data/manifest.toml: key format: expected a value, found no such key");
        let msg = message(&MINIMAL.replace("roll-dataset/1", "roll-dataset/2"));
        assert_eq!(msg, "data/manifest.toml: key format: expected \"roll-dataset/1\", found \"roll-dataset/2\"");
    }

    #[test]
    fn missing_keys_are_named() {
        let msg = message(&MINIMAL.replace("rho_kgm3 = 1.2", ""));
        assert!(msg.contains("key tunnel.rho_kgm3: expected a value"), "{msg}");
        let msg = message(&MINIMAL.replace("sample_hz = 1000.0", ""));
        assert!(msg.contains("key run[1].sample_hz: expected a value"), "{msg}");
        let msg = message(&MINIMAL.replace("file = \"runs/roll_a10.csv\"", ""));
        assert!(msg.contains("key run[1].file: expected a value"), "{msg}");
        let tunnel = MINIMAL.replace("[tunnel]\nu_inf_mps = 6.5\nrho_kgm3 = 1.2\n", "");
        assert!(message(&tunnel).contains("key tunnel: expected a value"));
    }

    #[test]
    fn bad_values_are_named() {
        let msg = message(&MINIMAL.replace("sample_hz = 1000.0", "sample_hz = -5"));
        assert_eq!(
            msg,
            "data/manifest.toml: key run[1].sample_hz: expected a finite number greater than \
             zero, found -5.0"
        );
        let msg = message(&MINIMAL.replace("alpha_deg = 10", "alpha_deg = nan"));
        assert!(msg.contains("key run[1].alpha_deg: expected a finite number, found nan"), "{msg}");
        let msg = message(&MINIMAL.replace("u_inf_mps = 6.5", "u_inf_mps = \"fast\""));
        assert!(msg.contains("key tunnel.u_inf_mps: expected a finite number greater"), "{msg}");
        let msg = message(&MINIMAL.replace("[[run]]", "[wing]\narea_m2 = 0\n[[run]]"));
        assert!(msg.contains("key wing.area_m2: expected a finite number greater"), "{msg}");
    }

    #[test]
    fn unknown_kind_names_run_and_kind() {
        let msg = message(&MINIMAL.replace("kind = \"roll\"", "kind = \"rolling\""));
        assert!(msg.starts_with("data/manifest.toml: key run[1].kind: expected one of"), "{msg}");
        assert!(msg.ends_with("found \"rolling\""), "{msg}");
    }

    #[test]
    fn manifest_without_runs_is_refused() {
        let text = MINIMAL.split("[[run]]").next().unwrap_or_default();
        assert_eq!(message(text), "data/manifest.toml: key run: expected at least one [[run]] table, found none");
    }

    fn dataset(manifest: Manifest) -> Dataset {
        let runs = manifest
            .runs
            .into_iter()
            .map(|meta| super::super::Run { meta, channels: super::super::Channels::default() })
            .collect();
        Dataset { tunnel: manifest.tunnel, wing: manifest.wing, extra: manifest.extra, runs }
    }

    #[test]
    fn written_manifest_parses_back_equal() {
        let head = MINIMAL.replace("[tunnel]", "campaign = \"c1\"\n[lab]\nname = \"fejer\"\n[tunnel]");
        let text = format!(
            "{head}notes = \"x\"\n[run.daq]\nid = 3\n\
             [[run]]\nfile = \"runs/act.csv\"\nkind = \"roll+actuation\"\nalpha_deg = -2.5e-3\n\
             sample_hz = 333.3\n"
        );
        let original = parse(&text).unwrap();
        let ds = dataset(original.clone());
        let files: Vec<String> = ds.runs.iter().map(|run| run.meta.file.display().to_string()).collect();
        let written = manifest_text(Path::new(FILE), &ds, &files).unwrap();
        assert!(written.starts_with("format = \"roll-dataset/1\"\n"), "{written}");
        assert_eq!(parse(&written).unwrap(), original, "{written}");
        assert_eq!(original.runs[0].extra["daq"]["id"], Value::Integer(3));
        assert_eq!(original.extra["lab"]["name"], Value::String("fejer".into()));
        assert_eq!(original.runs[1].kind, RunKind::RollActuation);
    }

    #[test]
    fn validate_refuses_reserved_extra_keys_and_bad_numbers() {
        let mut ds = dataset(parse(MINIMAL).unwrap());
        ds.runs[0].meta.extra.insert("kind".into(), Value::Integer(1));
        let msg = validate(Path::new(FILE), &ds).unwrap_err().to_string();
        assert!(msg.contains("key run[1].kind: expected an extra key"), "{msg}");
        ds.runs[0].meta.extra.clear();
        ds.runs[0].meta.sample_hz = f64::INFINITY;
        let msg = validate(Path::new(FILE), &ds).unwrap_err().to_string();
        assert!(msg.contains("key run[1].sample_hz: expected a finite number greater"), "{msg}");
        ds.runs[0].meta.sample_hz = 1.0;
        ds.extra.insert("wing".into(), Value::Integer(1));
        let msg = validate(Path::new(FILE), &ds).unwrap_err().to_string();
        assert!(msg.contains("key wing: expected an extra key"), "{msg}");
    }
}
