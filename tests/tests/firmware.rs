//! The firmware built for the STM32F405 and run in QEMU (netduinoplus2) replays a short
//! simulated run; every output field must match the host replay. Needs `qemu-system-arm`
//! (`./ci.sh setup` installs it): without it the test fails, it is never skipped.

use std::time::Duration;

use firmware_sim::campaign::{KindName, Scenario};
use firmware_sim::dataset::RunKind;
use host_tools::qemu;

/// Both sides run the same f32 code on bit-identical inputs: the only allowed difference is
/// round-off from a different instruction selection (FMA contraction, libm), far below this.
const MAX_ABS_DIFF: f32 = 1e-5;

#[test]
fn firmware_in_qemu_matches_the_host_replay() {
    let qemu_found =
        std::process::Command::new(qemu::QEMU).arg("--version").output().is_ok_and(|out| out.status.success());
    assert!(qemu_found, "{} is not installed: run `./ci.sh setup` (apt-get install qemu-system-arm)", qemu::QEMU);
    let scenario = Scenario {
        duration_s: 4.0,
        alphas_deg: vec![20.0],
        kinds: vec![KindName(RunKind::RollActuation)],
        ..Scenario::default()
    };
    let dataset = scenario.simulate(&|| {}).expect("simulates");
    let run = &dataset.runs[0];
    let dir = tempfile::tempdir().unwrap();
    let replay = qemu::qemu_replay(run, Some(2000), dir.path(), Duration::from_secs(120), qemu::SparseCode::Compiled)
        .expect("runs in QEMU");
    println!("{}", qemu::summary(&replay));
    let comparison = &replay.comparison;
    assert_eq!(comparison.steps, 2000);
    for (name, diff) in firmware_sim::frames::OUTPUT_FIELD_NAMES.iter().zip(comparison.max_abs) {
        assert!(diff < MAX_ABS_DIFF, "{name}: firmware and host replay differ by {diff:e}");
    }
    assert_eq!(comparison.health_mismatches, 0, "health bits differ");
    let trailer = &replay.firmware.trailer;
    assert!(trailer.stack_used > 0 && trailer.stack_used < trailer.stack_size, "stack {trailer:?}");
    assert!(replay.cost.estimator_mean > 100.0 && replay.cost.total_mean >= replay.cost.estimator_mean);
    assert!(replay.memory.flash > 0 && replay.memory.flash < 1024 * 1024);
}
