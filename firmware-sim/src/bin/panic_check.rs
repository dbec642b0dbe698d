//! Link-time proof that `Estimator::step` has no panic path on the Cortex-M4F.
//!
//! The binary calls nothing but the estimator's step, on inputs read with `read_volatile` from a
//! `static` (so the optimiser cannot const-fold them and drop a branch), and its panic handler
//! calls `estimator_step_has_a_panic_path`, a symbol that no object defines. With fat LTO (the
//! `firmware` profile) every panic the optimiser can prove unreachable is removed; if any path to
//! `core::panicking` survives, the handler is referenced and the link fails with
//! `undefined symbol: estimator_step_has_a_panic_path`. CI builds it in the `nostd` job:
//!
//! ```sh
//! cargo build -p firmware-sim --bin panic_check --no-default-features --features target \
//!     --target thumbv7em-none-eabihf --profile firmware
//! ```
//!
//! To check that the proof still bites, add a panic path to the step (for example
//! `let _ = [0u8; 4][input.cp[0] as usize];` at the top of `Estimator::step`), build as above
//! and expect the link error; then revert.
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]
// cortex-m-rt's `#[entry]` expands to an exported entry point, and the inputs are read with
// `read_volatile`: the unsafe code of this binary.
#![allow(unsafe_code)]

/// On the host (e.g. `--all-features`), the binary only says where it is built.
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("panic_check is a link-time check for thumbv7em-none-eabihf; it is built, never run");
    std::process::exit(2);
}

/// The check proper.
#[cfg(target_os = "none")]
mod board {
    use cortex_m_rt::entry;
    use estimator_core::coeffs::N_TAPS;
    use estimator_core::{CoefficientSet, Estimator, Input};
    // The device crate's interrupt vectors, which cortex-m-rt's `device` feature links against.
    use stm32f4 as _;

    /// The compiled-in coefficient tables, as the firmware flies them.
    static SET: CoefficientSet = estimator_core::coeffs::DEFAULT;

    /// The inputs, read with `read_volatile` each step: for the optimiser any value is possible.
    static INPUT: Input = Input { phi_deg: 0.0, alpha_deg: 0.0, cmu_port: 0.0, cmu_stbd: 0.0, cp: [0.0; N_TAPS] };

    // The one symbol that must stay unreferenced: defined nowhere, on purpose.
    unsafe extern "C" {
        fn estimator_step_has_a_panic_path() -> !;
    }

    #[entry]
    fn main() -> ! {
        // Both evaluations of the sparse models: from the tables (any loaded set) and the
        // built-in set's generated code (what the firmware flies).
        let mut estimator = Estimator::new(&SET);
        let mut compiled = Estimator::built_in();
        loop {
            // SAFETY: INPUT is a valid, aligned, immutable static of a `Copy` type.
            let input = unsafe { core::ptr::read_volatile(&raw const INPUT) };
            let outputs = [estimator.step(&input), compiled.step(&input)];
            // Keep the outputs observable so that the steps are not optimised away.
            // SAFETY: `outputs` is a live local; the volatile read only prevents elision.
            let _ = unsafe { core::ptr::read_volatile(&raw const outputs) };
        }
    }

    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        // SAFETY: never executed if the link succeeds: the symbol is undefined on purpose.
        unsafe { estimator_step_has_a_panic_path() }
    }
}
