//! The C interface from Rust: the committed header is what `cargo xtask header` generates, with
//! the crate's version; the library's estimates are the core's bit for bit (built-in tables and
//! a loaded blob); every bad pointer, storage or blob gets its documented code; and the library
//! reports its version and struct sizes for the program's start-up check.

extern crate std;

use std::boxed::Box;
use std::mem::size_of;
use std::path::Path;
use std::vec;
use std::vec::Vec;

use estimator_core::blob::HEADER_LEN;
use estimator_core::{Estimator, Input, Output};

use crate::*;

/// The C functions, called as C calls them. The pointers the tests pass are NULL, dangling only
/// where a check must refuse them before use (misaligned storage), or valid.
mod c {
    #![allow(clippy::undocumented_unsafe_blocks)]
    use crate::*;

    pub fn init_built_in(storage: *mut RollestEstimator, len: usize) -> RollestStatus {
        unsafe { rollest_init_built_in(storage, len) }
    }
    pub fn init_blob(storage: *mut RollestEstimator, len: usize, blob: *const u8, blob_len: usize) -> RollestStatus {
        unsafe { rollest_init_blob(storage, len, blob, blob_len) }
    }
    pub fn step(
        storage: *mut RollestEstimator,
        input: *const RollestInput,
        output: *mut RollestOutput,
    ) -> RollestStatus {
        unsafe { rollest_step(storage, input, output) }
    }
    pub fn note_demand(storage: *mut RollestEstimator, port: f32, stbd: f32) -> RollestStatus {
        unsafe { rollest_note_demand(storage, port, stbd) }
    }
    pub fn reset(storage: *mut RollestEstimator) -> RollestStatus {
        unsafe { rollest_reset(storage) }
    }
    pub fn dt_s(storage: *mut RollestEstimator, dt_s: *mut f32) -> RollestStatus {
        unsafe { rollest_dt_s(storage, dt_s) }
    }
}

fn workspace() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// Storage on the heap (8 KiB would crowd a test thread's stack), zeroed like a C `static`.
fn storage() -> Box<RollestEstimator> {
    Box::new(RollestEstimator::new())
}

fn c_input(input: &Input) -> RollestInput {
    RollestInput {
        phi_deg: input.phi_deg,
        alpha_deg: input.alpha_deg,
        cmu_port: input.cmu_port,
        cmu_stbd: input.cmu_stbd,
        cp: input.cp,
    }
}

/// Inputs with gaps, spikes and a stuck channel, from a sine roll.
fn inputs(n: usize) -> Vec<Input> {
    (0..n)
        .map(|k| {
            let t_s = k as f32 * 1e-3;
            let phi_deg = 25.0 * (3.0 * t_s).sin();
            let mut cp: [f32; 12] = std::array::from_fn(|tap| -0.5 + 0.01 * tap as f32 + 0.002 * phi_deg);
            if k % 97 == 0 {
                cp[3] = f32::NAN;
            }
            if k > 1500 {
                cp[7] = 0.25;
            }
            let cmu_port = if (k / 400) % 2 == 0 { 0.004 } else { 0.0 };
            Input {
                phi_deg: if k % 251 == 0 { f32::NAN } else { phi_deg },
                alpha_deg: 20.0,
                cmu_port,
                cmu_stbd: if k % 313 == 0 { f32::INFINITY } else { 0.0 },
                cp,
            }
        })
        .collect()
}

fn same_bits(c: &RollestOutput, rust: &Output) -> bool {
    let c_fields = [
        c.cl_egk,
        c.cl_pressure,
        c.cl_roll,
        c.cl_afc_port,
        c.cl_afc_stbd,
        c.cl_afc,
        c.cl_linear,
        c.coupling,
        c.cl,
        c.phi_dot_rad_s,
    ];
    let health = &rust.health;
    c_fields.iter().zip(rust.estimates()).all(|(a, b)| a.to_bits() == b.to_bits())
        && (c.health.flags, c.health.cp_missing, c.health.cp_rejected, c.health.cp_isolated)
            == (health.flags, health.cp_missing, health.cp_rejected, health.cp_isolated)
}

/// Steps the C interface and `rust` side by side over `inputs`, noting a demand after each step.
fn assert_bit_identical(est: &mut RollestEstimator, rust: &mut Estimator<'_, impl estimator_core::sparse::SparseEval>) {
    for (k, input) in inputs(3000).iter().enumerate() {
        let mut out = RollestOutput::default();
        assert_eq!(c::step(est, &c_input(input), &mut out), RollestStatus::Ok);
        let expected = rust.step(input);
        assert!(same_bits(&out, &expected), "step {k}: {out:?} against {expected:?}");
        let demand = [0.003, f32::NAN];
        assert_eq!(c::note_demand(est, demand[0], demand[1]), RollestStatus::Ok);
        rust.note_demand(demand);
    }
}

fn committed_header() -> std::string::String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("include/roll_estimator.h"))
        .expect("the committed header")
}

#[test]
fn the_committed_header_is_what_cbindgen_generates() {
    let text = crate::header::generate(Path::new(env!("CARGO_MANIFEST_DIR"))).expect("generates the header");
    assert!(
        committed_header().as_bytes() == text,
        "estimator-ffi/include/roll_estimator.h is stale: run `cargo xtask header`"
    );
}

#[test]
fn the_headers_version_and_the_librarys_are_the_crates() {
    // Computed here from the whole version string, apart from the const fn that reads its parts.
    let parts: Vec<u32> = env!("CARGO_PKG_VERSION")
        .split(['-', '+'])
        .next()
        .expect("a version")
        .split('.')
        .map(|part| part.parse().expect("a decimal version part"))
        .collect();
    let expected = parts[0] * 10000 + parts[1] * 100 + parts[2];
    let header = committed_header();
    let define = header
        .lines()
        .find_map(|line| line.strip_prefix("#define ROLLEST_VERSION "))
        .expect("the header defines ROLLEST_VERSION");
    assert_eq!(define.parse::<u32>(), Ok(expected), "the header's ROLLEST_VERSION: run `cargo xtask header`");
    assert_eq!(rollest_version(), expected);
    assert_eq!(ROLLEST_VERSION, expected);
}

#[test]
fn the_library_reports_the_size_of_every_public_struct() {
    assert_eq!(rollest_struct_size(RollestStruct::Estimator as i32), size_of::<RollestEstimator>());
    assert_eq!(rollest_struct_size(RollestStruct::Input as i32), size_of::<RollestInput>());
    assert_eq!(rollest_struct_size(RollestStruct::Output as i32), size_of::<RollestOutput>());
    assert_eq!(rollest_struct_size(RollestStruct::Health as i32), size_of::<RollestHealth>());
    // Any other integer C passes is no struct.
    for unknown in [-1, 4, i32::MAX, i32::MIN] {
        assert_eq!(rollest_struct_size(unknown), 0, "code {unknown}");
    }
}

#[test]
fn the_built_in_tables_step_like_the_core() {
    let mut est = storage();
    assert_eq!(c::init_built_in(&mut *est, size_of::<RollestEstimator>()), RollestStatus::Ok);
    assert_bit_identical(&mut est, &mut Estimator::built_in());
    // A reset returns to the fresh state: the same outputs again.
    assert_eq!(c::reset(&mut *est), RollestStatus::Ok);
    assert_bit_identical(&mut est, &mut Estimator::built_in());
}

#[test]
fn a_blob_steps_like_the_core_on_its_tables_and_a_flipped_bit_is_refused() {
    let blob = std::fs::read(workspace().join("models/default/model.bin")).expect("the committed blob");
    let set = estimator_core::blob::decode(&blob).expect("decodes");
    let mut est = storage();
    let status = c::init_blob(&mut *est, size_of::<RollestEstimator>(), blob.as_ptr(), blob.len());
    assert_eq!(status, RollestStatus::Ok);
    let mut dt_s = 0.0;
    assert_eq!(c::dt_s(&mut *est, &mut dt_s), RollestStatus::Ok);
    assert_eq!(dt_s, set.dt_s);
    assert_bit_identical(&mut est, &mut Estimator::new(&set));

    // A flipped payload bit fails the CRC, and leaves the storage refusing to step.
    let mut flipped = blob.clone();
    flipped[HEADER_LEN + 40] ^= 0x10;
    let status = c::init_blob(&mut *est, size_of::<RollestEstimator>(), flipped.as_ptr(), flipped.len());
    assert_eq!(status, RollestStatus::BlobCrcMismatch);
    let mut out = RollestOutput::default();
    assert_eq!(c::step(&mut *est, &c_input(&inputs(1)[0]), &mut out), RollestStatus::NotInitialised);
    let mut bad_magic = blob.clone();
    bad_magic[0] ^= 1;
    assert_eq!(
        c::init_blob(&mut *est, size_of::<RollestEstimator>(), bad_magic.as_ptr(), bad_magic.len()),
        RollestStatus::BlobBadMagic
    );
    assert_eq!(
        c::init_blob(&mut *est, size_of::<RollestEstimator>(), blob.as_ptr(), blob.len() - 1),
        RollestStatus::BlobLengthMismatch
    );
    assert_eq!(c::init_blob(&mut *est, size_of::<RollestEstimator>(), blob.as_ptr(), 3), RollestStatus::BlobTooShort);
}

#[test]
fn every_bad_pointer_and_storage_gets_its_code() {
    let input = c_input(&inputs(1)[0]);
    let mut out = RollestOutput::default();
    let null = std::ptr::null_mut::<RollestEstimator>();
    assert_eq!(c::init_built_in(null, size_of::<RollestEstimator>()), RollestStatus::NullPointer);
    assert_eq!(c::step(null, &input, &mut out), RollestStatus::NullPointer);
    let mut est = storage();
    assert_eq!(c::init_built_in(&mut *est, size_of::<RollestEstimator>() - 8), RollestStatus::StorageTooSmall);
    assert_eq!(c::step(&mut *est, &input, &mut out), RollestStatus::NotInitialised, "never initialised");
    assert_eq!(c::init_built_in(&mut *est, size_of::<RollestEstimator>()), RollestStatus::Ok);
    assert_eq!(c::step(&mut *est, std::ptr::null(), &mut out), RollestStatus::NullPointer);
    assert_eq!(c::step(&mut *est, &input, std::ptr::null_mut()), RollestStatus::NullPointer);
    assert_eq!(c::dt_s(&mut *est, std::ptr::null_mut()), RollestStatus::NullPointer);
    let blob_null = c::init_blob(&mut *est, size_of::<RollestEstimator>(), std::ptr::null(), 10);
    assert_eq!(blob_null, RollestStatus::NullPointer);

    // Misaligned input and output structs: one byte into aligned buffers.
    let mut words = vec![0u32; 64];
    let odd = words.as_mut_ptr().cast::<u8>().wrapping_add(1);
    assert_eq!(c::step(&mut *est, odd.cast(), &mut out), RollestStatus::Misaligned);
    assert_eq!(c::step(&mut *est, &input, odd.cast()), RollestStatus::Misaligned);

    // Misaligned storage: one byte into an aligned buffer.
    let mut bytes = vec![0u64; size_of::<RollestEstimator>() / 8 + 1];
    let misaligned = bytes.as_mut_ptr().cast::<u8>().wrapping_add(1).cast::<RollestEstimator>();
    assert_eq!(c::init_built_in(misaligned, size_of::<RollestEstimator>()), RollestStatus::Misaligned);

    // A copy of initialised storage refers to the original's address: refused, not followed.
    let mut fine = storage();
    assert_eq!(c::init_built_in(&mut *fine, size_of::<RollestEstimator>()), RollestStatus::Ok);
    // A bitwise copy, as C's memcpy or struct assignment makes.
    let mut copied = fine.clone();
    assert_eq!(c::step(&mut *copied, &input, &mut out), RollestStatus::Moved);
    assert_eq!(c::step(&mut *fine, &input, &mut out), RollestStatus::Ok);
}

#[test]
fn every_status_has_its_text() {
    // `rollest_status_text` hands C the static strings of `RollestStatus::text_of`.
    for code in -7..25 {
        assert_eq!(rollest_status_text(code), RollestStatus::text_of(code).as_ptr(), "code {code}");
    }
    let text = |code: i32| RollestStatus::text_of(code).to_str().expect("ASCII").to_owned();
    assert_eq!(text(0), "ok");
    assert_eq!(text(16), "blob: payload CRC-32 mismatch");
    assert_eq!(text(-7), "unknown status code");
    assert_eq!(text(RollestStatus::Moved as i32), "the estimator was copied or moved after initialisation");
}

#[test]
fn the_health_bits_are_the_cores() {
    use estimator_core::Health;
    let pairs = [
        (ROLLEST_HEALTH_PHI_HELD, Health::PHI_HELD),
        (ROLLEST_HEALTH_ALPHA_HELD, Health::ALPHA_HELD),
        (ROLLEST_HEALTH_CMU_HELD, Health::CMU_HELD),
        (ROLLEST_HEALTH_INPUT_CLAMPED, Health::INPUT_CLAMPED),
        (ROLLEST_HEALTH_PRESSURE_UNUSED, Health::PRESSURE_UNUSED),
        (ROLLEST_HEALTH_STATE_RESET, Health::STATE_RESET),
        (ROLLEST_HEALTH_CMU_SATURATED, Health::CMU_SATURATED),
        (ROLLEST_HEALTH_FEEDBACK_HELD, Health::FEEDBACK_HELD),
        (ROLLEST_HEALTH_ESTIMATE_LIMITED, Health::ESTIMATE_LIMITED),
        (ROLLEST_HEALTH_CMU_FROM_DEMAND, Health::CMU_FROM_DEMAND),
        (ROLLEST_HEALTH_PRESSURE_SETTLING, Health::PRESSURE_SETTLING),
    ];
    for (c, core) in pairs {
        assert_eq!(c, core);
    }
}
