//! The firmware built for the STM32F405 and run in QEMU (netduinoplus2): the file replay and
//! the real-time loop over the serial link (hardware in the loop); every output must equal the
//! host's bit for bit, and the step's instruction maximum must stay within its budget. Needs
//! `qemu-system-arm` (`./ci.sh setup` installs it): without it the tests fail, never skip. They
//! are the slow tier's (`./ci.sh test`; `cargo test -p tests -- --ignored firmware::`).

use std::time::Duration;

use firmware_sim::campaign::{KindName, Scenario};
use firmware_sim::dataset::RunKind;
use rigs::{hil, qemu};

/// Instructions of one `Estimator::step` on the Cortex-M4F, largest after the warm-up steps:
/// the budget with the built-in tables as generated code.
const MAX_INSTRUCTIONS_COMPILED: f64 = 2_500.0;
/// The same with a coefficient set loaded at run time (its sparse models interpreted from the
/// tables): the flight-controller loop's budget.
const MAX_INSTRUCTIONS_LOADED: f64 = 3_000.0;

fn assert_qemu() {
    let qemu_found =
        std::process::Command::new(qemu::QEMU).arg("--version").output().is_ok_and(|out| out.status.success());
    assert!(qemu_found, "{} is not installed: run `./ci.sh setup` (apt-get install qemu-system-arm)", qemu::QEMU);
}

/// Four seconds of rolling and blowing at 20 deg: every path of the estimator runs.
fn short_run() -> firmware_sim::dataset::Run {
    let scenario = Scenario {
        duration_s: 4.0,
        alphas_deg: vec![20.0],
        kinds: vec![KindName(RunKind::RollActuation)],
        ..Scenario::default()
    };
    let mut dataset = scenario.simulate(&|| {}).expect("simulates");
    dataset.runs.swap_remove(0)
}

/// Every output field and health bit of a QEMU replay equal to the host's.
fn assert_bit_identical(replay: &qemu::QemuReplay, steps: usize) {
    let comparison = &replay.comparison;
    assert_eq!(comparison.steps, steps);
    for (name, diff) in firmware_sim::frames::OUTPUT_FIELD_NAMES.iter().zip(comparison.max_abs) {
        assert!(diff == 0.0, "{name}: QEMU and host replay differ by {diff:e}");
    }
    assert_eq!(comparison.health_mismatches, 0, "health bits differ");
}

/// The C example flies the estimator through the C interface, built with
/// arm-none-eabi-gcc, bit for bit like the host: with the built-in tables and with the default
/// model's blob loaded at run time; a blob with a flipped bit makes it exit with
/// ROLLEST_STATUS_BLOB_CRC_MISMATCH (16), the documented code.
#[test]
#[ignore = "slow tier (QEMU): ./ci.sh test runs it"]
fn the_c_example_flies_like_the_host_and_refuses_a_flipped_blob() {
    assert_qemu();
    let run = &short_run();
    let dir = tempfile::tempdir().unwrap();
    let blob = std::fs::read(model_fit::codegen::default_model().join("model.bin")).expect("the committed blob");
    for blob in [None, Some(blob.clone())] {
        let program = qemu::Program::CExample { blob };
        let replay =
            qemu::qemu_replay(run, Some(2000), dir.path(), Duration::from_secs(120), &program).expect("runs in QEMU");
        println!("{}", qemu::summary(&replay));
        assert_bit_identical(&replay, 2000);
        let trailer = &replay.firmware.trailer;
        assert!(trailer.stack_used < trailer.stack_size, "the C example's stack overflowed: {trailer:?}");
        // The C call checks its pointers, copies its input and dispatches between the two
        // evaluators (measured: max 2,667 with the built-in tables, 3,309 with the blob).
        assert!(replay.cost.estimator_max <= MAX_INSTRUCTIONS_LOADED + 500.0, "{:?}", replay.cost);
    }
    let mut flipped = blob;
    flipped[estimator_core::blob::HEADER_LEN + 40] ^= 0x10;
    let elf = qemu::c_example::build_c_example().expect("builds");
    let status = qemu::c_example::exit_status(&elf, dir.path(), Some(&flipped)).expect("runs in QEMU");
    assert_eq!(status, 16, "ROLLEST_STATUS_BLOB_CRC_MISMATCH");
}

#[test]
#[ignore = "slow tier (QEMU): ./ci.sh test runs it"]
fn firmware_in_qemu_matches_the_host_replay() {
    assert_qemu();
    let run = &short_run();
    let dir = tempfile::tempdir().unwrap();
    let replay = qemu::qemu_replay(
        run,
        Some(2000),
        dir.path(),
        Duration::from_secs(120),
        &qemu::Program::Firmware(qemu::SparseCode::Compiled),
    )
    .expect("runs in QEMU");
    println!("{}", qemu::summary(&replay));
    assert_bit_identical(&replay, 2000);
    let trailer = &replay.firmware.trailer;
    assert!(trailer.stack_used > 0 && trailer.stack_used < trailer.stack_size, "stack {trailer:?}");
    assert!(replay.cost.estimator_mean > 100.0 && replay.cost.total_mean >= replay.cost.estimator_mean);
    assert!(replay.memory.flash > 0 && replay.memory.flash < 1024 * 1024);
}

/// The loop's outputs over the link, run by run, against the host's loop: bit for bit, with no
/// overrun, bad frame or dropped sample, and the step's largest instruction count in budget.
fn assert_flies_like_the_host(result: &hil::HilRun, budget: f64) {
    println!("{}", hil::summary(result));
    let c = &result.comparison;
    assert_eq!(c.steps, result.samples);
    for (name, diff) in hil::COMPARED_FIELDS.iter().zip(&c.max_abs) {
        assert!(*diff == 0.0, "{name}: firmware and host loop differ by {diff:e}");
    }
    assert_eq!(c.steps_not_identical, 0);
    let r = &result.report;
    assert_eq!((r.overruns, r.bad_frames, r.dropped_samples, r.dropped_estimates), (0, 0, 0, 0), "{r:?}");
    assert_eq!(r.steps as usize, result.samples);
    assert!(
        result.timing.estimator_max <= budget,
        "estimator step: max {:.0} instructions, budget {budget}",
        result.timing.estimator_max
    );
}

#[test]
#[ignore = "slow tier (QEMU): ./ci.sh test runs it"]
fn the_real_time_loop_over_the_serial_link_flies_like_the_host() {
    assert_qemu();
    let run = short_run();
    let samples = hil::samples_of(&run, Some(1500));
    let dir = tempfile::tempdir().unwrap();
    let result = hil::hil(&run.meta.file, &samples, None, dir.path()).expect("runs in QEMU");
    assert_eq!(result.tables, "built-in");
    assert_flies_like_the_host(&result, MAX_INSTRUCTIONS_COMPILED);
    assert!(result.timing.latency_max_us > 0.0 && result.timing.latency_max_us < 2_000.0, "{:?}", result.timing);
}

#[test]
#[ignore = "slow tier (QEMU): ./ci.sh test runs it"]
fn a_blob_sent_over_the_link_flies_and_a_corrupted_one_is_refused() {
    assert_qemu();
    let run = short_run();
    let samples = hil::samples_of(&run, Some(800));
    let mut set = estimator_core::coeffs::BUILT_IN;
    // Another set than the built-in one: a different fusion gain changes every fused output.
    set.fusion.gain *= 0.5;
    let blob = model_fit::model::encode(&set).expect("encodes");
    let file = std::path::Path::new("model.bin");
    let dir = tempfile::tempdir().unwrap();
    let loaded = hil::hil(&run.meta.file, &samples, Some((file, &blob)), dir.path()).expect("runs in QEMU");
    assert_eq!(loaded.tables, "loaded blob");
    assert!(loaded.blob.as_ref().is_some_and(|blob| blob.accepted));
    assert_flies_like_the_host(&loaded, MAX_INSTRUCTIONS_LOADED);

    let mut flipped = blob.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 0x10;
    let mut other_schema = blob.clone();
    other_schema[6] ^= 0xFF;
    for (corrupted, reason) in [(flipped, "crc"), (other_schema, "schema")] {
        let dir = tempfile::tempdir().unwrap();
        let refused = hil::hil(&run.meta.file, &samples[..300], Some((file, &corrupted)), dir.path()).expect("runs");
        let outcome = refused.blob.as_ref().expect("a blob was sent");
        assert!(!outcome.accepted);
        assert!(outcome.rejection.as_deref().is_some_and(|why| why.contains(reason)), "{outcome:?}");
        assert_eq!(refused.tables, "built-in", "the built-in tables keep flying");
        assert_flies_like_the_host(&refused, MAX_INSTRUCTIONS_COMPILED);
    }
}
