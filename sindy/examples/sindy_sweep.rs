//! Times the SINDy threshold sweep on a precomputed library (the Rust half of
//! tools/pysindy/bench_sweep.py).
//!
//! ```text
//! cargo run --release -p sindy --example sindy_sweep -- PROBLEM.bin THRESHOLDS.txt \
//!     [--alpha A] [--max-iter K] [--normalize none|l2|rms] [--repeats R] [--dense]
//! ```
//!
//! `PROBLEM.bin` holds the magic `SINDYBIN`, N and p as little-endian u64, Theta column-major
//! (N p little-endian f64) and then y (N f64). `THRESHOLDS.txt` holds one threshold a line.
//! Prints one JSON object: the median times over the repeats of the QR factorisation, of the
//! sweep on R and of their sum (and, with `--dense`, of the same sweep by `stls_dense` on the
//! full library), and the support of every threshold.

use std::time::Instant;

use anyhow::{Context, Result, bail};
use sindy::{DMatrix, Normalisation, QrProblem, StlsConfig, stls_dense, sweep};

/// The command line.
struct Args {
    problem: String,
    thresholds: String,
    config: StlsConfig,
    repeats: usize,
    dense: bool,
}

fn parse_args() -> Result<Args> {
    let mut args = std::env::args().skip(1);
    let problem = args.next().context("missing PROBLEM.bin")?;
    let thresholds = args.next().context("missing THRESHOLDS.txt")?;
    let mut parsed =
        Args { problem, thresholds, config: StlsConfig::pysindy(0.1, 0.05, 20, true, true), repeats: 5, dense: false };
    while let Some(flag) = args.next() {
        let mut value = || args.next().with_context(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--alpha" => parsed.config.alpha = value()?.parse()?,
            "--max-iter" => parsed.config.max_iter = value()?.parse()?,
            "--repeats" => parsed.repeats = value()?.parse::<usize>()?.max(1),
            "--normalize" => {
                parsed.config.normalisation = match value()?.as_str() {
                    "none" => Normalisation::None,
                    "l2" => Normalisation::L2,
                    "rms" => Normalisation::Rms,
                    other => bail!("unknown normalisation {other}"),
                }
            }
            "--dense" => parsed.dense = true,
            other => bail!("unknown argument {other}"),
        }
    }
    Ok(parsed)
}

/// Reads the binary problem file.
fn read_problem(path: &str) -> Result<(DMatrix<f64>, Vec<f64>)> {
    let bytes = std::fs::read(path).with_context(|| path.to_owned())?;
    if bytes.len() < 24 || &bytes[..8] != b"SINDYBIN" {
        bail!("{path}: not a SINDYBIN file");
    }
    let word = |idx: usize| -> Result<u64> { Ok(u64::from_le_bytes(bytes[8 * idx..8 * idx + 8].try_into()?)) };
    let (n, p) = (usize::try_from(word(1)?)?, usize::try_from(word(2)?)?);
    let values: Vec<f64> =
        bytes[24..].chunks_exact(8).map(|chunk| chunk.try_into().map(f64::from_le_bytes)).collect::<Result<_, _>>()?;
    if values.len() != n * (p + 1) {
        bail!("{path}: {} values for N = {n}, p = {p}", values.len());
    }
    Ok((DMatrix::from_column_slice(n, p, &values[..n * p]), values[n * p..].to_vec()))
}

/// The median of some durations in seconds.
fn median(mut times: Vec<f64>) -> f64 {
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn main() -> Result<()> {
    let args = parse_args()?;
    let (theta, y) = read_problem(&args.problem)?;
    let thresholds: Vec<f64> =
        std::fs::read_to_string(&args.thresholds)?.lines().map(str::parse).collect::<Result<_, _>>()?;
    let (mut qr_times, mut sweep_times, mut supports) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..args.repeats {
        let start = Instant::now();
        let problem = QrProblem::new(&theta, &y)?;
        let factored = Instant::now();
        let result = sweep(&problem, &args.config, &thresholds)?;
        sweep_times.push(factored.elapsed().as_secs_f64());
        qr_times.push((factored - start).as_secs_f64());
        supports = result.point_of_threshold.iter().map(|&idx| result.points[idx].support.clone()).collect();
    }
    let mut dense_seconds = None;
    if args.dense {
        let start = Instant::now();
        for (&threshold, support) in thresholds.iter().zip(&supports) {
            let fit = stls_dense(&theta, &y, &StlsConfig { threshold, ..args.config })?;
            if &fit.support != support {
                bail!("the dense path disagrees with the QR path at threshold {threshold}");
            }
        }
        dense_seconds = Some(start.elapsed().as_secs_f64());
    }
    let totals: Vec<f64> = qr_times.iter().zip(&sweep_times).map(|(a, b)| a + b).collect();
    let report = serde_json::json!({
        "n_samples": theta.nrows(), "n_features": theta.ncols(), "n_thresholds": thresholds.len(),
        "threads": rayon::current_num_threads(), "repeats": args.repeats,
        "qr_seconds": median(qr_times), "sweep_seconds": median(sweep_times), "total_seconds": median(totals),
        "dense_seconds": dense_seconds, "supports": supports,
    });
    println!("{report}");
    Ok(())
}
