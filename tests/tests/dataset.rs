//! The dataset format (docs/spec/dataset-format.md): round trips through the writer and the
//! reader, every error class with the file and the row or key in its message, missing values,
//! the `mx_nm` conversion, and atomic writes.
//!
//! Reader tests write their CSV and TOML by hand, so they do not depend on the writer.

use std::fs;
use std::path::{Path, PathBuf};

use firmware_sim::dataset::{
    Channels, Dataset, DatasetError, FORMAT, N_TAPS, Run, RunKind, RunMeta, Tunnel, Wing, channels_from_columns,
    check_dataset, load_dataset, load_run, write_dataset,
};
use tempfile::TempDir;

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// The header of a run file with all required columns, `cmu_stbd` and `cl`.
fn header() -> String {
    let cps: Vec<String> = (1..=N_TAPS).map(|tap| format!("cp{tap:02}")).collect();
    format!("t_s,phi_deg,cmu_port,cmu_stbd,{},cl", cps.join(","))
}

/// One data row of [`header`] for sample `k` at 1 kHz: every value is distinct and non-zero.
fn row(k: usize) -> String {
    let t = k as f64 * 1e-3;
    let cps: Vec<String> = (1..=N_TAPS).map(|tap| format!("{}", -0.1 * tap as f64 - k as f64)).collect();
    format!("{t},{},{},{},{},{}", 1.5 + k as f64, 0.01, 0.02, cps.join(","), 0.1 + k as f64)
}

/// A run file of [`header`] and `n` rows.
fn run_csv(n: usize) -> String {
    let mut text = header();
    for k in 0..n {
        text.push('\n');
        text.push_str(&row(k));
    }
    text.push('\n');
    text
}

/// A manifest with the given `[[run]]` tables appended.
fn manifest(runs: &str) -> String {
    format!("format = \"{FORMAT}\"\n[tunnel]\nu_inf_mps = 6.5\nrho_kgm3 = 1.2\n{runs}")
}

/// A `[[run]]` table at 1 kHz.
fn run_table(file: &str, kind: &str, alpha_deg: f64) -> String {
    format!("\n[[run]]\nfile = \"{file}\"\nkind = \"{kind}\"\nalpha_deg = {alpha_deg:?}\nsample_hz = 1000\n")
}

/// Writes `text` at `dir/rel`, creating folders.
fn put(dir: &Path, rel: &str, text: &str) {
    let path = dir.join(rel);
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(path, text).unwrap();
}

/// A temporary dataset folder with one roll run `runs/roll_a10.csv` holding `csv`.
fn one_run(csv: &str) -> TempDir {
    let tmp = TempDir::new().unwrap();
    put(tmp.path(), "manifest.toml", &manifest(&run_table("runs/roll_a10.csv", "roll", 10.0)));
    put(tmp.path(), "runs/roll_a10.csv", csv);
    tmp
}

/// The message of the error that loading `dir` must produce.
fn load_error(dir: &Path) -> String {
    match load_dataset(dir) {
        Ok(dataset) => panic!("expected an error, loaded {} runs", dataset.runs.len()),
        Err(err) => err.to_string(),
    }
}

/// The error message of loading a one-run dataset holding `csv`, with the run's full path.
fn run_error(csv: &str) -> (String, String) {
    let tmp = one_run(csv);
    let path = tmp.path().join("runs/roll_a10.csv").display().to_string();
    (load_error(tmp.path()), path)
}

/// Loads a one-run dataset holding `csv` and returns its channels.
fn load_channels(csv: &str) -> Channels {
    let tmp = one_run(csv);
    let mut dataset = load_dataset(tmp.path()).unwrap();
    dataset.runs.remove(0).channels
}

/// Equality of two sample vectors, bit for bit, where any NaN equals any NaN.
fn same_samples(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x.is_nan() && y.is_nan()) || x.to_bits() == y.to_bits())
}

/// Asserts NaN-aware, bit-exact equality of two channel sets, naming the first differing one.
fn assert_same_channels(a: &Channels, b: &Channels) {
    let pairs = [
        ("t_s", &a.t_s, &b.t_s),
        ("phi_deg", &a.phi_deg, &b.phi_deg),
        ("cmu_port", &a.cmu_port, &b.cmu_port),
        ("cmu_stbd", &a.cmu_stbd, &b.cmu_stbd),
        ("cl", &a.cl, &b.cl),
    ];
    for (name, x, y) in pairs {
        assert!(same_samples(x, y), "{name}: {x:?} != {y:?}");
    }
    for tap in 0..N_TAPS {
        assert!(same_samples(&a.cp[tap], &b.cp[tap]), "cp{:02}", tap + 1);
    }
    let optional = [
        ("alpha_deg", &a.alpha_deg, &b.alpha_deg),
        ("phi_cmd_deg", &a.phi_cmd_deg, &b.phi_cmd_deg),
        ("cmu_port_cmd", &a.cmu_port_cmd, &b.cmu_port_cmd),
        ("cmu_stbd_cmd", &a.cmu_stbd_cmd, &b.cmu_stbd_cmd),
    ];
    for (name, x, y) in optional {
        match (x, y) {
            (None, None) => {}
            (Some(x), Some(y)) => assert!(same_samples(x, y), "{name}: {x:?} != {y:?}"),
            _ => panic!("{name}: {x:?} != {y:?}"),
        }
    }
}

/// Asserts NaN-aware equality of two datasets.
fn assert_same_dataset(a: &Dataset, b: &Dataset) {
    assert_eq!(a.tunnel, b.tunnel);
    assert_eq!(a.wing, b.wing);
    assert_eq!(a.extra, b.extra);
    assert_eq!(a.runs.len(), b.runs.len());
    for (x, y) in a.runs.iter().zip(&b.runs) {
        assert_eq!(x.meta, y.meta);
        assert_same_channels(&x.channels, &y.channels);
    }
}

/// Awkward but finite values: a deterministic sequence of all magnitudes and both signs.
fn awkward(seed: u64, n: usize) -> Vec<f64> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let value = f64::from_bits(state);
            if value.is_finite() { value } else { 1.0 / 3.0 }
        })
        .collect()
}

/// Channels of `n` samples at `sample_hz` from `t0_s`, with awkward values and some NaN.
fn channels(seed: u64, n: usize, t0_s: f64, sample_hz: f64) -> Channels {
    let mut cl = awkward(seed + 5, n);
    cl[n / 2] = f64::NAN;
    let mut phi_deg = awkward(seed + 1, n);
    phi_deg[0] = -0.0;
    phi_deg[1] = f64::NAN;
    let mut cp: [Vec<f64>; N_TAPS] = std::array::from_fn(|tap| awkward(seed + 10 + tap as u64, n));
    cp[2][n - 1] = f64::NAN;
    Channels {
        t_s: (0..n).map(|k| t0_s + k as f64 / sample_hz).collect(),
        phi_deg,
        cmu_port: vec![0.0, 1e-300, 0.1 + 0.2, 123_456.789e10].into_iter().cycle().take(n).collect(),
        cmu_stbd: awkward(seed + 3, n),
        cp,
        cl,
        alpha_deg: None,
        phi_cmd_deg: Some(awkward(seed + 7, n)),
        cmu_port_cmd: None,
        cmu_stbd_cmd: Some(vec![f64::NAN; n]),
    }
}

/// Run metadata with extra keys.
fn meta(file: &str, kind: RunKind, alpha_deg: f64, sample_hz: f64) -> RunMeta {
    let mut extra = toml::Table::new();
    extra.insert("notes".into(), toml::Value::String(format!("run \"{file}\"\nsecond line")));
    extra.insert("seed".into(), toml::Value::Integer(42));
    RunMeta { file: file.into(), kind, alpha_deg, sample_hz, extra }
}

/// A three-run dataset with a non-paper wing, extra keys and NaN samples.
fn sample_dataset() -> Dataset {
    let extra: toml::Table = "campaign = \"sim-7\"\n[lab]\ntunnel = \"fejer\"\n".parse().unwrap();
    let mut aoa = channels(3, 40, 0.0, 1000.0);
    aoa.alpha_deg = Some(vec![12.5; 40]);
    let runs = vec![
        Run { meta: meta("runs/roll_a10.csv", RunKind::Roll, 10.0, 1000.0), channels: channels(1, 50, 2.5, 1000.0) },
        Run {
            meta: meta("runs/rollact_a-2.csv", RunKind::RollActuation, -2.25, 1000.0 / 3.0),
            channels: channels(2, 30, 1e-3, 1000.0 / 3.0),
        },
        Run { meta: meta("static.csv", RunKind::Static, 12.5, 1000.0), channels: aoa },
    ];
    let wing = Wing { span_m: 0.3, mass_kg: 0.2, ..Wing::PAPER };
    Dataset { tunnel: Tunnel { u_inf_mps: 6.5, rho_kgm3: 1.2 }, wing, extra, runs }
}

/// Names in `dir` starting with a dot (temporary or backup folders of the writer).
fn hidden_entries(dir: &Path) -> Vec<String> {
    fs::read_dir(dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with('.'))
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Round trip
// ---------------------------------------------------------------------------------------------

#[test]
fn round_trip_is_bit_exact_with_nan_positions_and_extra_keys() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("campaign");
    let original = sample_dataset();
    write_dataset(&dir, &original).unwrap();
    assert!(dir.join("runs/roll_a10.csv").is_file());
    assert!(dir.join("static.csv").is_file());
    let loaded = load_dataset(&dir).unwrap();
    assert_same_dataset(&loaded, &original);
    assert_eq!(loaded.extra["lab"]["tunnel"].as_str(), Some("fejer"));
    assert!(loaded.runs[0].channels.phi_deg[0].is_sign_negative());
    assert!(loaded.runs[0].channels.phi_deg[1].is_nan());
    assert!(loaded.runs[0].channels.cl[25].is_nan());
    assert!(hidden_entries(tmp.path()).is_empty());
    // Loading through the manifest path gives the same dataset.
    assert_same_dataset(&load_dataset(&dir.join("manifest.toml")).unwrap(), &original);
}

/// Columns held in memory (a notebook's arrays) become the channels a run file of the same
/// columns gives, and the dataset they make is checked as a folder is: an infinite sample, a
/// short column, a missing column are refused naming the run's file, row and column.
#[test]
fn columns_in_memory_are_read_and_checked_as_a_run_file_is() {
    let original = sample_dataset();
    let run = &original.runs[0];
    let c = &run.channels;
    let mut columns: Vec<(String, Vec<f64>)> = vec![
        ("t_s".into(), c.t_s.clone()),
        ("phi_deg".into(), c.phi_deg.clone()),
        ("cmu_port".into(), c.cmu_port.clone()),
        ("cmu_stbd".into(), c.cmu_stbd.clone()),
        ("temperature_c".into(), vec![20.0; c.len()]),
    ];
    columns.extend(c.cp.iter().enumerate().map(|(tap, values)| (format!("cp{:02}", tap + 1), values.clone())));
    let (tunnel, wing) = (original.tunnel, original.wing);
    let denominator = tunnel.dynamic_pressure_pa() * wing.area_m2 * wing.span_m;
    let mut with_mx = columns.clone();
    with_mx.push(("mx_nm".into(), c.cl.iter().map(|cl| cl * denominator).collect()));
    columns.push(("cl".into(), c.cl.clone()));
    columns.push(("phi_cmd_deg".into(), c.phi_cmd_deg.clone().unwrap()));
    columns.push(("cmu_stbd_cmd".into(), c.cmu_stbd_cmd.clone().unwrap()));
    let file = Path::new("<in memory>/runs/roll_a10.csv");
    let read = channels_from_columns(file, columns.clone(), &tunnel, &wing).unwrap();
    assert_same_channels(&read, c);
    let converted = channels_from_columns(file, with_mx, &tunnel, &wing).unwrap();
    for (got, want) in converted.cl.iter().zip(&c.cl) {
        assert!((got.is_nan() && want.is_nan()) || (got - want).abs() <= 1e-12 * want.abs(), "{got} {want}");
    }

    let missing: Vec<(String, Vec<f64>)> = columns.iter().filter(|(name, _)| name != "cp05").cloned().collect();
    let error = channels_from_columns(file, missing, &tunnel, &wing).unwrap_err();
    assert!(matches!(error, DatasetError::MissingColumn { column: "cp05", .. }), "{error}");

    let folder = Path::new("<in memory>");
    assert!(check_dataset(folder, &original).is_ok());
    let mut infinite = original.clone();
    infinite.runs[0].channels.cp[6][9] = f64::INFINITY;
    let error = check_dataset(folder, &infinite).unwrap_err();
    assert!(
        matches!(&error, DatasetError::BadNumber { row: 11, column: "cp07", file, .. } if file.ends_with("runs/roll_a10.csv")),
        "{error}"
    );
    let mut short = original.clone();
    short.runs[1].channels.cl.pop();
    let error = check_dataset(folder, &short).unwrap_err();
    assert!(matches!(error, DatasetError::ChannelLength { column: "cl", .. }), "{error}");
}

#[test]
fn written_run_file_has_the_documented_columns_and_empty_fields_for_nan() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    write_dataset(&dir, &sample_dataset()).unwrap();
    let text = fs::read_to_string(dir.join("runs/roll_a10.csv")).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(format!("{},phi_cmd_deg,cmu_stbd_cmd", header()).as_str()));
    let second = lines.nth(1).unwrap();
    let fields: Vec<&str> = second.split(',').collect();
    assert_eq!(fields.len(), 19);
    assert_eq!(fields[1], "", "phi_deg of row 3 is NaN: {second}");
    assert_eq!(fields[18], "", "cmu_stbd_cmd is NaN: {second}");
    let manifest = fs::read_to_string(dir.join("manifest.toml")).unwrap();
    assert!(manifest.starts_with("format = \"roll-dataset/1\"\n"), "{manifest}");
    assert!(manifest.contains("[tunnel]") && manifest.contains("[wing]") && manifest.contains("[[run]]"));
}

#[test]
fn load_run_reads_one_file() {
    let tmp = one_run(&run_csv(3));
    let meta = meta("runs/roll_a10.csv", RunKind::Roll, 10.0, 1000.0);
    let run = load_run(
        &tmp.path().join("runs/roll_a10.csv"),
        meta.clone(),
        &Tunnel { u_inf_mps: 6.5, rho_kgm3: 1.2 },
        &Wing::PAPER,
    )
    .unwrap();
    assert_eq!(run.meta, meta);
    assert_eq!(run.channels.len(), 3);
    let expected: Vec<f64> = (0..3).map(|k| -0.1 * 12.0 - f64::from(k)).collect();
    assert_eq!(run.channels.cp[11], expected);
}

// ---------------------------------------------------------------------------------------------
// Reader: values and columns
// ---------------------------------------------------------------------------------------------

#[test]
fn hand_written_dataset_loads_with_paper_wing_and_integer_keys() {
    let tmp = one_run(&run_csv(4));
    let dataset = load_dataset(tmp.path()).unwrap();
    assert_eq!(dataset.tunnel, Tunnel { u_inf_mps: 6.5, rho_kgm3: 1.2 });
    assert_eq!(dataset.wing, Wing::PAPER);
    let run = &dataset.runs[0];
    assert_eq!(run.meta.kind, RunKind::Roll);
    assert_eq!((run.meta.alpha_deg, run.meta.sample_hz), (10.0, 1000.0));
    let ch = &run.channels;
    let by_sample = |f: fn(f64) -> f64| -> Vec<f64> { (0..4).map(|k| f(f64::from(k))).collect() };
    assert_eq!(ch.t_s, by_sample(|k| k * 1e-3));
    assert_eq!(ch.phi_deg, by_sample(|k| 1.5 + k));
    assert_eq!(ch.cmu_stbd, vec![0.02; 4]);
    assert_eq!(ch.cl, by_sample(|k| 0.1 + k));
    assert_eq!(ch.cp[0], by_sample(|k| -0.1 - k));
    assert_eq!((ch.alpha_deg.as_ref(), ch.phi_cmd_deg.as_ref()), (None, None));
}

#[test]
fn missing_values_stay_nan_never_zero() {
    let csv = format!(
        "{}\n0,,0,0,{},\n0.001,nan,0,0,{},NaN\n0.002,-nan,0,0,{},NAN\n0.003, 0 ,0,0,{}, \n",
        header(),
        ["0"; 12].join(","),
        ["nan"; 12].join(","),
        ["", "NaN", "", "nAn", "", "", "", "", "", "", "", "-NaN"].join(","),
        ["0.5"; 12].join(","),
    );
    let ch = load_channels(&csv);
    assert!(ch.phi_deg[..3].iter().all(|v| v.is_nan()), "{:?}", ch.phi_deg);
    assert_eq!(ch.phi_deg[3].to_bits(), 0.0_f64.to_bits(), "an explicit 0 stays 0");
    assert!(ch.cl.iter().all(|v| v.is_nan()), "{:?}", ch.cl);
    assert_eq!(ch.cp[0][0], 0.0);
    for tap in 0..N_TAPS {
        assert!(ch.cp[tap][1].is_nan() && ch.cp[tap][2].is_nan(), "cp{:02}", tap + 1);
        assert_eq!(ch.cp[tap][3], 0.5);
    }
}

#[test]
fn mx_nm_is_converted_to_cl_with_q_s_b() {
    let csv = run_csv(2).replace(",cl\n", ",mx_nm\n");
    let ch = load_channels(&csv);
    // q = 1.2 * 6.5^2 / 2 = 25.35 Pa; S = 0.0474 m^2, b = 0.287 m (paper wing):
    // q S b = 25.35 * 0.0474 * 0.287 = 0.344856... N m.
    let qsb: f64 = 25.35 * 0.0474 * 0.287;
    assert!((qsb - 0.344_856_33).abs() < 1e-8, "{qsb}");
    assert!((ch.cl[0] - 0.1 / 0.344_856_33).abs() < 1e-7, "{}", ch.cl[0]);
    assert!((ch.cl[0] - 0.289_975_83).abs() < 1e-8, "{}", ch.cl[0]);
    assert!((ch.cl[1] - 1.1 / qsb).abs() < 1e-12, "{}", ch.cl[1]);
}

#[test]
fn mx_nm_uses_the_manifest_wing_and_cl_wins_when_both_are_present() {
    let tmp = TempDir::new().unwrap();
    let runs = format!(
        "[wing]\narea_m2 = 0.05\nspan_m = 0.25\n{}{}",
        run_table("mx.csv", "roll", 0.0),
        run_table("both.csv", "roll", 0.0)
    );
    put(tmp.path(), "manifest.toml", &manifest(&runs));
    put(
        tmp.path(),
        "mx.csv",
        "t_s,phi_deg,cmu_port,cp01,cp02,cp03,cp04,cp05,cp06,cp07,cp08,cp09,cp10,cp11,cp12,mx_nm\n0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,2\n",
    );
    put(tmp.path(), "both.csv", &run_csv(1).replace(",cl\n", ",cl,mx_nm\n").replace("0.1\n", "0.1,99\n"));
    let dataset = load_dataset(tmp.path()).unwrap();
    // q = 25.35 Pa, S b = 0.05 * 0.25 = 0.0125 m^3: cl = 2 / 0.316875.
    let cl = dataset.runs[0].channels.cl[0];
    assert!((cl - 6.311_637_080_867_85).abs() < 1e-12, "{cl}");
    assert_eq!(dataset.runs[1].channels.cl, vec![0.1]);
}

#[test]
fn column_order_is_free_and_unknown_columns_are_ignored() {
    let cps: Vec<String> = (1..=N_TAPS).rev().map(|tap| format!(" cp{tap:02} ")).collect();
    let values: Vec<String> = (1..=N_TAPS).rev().map(|tap| format!("{tap}")).collect();
    let csv = format!(
        "\u{feff}cl,operator,{},cmu_port, phi_deg,temp_c,t_s\r\n\"7.5\",anna,{},0.25,-3,21.5,100\r\n",
        cps.join(","),
        values.join(",")
    );
    let ch = load_channels(&csv);
    assert_eq!(ch.t_s, vec![100.0]);
    assert_eq!(ch.phi_deg, vec![-3.0]);
    assert_eq!(ch.cmu_port, vec![0.25]);
    assert_eq!(ch.cl, vec![7.5]);
    for tap in 0..N_TAPS {
        assert_eq!(ch.cp[tap], vec![(tap + 1) as f64], "cp{:02}", tap + 1);
    }
}

#[test]
fn absent_cmu_stbd_is_zero_but_an_empty_field_is_nan() {
    let without = run_csv(3).replace("cmu_port,cmu_stbd,", "cmu_port,").replace(",0.01,0.02,", ",0.01,");
    assert_eq!(load_channels(&without).cmu_stbd, vec![0.0; 3]);
    let empty = run_csv(2).replace("0.001,2.5,0.01,0.02,", "0.001,2.5,0.01,,");
    let stbd = load_channels(&empty).cmu_stbd;
    assert_eq!(stbd[0], 0.02);
    assert!(stbd[1].is_nan(), "{stbd:?}");
}

#[test]
fn optional_columns_are_read_when_present() {
    let csv = run_csv(2)
        .replace(",cl\n", ",cl,alpha_deg,phi_cmd_deg,cmu_port_cmd,cmu_stbd_cmd\n")
        .replace("0.1\n", "0.1,11,5,0.03,\n")
        .replace("1.1\n", "1.1,,6,0.04,0\n");
    let ch = load_channels(&csv);
    let alpha = ch.alpha_deg.clone().unwrap();
    assert_eq!(alpha[0], 11.0);
    assert!(alpha[1].is_nan());
    assert_eq!(ch.alpha_at(0, 10.0), 11.0);
    assert_eq!(ch.alpha_at(1, 10.0), 10.0);
    assert_eq!(ch.phi_cmd_deg, Some(vec![5.0, 6.0]));
    assert_eq!(ch.cmu_port_cmd, Some(vec![0.03, 0.04]));
    assert!(ch.cmu_stbd_cmd.unwrap()[0].is_nan());
}

#[test]
fn jitter_of_half_a_percent_is_accepted_and_two_percent_rejected() {
    let with_t3 = |t3: &str| run_csv(5).replace("\n0.003,", &format!("\n{t3},"));
    let ch = load_channels(&with_t3("0.003005"));
    assert_eq!(ch.t_s[3], 0.003005);
    let ch = load_channels(&with_t3("0.002995"));
    assert_eq!(ch.t_s[3], 0.002995);
    let (msg, path) = run_error(&with_t3("0.00302"));
    assert_eq!(
        msg,
        format!(
            "{path}: row 5, column t_s: expected 0.003 s (uniform steps of 1/sample_hz, jitter up to \
             1 % of the step), found 0.00302 s"
        )
    );
}

#[test]
fn time_drifting_off_the_grid_is_rejected_at_the_first_bad_row() {
    // Every step is 0.6 % long: each step alone is within tolerance, but the samples drift
    // off the uniform grid and row 4 (sample 2, 1.2 % late) is refused.
    let rows: Vec<String> = (0..5)
        .map(|k| row(k).replacen(&format!("{}", k as f64 * 1e-3), &format!("{}", k as f64 * 1.006e-3), 1))
        .collect();
    let (msg, path) = run_error(&format!("{}\n{}\n", header(), rows.join("\n")));
    assert!(msg.starts_with(&format!("{path}: row 4, column t_s: expected 0.002 s")), "{msg}");
}

// ---------------------------------------------------------------------------------------------
// Reader: every error class names the file and the row or key
// ---------------------------------------------------------------------------------------------

#[test]
fn missing_column_names_file_and_column() {
    let (msg, path) = run_error(&run_csv(2).replace(",cp03,", ",cp3,"));
    assert_eq!(msg, format!("{path}: row 1 (header): expected a column named \"cp03\", found none"));
    let (msg, path) = run_error(&run_csv(2).replace("t_s,", "time,"));
    assert_eq!(msg, format!("{path}: row 1 (header): expected a column named \"t_s\", found none"));
}

#[test]
fn missing_cl_and_mx_nm_is_refused() {
    let (msg, path) = run_error(&run_csv(2).replace(",cl\n", ",cx\n"));
    assert_eq!(msg, format!("{path}: row 1 (header): expected a column named \"cl\" or \"mx_nm\", found neither"));
}

#[test]
fn duplicate_known_column_is_refused() {
    let csv = run_csv(1).replace(",cl\n", ",cl, phi_deg\n").replace("0.1\n", "0.1,3\n");
    let (msg, path) = run_error(&csv);
    assert_eq!(msg, format!("{path}: row 1 (header): expected column \"phi_deg\" once, found it twice"));
}

#[test]
fn bad_number_names_row_column_and_text() {
    let mut csv = run_csv(20);
    // Data row k is file row k + 2: row 17 holds sample 15; cp03 is its 7th field.
    let line = row(15);
    let mut fields: Vec<&str> = line.split(',').collect();
    fields[6] = "abc";
    csv = csv.replace(&line, &fields.join(","));
    let (msg, path) = run_error(&csv);
    assert_eq!(msg, format!("{path}: row 17, column cp03: expected a number or an empty field, found \"abc\""));
    assert!(msg.contains("runs/roll_a10.csv: row 17, column cp03"), "{msg}");
    let (msg, path) = run_error(&run_csv(3).replace("\n0.001,2.5,", "\n0.001,inf,"));
    assert_eq!(msg, format!("{path}: row 3, column phi_deg: expected a number or an empty field, found \"inf\""));
}

#[test]
fn missing_time_names_the_row() {
    let (msg, path) = run_error(&run_csv(3).replace("\n0.002,", "\nnan,"));
    assert_eq!(msg, format!("{path}: row 4, column t_s: expected a sample time, found a missing value"));
}

#[test]
fn ragged_row_names_the_row_and_field_counts() {
    let (msg, path) = run_error(&run_csv(4).replace("\n0.002,", "\n0.002,7,"));
    assert_eq!(msg, format!("{path}: row 4: expected 17 fields like the header, found 18"));
}

#[test]
fn run_without_rows_is_refused() {
    let (msg, path) = run_error(&format!("{}\n", header()));
    assert_eq!(msg, format!("{path}: expected at least one data row after the header, found none"));
}

#[test]
fn manifest_pointing_to_a_missing_file_names_it() {
    let tmp = one_run(&run_csv(2));
    put(
        tmp.path(),
        "manifest.toml",
        &manifest(&format!(
            "{}{}",
            run_table("runs/roll_a10.csv", "roll", 10.0),
            run_table("runs/gone.csv", "static", 0.0)
        )),
    );
    let msg = load_error(tmp.path());
    let path = tmp.path().join("runs/gone.csv").display().to_string();
    assert!(msg.starts_with(&format!("{path}: cannot read the run file: ")), "{msg}");
}

#[test]
fn missing_manifest_names_it() {
    let tmp = TempDir::new().unwrap();
    let msg = load_error(tmp.path());
    let path = tmp.path().join("manifest.toml").display().to_string();
    assert!(msg.starts_with(&format!("{path}: cannot read the manifest: ")), "{msg}");
}

#[test]
fn first_faulty_run_in_manifest_order_is_reported() {
    let tmp = TempDir::new().unwrap();
    let runs: String = ["a", "b", "c", "d"].iter().map(|name| run_table(&format!("{name}.csv"), "roll", 0.0)).collect();
    put(tmp.path(), "manifest.toml", &manifest(&runs));
    put(tmp.path(), "a.csv", &run_csv(3));
    put(tmp.path(), "b.csv", &run_csv(3).replace(",cl\n", ",c\n"));
    put(tmp.path(), "c.csv", &run_csv(3));
    put(tmp.path(), "d.csv", "");
    for _ in 0..5 {
        let msg = load_error(tmp.path());
        assert!(msg.contains("b.csv: row 1 (header)"), "{msg}");
    }
}

/// The error message of loading a folder whose manifest is `text` and whose one run is valid.
fn manifest_error(text: &str) -> (String, String) {
    let tmp = one_run(&run_csv(2));
    put(tmp.path(), "manifest.toml", text);
    let path = tmp.path().join("manifest.toml").display().to_string();
    (load_error(tmp.path()), path)
}

#[test]
fn wrong_format_string_is_refused() {
    let text = manifest(&run_table("runs/roll_a10.csv", "roll", 10.0)).replace("roll-dataset/1", "roll-dataset/2");
    let (msg, path) = manifest_error(&text);
    assert_eq!(msg, format!("{path}: key format: expected \"roll-dataset/1\", found \"roll-dataset/2\""));
}

#[test]
fn missing_key_is_named() {
    let good = manifest(&format!(
        "{}{}",
        run_table("runs/roll_a10.csv", "roll", 10.0),
        run_table("runs/roll_a10.csv", "roll", 10.0)
    ));
    let (msg, path) = manifest_error(&good.replace("u_inf_mps = 6.5\n", ""));
    assert_eq!(msg, format!("{path}: key tunnel.u_inf_mps: expected a value, found no such key"));
    let second = good.rfind("sample_hz = 1000\n").unwrap();
    let text = format!("{}{}", &good[..second], &good[second + "sample_hz = 1000\n".len()..]);
    let (msg, path) = manifest_error(&text);
    assert_eq!(msg, format!("{path}: key run[2].sample_hz: expected a value, found no such key"));
}

#[test]
fn unknown_kind_is_named() {
    let (msg, path) = manifest_error(&manifest(&run_table("runs/roll_a10.csv", "rolling", 10.0)));
    assert_eq!(
        msg,
        format!(
            "{path}: key run[1].kind: expected one of \"roll\", \"actuation\", \"roll+actuation\", \
             \"static\", found \"rolling\""
        )
    );
}

#[test]
fn bad_manifest_value_is_named() {
    let text = manifest(&run_table("runs/roll_a10.csv", "roll", 10.0)).replace("sample_hz = 1000", "sample_hz = -1000");
    let (msg, path) = manifest_error(&text);
    assert_eq!(msg, format!("{path}: key run[1].sample_hz: expected a finite number greater than zero, found -1000.0"));
    let text =
        manifest(&run_table("runs/roll_a10.csv", "roll", 10.0)).replace("rho_kgm3 = 1.2", "rho_kgm3 = \"dense\"");
    let (msg, path) = manifest_error(&text);
    assert_eq!(
        msg,
        format!("{path}: key tunnel.rho_kgm3: expected a finite number greater than zero, found \"dense\"")
    );
}

#[test]
fn manifest_syntax_error_names_the_line() {
    let text = manifest(&run_table("runs/roll_a10.csv", "roll", 10.0)).replace("kind = \"roll\"", "kind = roll");
    let (msg, path) = manifest_error(&text);
    assert!(msg.starts_with(&format!("{path}: line 8: expected valid TOML")), "{msg}");
}

#[test]
fn manifest_without_runs_is_refused() {
    let (msg, path) = manifest_error(&manifest(""));
    assert_eq!(msg, format!("{path}: key run: expected at least one [[run]] table, found none"));
}

#[test]
fn error_is_a_matchable_variant() {
    let tmp = one_run(&run_csv(3).replace("\n0.002,", "\n0.0025,"));
    match load_dataset(tmp.path()) {
        Err(DatasetError::NonUniformTime { file, row, expected_s, found_s }) => {
            assert_eq!(file, tmp.path().join("runs/roll_a10.csv"));
            assert_eq!((row, expected_s, found_s), (4, 0.002, 0.0025));
        }
        other => panic!("expected NonUniformTime, got {other:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Writer: atomicity and refusals
// ---------------------------------------------------------------------------------------------

#[test]
fn failed_write_into_a_path_under_a_file_leaves_nothing() {
    let tmp = TempDir::new().unwrap();
    let blocker = tmp.path().join("not-a-folder");
    fs::write(&blocker, "x").unwrap();
    let dir = blocker.join("ds");
    let msg = write_dataset(&dir, &sample_dataset()).unwrap_err().to_string();
    assert!(msg.starts_with(&format!("{}: cannot create the folder: ", blocker.display())), "{msg}");
    let names: Vec<PathBuf> = fs::read_dir(tmp.path()).unwrap().map(|entry| entry.unwrap().path()).collect();
    assert_eq!(names, vec![blocker]);
}

#[test]
fn failed_write_midway_removes_the_temporary_folder_and_keeps_the_old_dataset() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    let old = sample_dataset();
    write_dataset(&dir, &old).unwrap();
    let mut bad = sample_dataset();
    bad.runs[2].channels.cp[4][7] = f64::INFINITY;
    let msg = write_dataset(&dir, &bad).unwrap_err().to_string();
    let path = dir.join("static.csv").display().to_string();
    assert_eq!(msg, format!("{path}: row 9, column cp05: expected a number or an empty field, found \"inf\""));
    assert!(hidden_entries(tmp.path()).is_empty(), "{:?}", hidden_entries(tmp.path()));
    assert_same_dataset(&load_dataset(&dir).unwrap(), &old);
    // Into a fresh folder, the failed write leaves no folder at all.
    let fresh = tmp.path().join("fresh");
    assert!(write_dataset(&fresh, &bad).is_err());
    assert!(!fresh.exists());
    assert!(hidden_entries(tmp.path()).is_empty());
}

#[test]
fn existing_dataset_is_replaced_completely() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    write_dataset(&dir, &sample_dataset()).unwrap();
    fs::write(dir.join("runs/stale.csv"), "old").unwrap();
    let mut new = sample_dataset();
    new.runs.truncate(1);
    new.runs[0].meta.alpha_deg = 4.0;
    new.wing = Wing::PAPER;
    write_dataset(&dir, &new).unwrap();
    assert_same_dataset(&load_dataset(&dir).unwrap(), &new);
    assert!(!dir.join("runs/stale.csv").exists(), "the old folder's files are gone");
    assert!(!dir.join("static.csv").exists());
    assert!(hidden_entries(tmp.path()).is_empty(), "{:?}", hidden_entries(tmp.path()));
}

#[test]
fn writer_refuses_to_replace_a_folder_that_is_not_a_dataset() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("home");
    put(&dir, "thesis.tex", "precious");
    let msg = write_dataset(&dir, &sample_dataset()).unwrap_err().to_string();
    assert_eq!(
        msg,
        format!(
            "{}: expected no folder, an empty folder or a dataset folder with manifest.toml, found \
             a folder without manifest.toml; refusing to replace it",
            dir.display()
        )
    );
    assert_eq!(fs::read_to_string(dir.join("thesis.tex")).unwrap(), "precious");
    // An empty folder is fine.
    let empty = tmp.path().join("empty");
    fs::create_dir(&empty).unwrap();
    write_dataset(&empty, &sample_dataset()).unwrap();
    assert!(empty.join("manifest.toml").is_file());
}

#[test]
fn writer_refuses_channels_of_different_lengths() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    let mut short = sample_dataset();
    short.runs[1].channels.cl.pop();
    let msg = write_dataset(&dir, &short).unwrap_err().to_string();
    let run_path = dir.join("runs/rollact_a-2.csv").display().to_string();
    assert_eq!(msg, format!("{run_path}: column cl: expected 30 samples like t_s, found 29"));
    assert!(!dir.exists());
    assert!(hidden_entries(tmp.path()).is_empty());
}

#[test]
fn writer_refuses_run_files_outside_the_folder_or_used_twice() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    let manifest_path = dir.join("manifest.toml").display().to_string();
    let mut escaping = sample_dataset();
    escaping.runs[2].meta.file = "../outside.csv".into();
    let msg = write_dataset(&dir, &escaping).unwrap_err().to_string();
    assert!(msg.starts_with(&format!("{manifest_path}: key run[3].file: expected a relative path")), "{msg}");
    let mut twice = sample_dataset();
    twice.runs[2].meta.file = "./runs//roll_a10.csv".into();
    let msg = write_dataset(&dir, &twice).unwrap_err().to_string();
    assert!(msg.contains("key run[3].file: expected a file that no other run uses"), "{msg}");
    assert!(!dir.exists());
    assert!(!tmp.path().join("outside.csv").exists());
    assert!(hidden_entries(tmp.path()).is_empty());
}

#[test]
fn writer_refuses_runs_with_irregular_time_or_no_samples() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    let mut jumpy = sample_dataset();
    jumpy.runs[0].channels.t_s[10] += 0.5e-3;
    let msg = write_dataset(&dir, &jumpy).unwrap_err().to_string();
    assert!(msg.contains("runs/roll_a10.csv: row 12, column t_s: expected 2.51"), "{msg}");
    let mut empty = sample_dataset();
    empty.runs[0].channels = Channels::default();
    let msg = write_dataset(&dir, &empty).unwrap_err().to_string();
    assert!(msg.ends_with("runs/roll_a10.csv: expected at least one data row after the header, found none"), "{msg}");
    assert!(!dir.exists());
    assert!(hidden_entries(tmp.path()).is_empty());
}

#[test]
fn dataset_without_runs_is_refused_by_the_writer() {
    let tmp = TempDir::new().unwrap();
    let dir = tmp.path().join("ds");
    let mut dataset = sample_dataset();
    dataset.runs.clear();
    let msg = write_dataset(&dir, &dataset).unwrap_err().to_string();
    assert_eq!(
        msg,
        format!("{}: key run: expected at least one [[run]] table, found none", dir.join("manifest.toml").display())
    );
    assert!(!dir.exists());
}
