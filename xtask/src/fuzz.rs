//! A seeded, structure-aware mutation fuzzer for every loader (`cargo xtask fuzz`): the dataset's
//! run files (CSV) and manifest, the coefficient blob, and scenario files.
//!
//! cargo-fuzz needs a nightly toolchain and libFuzzer, which the pinned stable toolchain of this
//! workspace does not have; this is the property-based equivalent that runs in CI on stable.
//! Every execution starts from a valid input of the target (a corpus built here), stacks one to
//! four mutations (generic byte mutations, and the target's own: columns and lines of a CSV
//! removed, duplicated or swapped, TOML values replaced by NaN, infinities, huge or ill-typed
//! values, blob payloads mutated and re-sealed with a correct length and CRC so that decoding
//! and validation are reached), and calls the loader's in-memory entry point (the same code the
//! file loaders run) under `catch_unwind`. A finding is a panic, an input slower than the time
//! limit, or a result that breaks the loader's contract (an error that does not name the file,
//! a loaded run with columns of different lengths, a loaded blob whose step is not finite).
//!
//! Execution `i` draws its mutations from `ChaCha8(mix_seed(seed, i))`: a run is reproducible
//! and does not depend on how rayon schedules it.

use std::collections::BTreeMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::time::{Duration, Instant};

use estimator_core::blob::{self, HEADER_LEN};
use firmware_sim::campaign::{Scenario, mix_seed};
use firmware_sim::dataset::{N_TAPS, RunKind, RunMeta, Tunnel, Wing, parse_manifest_bytes, parse_run};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Serialize;

/// What is fuzzed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    /// A run file (`firmware_sim::dataset::parse_run`).
    DatasetCsv,
    /// A manifest (`firmware_sim::dataset::parse_manifest_bytes`).
    Manifest,
    /// A coefficient blob (`estimator_core::blob::decode`), after every single-bit flip of the
    /// valid blob.
    Blob,
    /// A scenario file (`Scenario::from_bytes`, then `validate`).
    Scenario,
}

/// How long and how hard to fuzz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FuzzConfig {
    /// The loader.
    pub target: Target,
    /// Mutated inputs to try.
    pub execs: u64,
    /// Seed of the mutations.
    pub seed: u64,
    /// An input that takes longer than this is a finding (a hang or a quadratic blow-up).
    pub time_limit: Duration,
}

/// One input that broke the loader's contract.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// Index of the execution (reproduce with the same seed).
    pub exec_idx: u64,
    /// What went wrong.
    pub what: String,
    /// The input, lossily as text (at most 2,000 bytes).
    pub input: String,
}

/// The result of a fuzzing run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FuzzOutcome {
    /// The loader.
    pub target: Target,
    /// The seed.
    pub seed: u64,
    /// Inputs tried (for the blob: the random executions plus every single-bit flip).
    pub execs: u64,
    /// Inputs the loader accepted.
    pub accepted: u64,
    /// Inputs the loader rejected with a typed error.
    pub rejected: u64,
    /// How often each error variant was returned (shows how deep the mutations reach).
    pub errors: BTreeMap<String, u64>,
    /// Panics, slow inputs and contract violations (at most 20 kept).
    pub findings: Vec<Finding>,
    /// Number of findings in all.
    pub n_findings: u64,
    /// The slowest single input, µs.
    pub slowest_exec_us: u64,
    /// Wall time, s.
    pub elapsed_s: f64,
}

/// What the loader did with one input.
enum Verdict {
    Accepted,
    Rejected(String),
    Broken(String),
}

/// Findings kept in the outcome.
const MAX_FINDINGS: usize = 20;

impl Target {
    /// Every target, in the order of the command line's help.
    pub const ALL: [Self; 4] = [Self::DatasetCsv, Self::Manifest, Self::Blob, Self::Scenario];

    /// The name on the command line.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::DatasetCsv => "dataset-csv",
            Self::Manifest => "manifest",
            Self::Blob => "blob",
            Self::Scenario => "scenario",
        }
    }
}

impl std::str::FromStr for Target {
    type Err = String;

    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Self::ALL.into_iter().find(|target| target.name() == name).ok_or_else(|| {
            let names: Vec<&str> = Self::ALL.iter().map(|target| target.name()).collect();
            format!("unknown fuzz target `{name}`; expected one of {}", names.join(", "))
        })
    }
}

/// Runs the fuzzer; `on_progress` is called with the number of executions done every 10,000.
#[must_use]
pub fn fuzz(config: &FuzzConfig, on_progress: &(dyn Fn(u64) + Sync)) -> FuzzOutcome {
    let started = Instant::now();
    let corpus = corpus(config.target);
    let mut outcome = outcome_template(config);
    if config.target == Target::Blob {
        outcome.merge(every_bit_flip(&corpus[0], config.time_limit));
    }
    let chunk = 10_000u64;
    let n_chunks = config.execs.div_ceil(chunk);
    let done = std::sync::atomic::AtomicU64::new(0);
    let partials: Vec<FuzzOutcome> = (0..n_chunks)
        .into_par_iter()
        .map(|chunk_idx| {
            let range = chunk_idx * chunk..((chunk_idx + 1) * chunk).min(config.execs);
            let mut partial = outcome_template(config);
            for exec_idx in range {
                let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(config.seed, exec_idx));
                let input = mutated(config.target, &corpus, &mut rng);
                partial.record(exec_idx, &input, run_once(config.target, &input), config.time_limit);
            }
            let so_far = done.fetch_add(partial.execs, std::sync::atomic::Ordering::Relaxed) + partial.execs;
            on_progress(so_far);
            partial
        })
        .collect();
    for partial in partials {
        outcome.merge(partial);
    }
    outcome.elapsed_s = started.elapsed().as_secs_f64();
    outcome
}

/// An empty outcome for `config`'s target and seed.
fn outcome_template(config: &FuzzConfig) -> FuzzOutcome {
    FuzzOutcome {
        target: config.target,
        seed: config.seed,
        execs: 0,
        accepted: 0,
        rejected: 0,
        errors: BTreeMap::new(),
        findings: Vec::new(),
        n_findings: 0,
        slowest_exec_us: 0,
        elapsed_s: 0.0,
    }
}

/// Every single-bit flip of the valid blob must be rejected (the CRC and the header checks).
fn every_bit_flip(valid: &[u8], time_limit: Duration) -> FuzzOutcome {
    let config = FuzzConfig { target: Target::Blob, execs: 0, seed: 0, time_limit };
    let mut outcome = outcome_template(&config);
    for bit in 0..valid.len() * 8 {
        let mut flipped = valid.to_vec();
        flipped[bit / 8] ^= 1 << (bit % 8);
        let timed = run_once(Target::Blob, &flipped);
        let timed = match timed.0 {
            Verdict::Accepted => (Verdict::Broken(format!("single-bit flip {bit} was accepted")), timed.1),
            other => (other, timed.1),
        };
        outcome.record(bit as u64, &flipped, timed, time_limit);
    }
    outcome
}

impl FuzzOutcome {
    fn record(&mut self, exec_idx: u64, input: &[u8], (verdict, took): (Verdict, Duration), time_limit: Duration) {
        self.execs += 1;
        self.slowest_exec_us = self.slowest_exec_us.max(took.as_micros() as u64);
        let broken = match verdict {
            Verdict::Accepted => {
                self.accepted += 1;
                None
            }
            Verdict::Rejected(kind) => {
                self.rejected += 1;
                *self.errors.entry(kind).or_default() += 1;
                None
            }
            Verdict::Broken(what) => Some(what),
        };
        let slow = (took > time_limit).then(|| format!("took {} ms", took.as_millis()));
        if let Some(what) = broken.or(slow) {
            self.n_findings += 1;
            if self.findings.len() < MAX_FINDINGS {
                let shown = &input[..input.len().min(2000)];
                self.findings.push(Finding { exec_idx, what, input: String::from_utf8_lossy(shown).into_owned() });
            }
        }
    }

    fn merge(&mut self, other: Self) {
        self.execs += other.execs;
        self.accepted += other.accepted;
        self.rejected += other.rejected;
        for (kind, count) in other.errors {
            *self.errors.entry(kind).or_default() += count;
        }
        self.n_findings += other.n_findings;
        self.findings.extend(other.findings);
        self.findings.truncate(MAX_FINDINGS);
        self.slowest_exec_us = self.slowest_exec_us.max(other.slowest_exec_us);
    }
}

/// Calls the loader of `target` on `input` and checks its contract: `Ok(true)` when it
/// accepted the input, `Ok(false)` when it rejected it with a typed error that names the file,
/// `Err` with what broke otherwise; a panic propagates. The entry point of the cargo-fuzz
/// targets (`fuzz/`), which run it on nightly with libFuzzer.
///
/// # Errors
/// A description of the broken contract.
pub fn check_input(target: Target, input: &[u8]) -> Result<bool, String> {
    match verdict(target, input) {
        Verdict::Accepted => Ok(true),
        Verdict::Rejected(_) => Ok(false),
        Verdict::Broken(what) => Err(what),
    }
}

/// The valid inputs every execution starts from (the seed corpus of the cargo-fuzz targets).
#[must_use]
pub fn seeds(target: Target) -> Vec<Vec<u8>> {
    corpus(target)
}

fn verdict(target: Target, input: &[u8]) -> Verdict {
    match target {
        Target::DatasetCsv => check_run(input),
        Target::Manifest => check_manifest(input),
        Target::Blob => check_blob(input),
        Target::Scenario => check_scenario(input),
    }
}

/// Calls the loader on `input` under `catch_unwind` and checks its contract.
fn run_once(target: Target, input: &[u8]) -> (Verdict, Duration) {
    let started = Instant::now();
    let verdict = catch_unwind(AssertUnwindSafe(|| verdict(target, input))).unwrap_or_else(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|text| (*text).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        Verdict::Broken(format!("panic: {message}"))
    });
    (verdict, started.elapsed())
}

/// The variant name of an error's `Debug` form.
fn variant<E: std::fmt::Debug>(error: &E) -> String {
    let debug = format!("{error:?}");
    debug.split([' ', '{', '(']).next().unwrap_or_default().to_owned()
}

/// A rejection whose message must start with `prefix` (the file it names).
fn named<E: std::fmt::Debug + std::fmt::Display>(error: &E, prefix: &str) -> Verdict {
    let message = error.to_string();
    if message.starts_with(prefix) {
        Verdict::Rejected(variant(error))
    } else {
        Verdict::Broken(format!("error without the file name: {message}"))
    }
}

const RUN_FILE: &str = "runs/fuzz.csv";
const MANIFEST_FILE: &str = "manifest.toml";
const SCENARIO_FILE: &str = "scenario.toml";

fn check_run(input: &[u8]) -> Verdict {
    let meta = RunMeta {
        file: RUN_FILE.into(),
        kind: RunKind::Roll,
        alpha_deg: 10.0,
        sample_hz: 1000.0,
        extra: toml::Table::new(),
    };
    let tunnel = Tunnel { u_inf_mps: 6.5, rho_kgm3: 1.2 };
    match parse_run(Path::new(RUN_FILE), input, meta, &tunnel, &Wing::default()) {
        Err(error) => named(&error, RUN_FILE),
        Ok(run) => {
            let channels = &run.channels;
            let n = channels.len();
            let lengths_agree = n > 0
                && [&channels.phi_deg, &channels.cmu_port, &channels.cmu_stbd, &channels.cl]
                    .iter()
                    .chain(channels.cp.iter().collect::<Vec<_>>().iter())
                    .all(|column| column.len() == n);
            if lengths_agree && channels.t_s.iter().all(|t| t.is_finite()) {
                Verdict::Accepted
            } else {
                Verdict::Broken("a loaded run has columns of different lengths or a non-finite time".into())
            }
        }
    }
}

fn check_manifest(input: &[u8]) -> Verdict {
    match parse_manifest_bytes(Path::new(MANIFEST_FILE), input) {
        Err(error) => named(&error, MANIFEST_FILE),
        Ok(manifest) => {
            let rates_ok = manifest.runs.iter().all(|run| run.sample_hz.is_finite() && run.sample_hz > 0.0);
            if !manifest.runs.is_empty() && rates_ok {
                Verdict::Accepted
            } else {
                Verdict::Broken("a loaded manifest has no run or a non-positive rate".into())
            }
        }
    }
}

fn check_blob(input: &[u8]) -> Verdict {
    match blob::decode(input) {
        Err(error) => Verdict::Rejected(variant(&error)),
        Ok(set) => {
            // A blob that loads must fly: a few steps on a plain input stay finite.
            let mut estimator = estimator_core::Estimator::new(&set);
            let input = estimator_core::Input {
                phi_deg: 5.0,
                alpha_deg: 10.0,
                cmu_port: 0.002,
                cmu_stbd: 0.0,
                cp: [-0.4; N_TAPS],
            };
            let finite = (0..10).all(|_| estimator.step(&input).estimates().iter().all(|value| value.is_finite()));
            if finite { Verdict::Accepted } else { Verdict::Broken("a loaded blob steps to a non-finite value".into()) }
        }
    }
}

fn check_scenario(input: &[u8]) -> Verdict {
    let scenario = Scenario::from_bytes(SCENARIO_FILE, input);
    match scenario.and_then(|scenario| scenario.validate().map(|()| scenario)) {
        Err(error @ firmware_sim::campaign::ScenarioError::Invalid { .. }) => named(&error, "scenario key"),
        Err(error) => named(&error, SCENARIO_FILE),
        Ok(scenario) => {
            let _ = scenario.tunnel_config();
            Verdict::Accepted
        }
    }
}

/// Valid inputs of the target.
fn corpus(target: Target) -> Vec<Vec<u8>> {
    match target {
        Target::DatasetCsv => vec![run_text(false).into_bytes(), run_text(true).into_bytes()],
        Target::Manifest => vec![MANIFEST_MINIMAL.as_bytes().to_vec(), MANIFEST_FULL.as_bytes().to_vec()],
        Target::Blob => {
            let mut bytes = vec![0u8; blob::MAX_BLOB_LEN];
            let len = blob::encode(&estimator_core::coeffs::DEFAULT, &mut bytes).unwrap_or(0);
            bytes.truncate(len);
            vec![bytes]
        }
        Target::Scenario => vec![SCENARIO_README.as_bytes().to_vec(), SCENARIO_FULL.as_bytes().to_vec()],
    }
}

/// A valid run file of 40 samples at 1 kHz; `variant` uses `mx_nm`, the optional columns, CRLF
/// line ends, a byte order mark and missing values.
fn run_text(variant: bool) -> String {
    let taps: Vec<String> = (1..=N_TAPS).map(|tap| format!("cp{tap:02}")).collect();
    let (moment, extra, newline) =
        if variant { ("mx_nm", ",alpha_deg,phi_cmd_deg,cmu_port_cmd,cmu_stbd_cmd", "\r\n") } else { ("cl", "", "\n") };
    let mut text = if variant { "\u{feff}".to_owned() } else { String::new() };
    text.push_str(&format!("t_s,phi_deg,cmu_port,cmu_stbd,{},{moment}{extra}{newline}", taps.join(",")));
    for k in 0..40 {
        let t_s = k as f64 * 1e-3;
        let cps: Vec<String> =
            (0..N_TAPS).map(|tap| format!("{:.4}", -0.5 + 0.03 * tap as f64 + 1e-3 * k as f64)).collect();
        let missing = variant && k % 7 == 3;
        let phi = if missing { String::new() } else { format!("{:.3}", 10.0 * (k as f64 * 0.05).sin()) };
        text.push_str(&format!(
            "{t_s},{phi},0.002,{},{},{:.5}",
            if missing { "nan" } else { "0" },
            cps.join(","),
            0.01
        ));
        if variant {
            text.push_str(&format!(",10,{phi},0.002,0"));
        }
        text.push_str(newline);
    }
    text
}

const MANIFEST_MINIMAL: &str = r#"format = "roll-dataset/1"
[tunnel]
u_inf_mps = 6.5
rho_kgm3 = 1.2
[[run]]
file = "runs/roll_a10.csv"
kind = "roll"
alpha_deg = 10
sample_hz = 1000.0
"#;

const MANIFEST_FULL: &str = r#"format = "roll-dataset/1"
campaign = "fuzz"
[tunnel]
u_inf_mps = 6.5
rho_kgm3 = 1.2
[wing]
span_m = 0.5
chord_m = 0.4
area_m2 = 0.12
ixx_kgm2 = 0.01
mass_kg = 1.0
[[run]]
file = "runs/roll_a0.csv"
kind = "roll"
alpha_deg = 0.0
sample_hz = 1000.0
notes = "calm"
[[run]]
file = "runs/actuation_a10.csv"
kind = "actuation"
alpha_deg = 10.0
sample_hz = 1000
[[run]]
file = "runs/rollact_a20.csv"
kind = "roll+actuation"
alpha_deg = 20.0
sample_hz = 500.0
seed = 7
"#;

const SCENARIO_README: &str = r"seed = 7
alphas_deg = [0, 10, 20]
[aero]
clp = -0.2
[effects.actuator_delay]
delay_s = 0.03
[effects.inertial_tare]
";

const SCENARIO_FULL: &str = r#"seed = 3
duration_s = 5.0
sample_hz = 1000.0
alphas_deg = [5.0, 15.0]
kinds = ["roll", "actuation", "roll+actuation"]
blowing_sides = "both"
[tunnel]
u_inf_mps = 6.5
rho_kgm3 = 1.2
[wing]
span_m = 0.5
[effects.pressure_fault]
channel = 3
mode = "stuck"
start_s = 1.0
[effects.vortex_lag]
[effects.coupling]
"#;

/// A corpus input with one to four mutations of the target's kinds.
fn mutated(target: Target, corpus: &[Vec<u8>], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut data = corpus[rng.random_range(0..corpus.len())].clone();
    for _ in 0..rng.random_range(1..=4) {
        match (target, rng.random_range(0..3)) {
            (_, 0) => mutate_bytes(&mut data, rng),
            (Target::DatasetCsv, _) => mutate_csv(&mut data, rng),
            (Target::Manifest | Target::Scenario, _) => mutate_toml(&mut data, rng),
            (Target::Blob, _) => mutate_payload_and_reseal(&mut data, rng),
        }
    }
    data
}

/// Tokens that break parsers: special numbers, separators, quotes, bad UTF-8.
const TOKENS: [&str; 24] = [
    "nan",
    "inf",
    "-inf",
    "1e309",
    "-1e309",
    "1e-400",
    "99999999999999999999",
    "-0",
    "0",
    "-1",
    "\u{feff}",
    "\u{ff}",
    "\"",
    "\"\"",
    ",",
    "\n",
    "\r",
    "=",
    "[[run]]",
    "[",
    "0x10",
    "1_000",
    "  ",
    "\u{0}",
];

fn token(rng: &mut ChaCha8Rng) -> Vec<u8> {
    if rng.random_bool(0.1) {
        // Invalid UTF-8.
        return vec![0xff, 0xfe, 0xc3];
    }
    TOKENS[rng.random_range(0..TOKENS.len())].as_bytes().to_vec()
}

/// Generic byte mutations.
fn mutate_bytes(data: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    if data.is_empty() {
        data.extend(token(rng));
        return;
    }
    let at = rng.random_range(0..data.len());
    let span = rng.random_range(1..=16).min(data.len() - at);
    match rng.random_range(0..8) {
        0 => data[at] ^= 1 << rng.random_range(0..8),
        1 => data[at] = [0, 0xff, b',', b'\n', b'"', b'=', b'.', b'-', b'e', b'9'][rng.random_range(0..10)],
        2 => drop(data.drain(at..at + span)),
        3 => {
            let bytes: Vec<u8> = (0..rng.random_range(1..=8)).map(|_| rng.random()).collect();
            data.splice(at..at, bytes);
        }
        4 => drop(data.splice(at..at, token(rng))),
        5 => {
            let copy = data[at..at + span].to_vec();
            data.splice(at..at, copy);
        }
        6 => data.truncate(at),
        _ => drop(data.splice(at..at + span, token(rng))),
    }
}

/// Splits into lines of comma-separated fields (bytes, `\n` only).
fn lines_and_fields(data: &[u8]) -> Vec<Vec<Vec<u8>>> {
    data.split(|&byte| byte == b'\n')
        .map(|line| line.split(|&byte| byte == b',').map(<[u8]>::to_vec).collect())
        .collect()
}

fn join_lines(lines: &[Vec<Vec<u8>>]) -> Vec<u8> {
    let joined: Vec<Vec<u8>> = lines.iter().map(|fields| fields.join(&b","[..])).collect();
    joined.join(&b"\n"[..])
}

/// CSV mutations: whole columns and lines, single fields, header names.
fn mutate_csv(data: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    let mut lines = lines_and_fields(data);
    let n_lines = lines.len();
    let line = rng.random_range(0..n_lines);
    let n_fields = lines[0].len().max(1);
    let column = rng.random_range(0..n_fields);
    match rng.random_range(0..8) {
        0 => lines.iter_mut().filter(|fields| column < fields.len()).for_each(|fields| drop(fields.remove(column))),
        1 => lines.iter_mut().filter(|fields| column < fields.len()).for_each(|fields| {
            let copy = fields[column].clone();
            fields.push(copy);
        }),
        2 => {
            let field = rng.random_range(0..lines[line].len().max(1)).min(lines[line].len().saturating_sub(1));
            if let Some(cell) = lines[line].get_mut(field) {
                *cell = token(rng);
            }
        }
        3 => drop(lines.remove(line)),
        4 => {
            let copy = lines[line].clone();
            lines.insert(line, copy);
        }
        5 => lines.swap(line, rng.random_range(0..n_lines)),
        6 => {
            let other = rng.random_range(0..n_fields);
            if let (Some(name), true) = (lines[0].get(other).cloned(), column < lines[0].len()) {
                lines[0][column] = name;
            }
        }
        _ => lines[line].push(token(rng)),
    }
    *data = join_lines(&lines);
}

/// Values a TOML key may be given: special, huge, ill-typed.
const TOML_VALUES: [&str; 20] = [
    "nan",
    "inf",
    "-inf",
    "1e400",
    "-1",
    "0",
    "-0.0",
    "1e-320",
    "\"x\"",
    "[]",
    "[1, 2]",
    "{ a = 1 }",
    "true",
    "99999999999999999999",
    "18446744073709551615",
    "1.5",
    "\"roll\"",
    "\"roll+actuation\"",
    "[nan]",
    "\"\"",
];

/// TOML mutations: lines deleted, duplicated or swapped, values replaced, keys renamed, tables
/// inserted.
fn mutate_toml(data: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    let mut lines: Vec<Vec<u8>> = data.split(|&byte| byte == b'\n').map(<[u8]>::to_vec).collect();
    let keys: Vec<Vec<u8>> = lines
        .iter()
        .filter_map(|line| line.iter().position(|&byte| byte == b'=').map(|at| line[..at].trim_ascii().to_vec()))
        .collect();
    let line = rng.random_range(0..lines.len());
    let equals = lines[line].iter().position(|&byte| byte == b'=');
    match rng.random_range(0..7) {
        0 => drop(lines.remove(line)),
        1 => {
            let copy = lines[line].clone();
            lines.insert(line, copy);
        }
        2 | 3 => {
            if let Some(at) = equals {
                let value = TOML_VALUES[rng.random_range(0..TOML_VALUES.len())].as_bytes();
                lines[line].truncate(at + 1);
                lines[line].push(b' ');
                lines[line].extend_from_slice(value);
            }
        }
        4 => {
            if let (Some(at), false) = (equals, keys.is_empty()) {
                let key = keys[rng.random_range(0..keys.len())].clone();
                lines[line].splice(..at, key);
            }
        }
        5 => {
            let other = rng.random_range(0..lines.len());
            lines.swap(line, other);
        }
        _ => {
            let tables = ["[tunnel]", "[[run]]", "[wing]", "[aero]", "[rig]", "[effects.coupling]", "[excitation]"];
            lines.insert(line, tables[rng.random_range(0..tables.len())].as_bytes().to_vec());
        }
    }
    *data = lines.join(&b"\n"[..]);
}

/// Mutates the blob's payload, then rewrites the header's length and CRC so that the blob
/// passes the integrity checks and reaches the decoder and the validation.
fn mutate_payload_and_reseal(data: &mut Vec<u8>, rng: &mut ChaCha8Rng) {
    if data.len() <= HEADER_LEN {
        return;
    }
    let mut payload = data.split_off(HEADER_LEN);
    if rng.random_bool(0.5) && payload.len() >= 4 {
        // An f32 field set to a special value (postcard writes f32 as 4 little-endian bytes).
        let at = rng.random_range(0..=payload.len() - 4);
        let value = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1e30, -1e30, 0.0, -1.0, f32::MIN_POSITIVE]
            [rng.random_range(0..8)];
        payload[at..at + 4].copy_from_slice(&value.to_le_bytes());
    } else {
        mutate_bytes(&mut payload, rng);
    }
    let len = u32::try_from(payload.len()).unwrap_or(u32::MAX);
    data[10..14].copy_from_slice(&len.to_le_bytes());
    data[14..18].copy_from_slice(&crc32(&payload).to_le_bytes());
    data.extend(payload);
}

/// CRC-32/ISO-HDLC (the blob's payload CRC), bitwise: reflected polynomial 0xEDB88320, initial
/// value and final XOR all ones.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = u32::MAX;
    for &byte in bytes {
        crc ^= u32::from(byte);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corpus_inputs_are_accepted() {
        for target in Target::ALL {
            for input in corpus(target) {
                assert!(matches!(run_once(target, &input).0, Verdict::Accepted), "{target:?}");
            }
        }
    }

    #[test]
    fn resealed_blob_with_unchanged_payload_is_the_valid_blob() {
        let valid = corpus(Target::Blob).remove(0);
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926, "the CRC-32/ISO-HDLC check value");
        let mut copy = valid.clone();
        copy[14..18].fill(0);
        let payload = copy.split_off(HEADER_LEN);
        copy[14..18].copy_from_slice(&crc32(&payload).to_le_bytes());
        copy.extend(payload);
        assert_eq!(copy, valid);
    }

    #[test]
    fn target_names_round_trip() {
        for target in Target::ALL {
            assert_eq!(target.name().parse::<Target>(), Ok(target));
        }
        assert!("csv".parse::<Target>().unwrap_err().contains("dataset-csv"));
    }
}
