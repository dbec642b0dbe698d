//! Link-time proof that the firmware's step has no panic path on the Cortex-M4F.
//!
//! The binary runs the firmware's fixed-rate loop (`firmware_sim::io::FixedRateLoop`: the
//! estimator, `note_demand` and the controller) twice: over the built-in tables with their
//! generated code, and over a coefficient set the optimiser cannot know: decoded at run time from
//! a blob read with `read_volatile` (the blob decoder's checks are part of the proof), or, when
//! that fails, a whole `CoefficientSet` read with `read_volatile` (any bit pattern: the step must
//! stay panic-free with any tables). The inputs are read with `read_volatile` each step too. Its
//! panic handler calls `estimator_step_has_a_panic_path`, a symbol that no object defines. With
//! fat LTO (the `firmware` profile) every panic the optimiser can prove unreachable is removed;
//! if any path to `core::panicking` survives, the handler is referenced and the link fails with
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
    use estimator_core::CoefficientSet;
    use estimator_core::blob::MAX_BLOB_LEN;
    use estimator_core::coeffs::N_TAPS;
    use firmware_sim::io::{
        AlphaSource, BlowingMeasurement, BlowingOutput, FixedRateLoop, PressureFrontEnd, RollEncoder, TickCounter,
    };
    use firmware_sim::link::FIRMWARE_BLOCKS;
    // The device crate's interrupt vectors, which cortex-m-rt's `device` feature links against.
    use stm32f4 as _;

    /// A coefficient set's image: read with `read_volatile`, so for the optimiser any tables.
    static SET_IMAGE: CoefficientSet = estimator_core::coeffs::DEFAULT;
    /// A blob's bytes, read with `read_volatile`: any bytes.
    static BLOB: [u8; MAX_BLOB_LEN] = [0; MAX_BLOB_LEN];

    /// One step's inputs, read with `read_volatile`: for the optimiser any values.
    static INPUTS: [f32; 4 + N_TAPS] = [0.0; 4 + N_TAPS];

    // The one symbol that must stay unreferenced: defined nowhere, on purpose.
    unsafe extern "C" {
        fn estimator_step_has_a_panic_path() -> !;
    }

    /// Sensors that may read anything, valves and a clock.
    struct VolatileBoard {
        inputs: [f32; 4 + N_TAPS],
        demand: [f32; 2],
    }

    impl VolatileBoard {
        fn sample(&mut self) {
            // SAFETY: INPUTS is a valid, aligned, immutable static of a `Copy` type.
            self.inputs = unsafe { core::ptr::read_volatile(&raw const INPUTS) };
        }
    }

    impl PressureFrontEnd for VolatileBoard {
        fn read(&mut self) -> [f32; N_TAPS] {
            core::array::from_fn(|tap| self.inputs[4 + tap])
        }
    }
    impl RollEncoder for VolatileBoard {
        fn angle_deg(&mut self) -> f32 {
            self.inputs[0]
        }
    }
    impl AlphaSource for VolatileBoard {
        fn alpha_deg(&mut self) -> f32 {
            self.inputs[1]
        }
    }
    impl BlowingMeasurement for VolatileBoard {
        fn cmu(&mut self) -> [f32; 2] {
            [self.inputs[2], self.inputs[3]]
        }
    }
    impl BlowingOutput for VolatileBoard {
        fn set_cmu(&mut self, cmu: [f32; 2]) {
            self.demand = cmu;
        }
    }
    impl TickCounter for VolatileBoard {
        fn now(&mut self) -> u32 {
            // SAFETY: as in `sample`.
            let inputs = unsafe { core::ptr::read_volatile(&raw const INPUTS) };
            inputs[0].to_bits()
        }
        fn elapsed(&self, start: u32, end: u32) -> u32 {
            end.wrapping_sub(start)
        }
    }

    #[entry]
    fn main() -> ! {
        // SAFETY: BLOB and SET_IMAGE are valid, aligned, immutable statics of `Copy` types.
        let blob = unsafe { core::ptr::read_volatile(&raw const BLOB) };
        let set = match estimator_core::blob::decode(&blob) {
            Ok(set) => set,
            // SAFETY: as above.
            Err(_) => unsafe { core::ptr::read_volatile(&raw const SET_IMAGE) },
        };
        let mut loaded = FixedRateLoop::new(&set, FIRMWARE_BLOCKS);
        let mut built_in = FixedRateLoop::built_in(FIRMWARE_BLOCKS);
        let mut board = VolatileBoard { inputs: [0.0; 4 + N_TAPS], demand: [0.0; 2] };
        let mut clock = VolatileBoard { inputs: [0.0; 4 + N_TAPS], demand: [0.0; 2] };
        loop {
            board.sample();
            let results = [loaded.step(&mut board, &mut clock), built_in.step(&mut board, &mut clock)];
            // Keep the results observable so that the steps are not optimised away.
            // SAFETY: `results` and `board` are live locals; the volatile reads only prevent elision.
            let _ = unsafe { core::ptr::read_volatile(&raw const results) };
            let _ = unsafe { core::ptr::read_volatile(&raw const board.demand) };
        }
    }

    #[panic_handler]
    fn panic(_info: &core::panic::PanicInfo) -> ! {
        // SAFETY: never executed if the link succeeds: the symbol is undefined on purpose.
        unsafe { estimator_step_has_a_panic_path() }
    }
}
