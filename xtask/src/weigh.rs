//! `cargo xtask weigh`: the design's packages weighed by measurement. The firmware is
//! built three times, with the core as it is, with micromath's approximations of its
//! transcendental functions (`estimator-core/micromath`), and with nalgebra's fixed-size
//! matrix-vector products in the pressure filter (`estimator-core/nalgebra`); each replays the
//! same run in QEMU. The table gives instructions per step, flash, and how far each variant's
//! estimates are from the present code's; a second table gives each function's error against
//! libm in f64 over the range the estimator uses.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use firmware_sim::frames::{OUTPUT_FIELD_NAMES, OutputRecord, output_fields};
use rigs::qemu;

/// Flags of `weigh`.
#[derive(Debug, clap::Args)]
pub struct WeighArgs {
    /// Dataset folder (default: the main job's campaign).
    #[arg(long, default_value = "out/campaign")]
    data: PathBuf,
    /// The run to replay.
    #[arg(long, default_value = "runs/rollact_a20.csv")]
    run: PathBuf,
}

/// One variant of the core: its name and firmware-sim features.
const VARIANTS: [(&str, &str); 3] =
    [("present", "qemu"), ("micromath", "qemu,core-micromath"), ("nalgebra", "qemu,core-nalgebra")];

/// Builds and replays every variant; prints the tables.
pub fn weigh(args: &WeighArgs) -> anyhow::Result<()> {
    let dataset = firmware_sim::dataset::load_dataset(&args.data)
        .with_context(|| format!("{} (`./main-job` or `host-tools simulate` writes it)", args.data.display()))?;
    let run = dataset
        .runs
        .iter()
        .find(|run| run.meta.file == args.run)
        .with_context(|| format!("no run {} in {}", args.run.display(), args.data.display()))?;
    let input = qemu::input_bytes(run, None);
    let mut results: Vec<(&str, qemu::FirmwareRun, qemu::Memory)> = Vec::new();
    for (name, features) in VARIANTS {
        let elf = qemu::build_firmware_with(features, &format!("weigh-{name}"))?;
        let dir = tempfile::tempdir().context("a scratch folder")?;
        std::fs::write(dir.path().join(qemu::INPUT_FILE), &input).context("writing the input")?;
        let firmware = qemu::run_firmware(&elf, dir.path(), Duration::from_secs(600))?;
        let memory = qemu::memory(&std::fs::read(&elf).context("reading the ELF")?)?;
        results.push((name, firmware, memory));
    }
    let present = &results[0].1.records;
    println!(
        "{} of {} ({} steps), the estimator's step in QEMU (netduinoplus2, -icount shift=0):\n",
        args.run.display(),
        args.data.display(),
        present.len()
    );
    let rms_cl =
        (present.iter().map(|r| f64::from(r.output.cl).powi(2)).sum::<f64>() / present.len().max(1) as f64).sqrt();
    println!(
        "| core | instructions per step, mean / max | flash, bytes | largest change of C_l (of its RMS, {rms_cl:.2e}) | steps with an output changed | health bits changed |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    for (name, firmware, memory) in &results {
        let cost = qemu::step_cost(&firmware.trailer);
        let change = compare(present, &firmware.records);
        println!(
            "| {name} | {:.0} / {:.0} | {} | {:.3e} ({:.2e}) | {} | {} |",
            cost.estimator_mean,
            cost.estimator_max,
            memory.flash,
            change.max_abs_cl,
            f64::from(change.max_abs_cl) / rms_cl,
            change.steps_changed,
            change.health_changed
        );
    }
    for (name, firmware, _) in &results[1..] {
        let change = compare(present, &firmware.records);
        let fields: Vec<String> = OUTPUT_FIELD_NAMES
            .iter()
            .zip(change.max_abs)
            .filter(|(_, diff)| *diff > 0.0)
            .map(|(field, diff)| format!("{field} {diff:.2e}"))
            .collect();
        println!(
            "\n{name}: largest change per output: {}",
            if fields.is_empty() { "none".into() } else { fields.join(", ") }
        );
    }
    println!("\nEach function against libm in f64, over the range the estimator uses:\n");
    println!(
        "| function | range | present core: max abs error / max ulp where \\|f\\| >= 1e-3 | micromath: max abs error / max ulp where \\|f\\| >= 1e-3 |"
    );
    println!("| --- | --- | --- | --- |");
    for row in function_errors() {
        println!("| {} | {} | {:.2e} / {} | {:.2e} / {} |", row.0, row.1, row.2.0, row.2.1, row.3.0, row.3.1);
    }
    Ok(())
}

/// How far a variant's records are from the present code's.
struct Change {
    max_abs: [f32; 10],
    max_abs_cl: f32,
    steps_changed: usize,
    health_changed: usize,
}

fn compare(present: &[OutputRecord], variant: &[OutputRecord]) -> Change {
    let mut change = Change { max_abs: [0.0; 10], max_abs_cl: 0.0, steps_changed: 0, health_changed: 0 };
    for (a, b) in present.iter().zip(variant) {
        let (fa, fb) = (output_fields(&a.output), output_fields(&b.output));
        let mut changed = false;
        for field in 0..10 {
            let diff = if fa[field].to_bits() == fb[field].to_bits() { 0.0 } else { (fa[field] - fb[field]).abs() };
            changed |= fa[field].to_bits() != fb[field].to_bits();
            change.max_abs[field] = change.max_abs[field].max(if diff.is_nan() { f32::INFINITY } else { diff });
        }
        change.max_abs_cl = change.max_abs_cl.max((a.output.cl - b.output.cl).abs());
        change.steps_changed += usize::from(changed);
        change.health_changed += usize::from(a.output.health != b.output.health);
    }
    change
}

/// ULPs between two finite f32 of any sign (`u32::MAX` when either is not finite).
fn ulp_distance(a: f32, b: f32) -> u32 {
    if !a.is_finite() || !b.is_finite() {
        return u32::MAX;
    }
    let key = |x: f32| {
        let bits = x.to_bits() as i64;
        if bits < 0x8000_0000 { bits } else { 0x8000_0000 - bits }
    };
    (key(a) - key(b)).unsigned_abs().min(u64::from(u32::MAX)) as u32
}

type Error = (f64, u32);

/// `(function, range, present core's error, micromath's error)` over 100,001 points each. The
/// core's `sin_cos` serves roll angles and clamps to `[-pi/2, pi/2]`: its grid stays there.
fn function_errors() -> Vec<(&'static str, &'static str, Error, Error)> {
    use core::f32::consts::FRAC_PI_2;
    use micromath::F32Ext;
    let grid = |low: f32, high: f32| (0..=100_000).map(move |i| low + (high - low) * i as f32 / 100_000.0);
    let worst = |points: &mut dyn Iterator<Item = f32>, f: &dyn Fn(f32) -> f32, reference: &dyn Fn(f64) -> f64| {
        let mut error: Error = (0.0, 0);
        for x in points {
            let (value, exact) = (f(x), reference(f64::from(x)));
            error.0 = error.0.max((f64::from(value) - exact).abs());
            // ULPs only away from zero, where they measure the relative error.
            if exact.abs() >= 1e-3 {
                error.1 = error.1.max(ulp_distance(value, exact as f32));
            }
        }
        error
    };
    let core_sin = |x: f32| estimator_core::trig::sin_cos(x).0;
    let core_cos = |x: f32| estimator_core::trig::sin_cos(x).1;
    vec![
        (
            "exp",
            "[-20, 20]",
            worst(&mut grid(-20.0, 20.0), &estimator_core::exp::exp, &libm::exp),
            worst(&mut grid(-20.0, 20.0), &|x| F32Ext::exp(x), &libm::exp),
        ),
        (
            "sin",
            "[-pi/2, pi/2]",
            worst(&mut grid(-FRAC_PI_2, FRAC_PI_2), &core_sin, &libm::sin),
            worst(&mut grid(-FRAC_PI_2, FRAC_PI_2), &|x| F32Ext::sin(x), &libm::sin),
        ),
        (
            "cos",
            "[-pi/2, pi/2]",
            worst(&mut grid(-FRAC_PI_2, FRAC_PI_2), &core_cos, &libm::cos),
            worst(&mut grid(-FRAC_PI_2, FRAC_PI_2), &|x| F32Ext::cos(x), &libm::cos),
        ),
        (
            "asin",
            "[-1, 1]",
            worst(&mut grid(-1.0, 1.0), &libm::asinf, &libm::asin),
            worst(&mut grid(-1.0, 1.0), &|x| F32Ext::asin(x), &libm::asin),
        ),
        (
            "atan",
            "[-10, 10]",
            worst(&mut grid(-10.0, 10.0), &libm::atanf, &libm::atan),
            worst(&mut grid(-10.0, 10.0), &|x| F32Ext::atan(x), &libm::atan),
        ),
        (
            "sqrt",
            "[0, 100]",
            worst(&mut grid(0.0, 100.0), &libm::sqrtf, &libm::sqrt),
            worst(&mut grid(0.0, 100.0), &|x| F32Ext::sqrt(x), &libm::sqrt),
        ),
    ]
}
