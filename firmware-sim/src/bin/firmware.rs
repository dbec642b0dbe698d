//! The roll-moment estimator's firmware for the STM32F405 (Cortex-M4F, thumbv7em-none-eabihf).
//!
//! SysTick is the loop's clock: it is configured from the core clock (168 MHz) to wrap at the
//! model's rate (1 kHz), and on the board the loop steps once per wrap (SysTick's COUNTFLAG),
//! reading the sensors through the traits of `firmware_sim::io`. The same SysTick counter times
//! each step (ticks of `Estimator::step` alone and with the controller).
//!
//! Replay under QEMU (`netduinoplus2`): when the semihosting file `firmware-in.bin` exists (the
//! `firmware_sim::frames` input format), the traits read its samples and the loop steps as fast
//! as the reads deliver, without waiting for the tick; every step's output goes to
//! `firmware-out.bin`, then a trailer with the timing, the SysTick calibration (ticks of a
//! counted instruction loop) and the stack high-water mark; the firmware exits through
//! semihosting with status 0. A panic exits with failure.
//!
//! Logging is defmt over semihosting stdout (binary; decode with `defmt-print -e ELF`).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]
// cortex-m-rt's `#[entry]` expands to an exported entry point, and the stack high-water scan
// reads the painted RAM between two linker symbols: the only unsafe code of the package.
#![allow(unsafe_code)]

/// On the host (e.g. `--all-features`), the binary only says where it runs.
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the firmware runs on thumbv7em-none-eabihf (QEMU: host-tools qemu-replay)");
    std::process::exit(2);
}

/// The firmware proper.
#[cfg(target_os = "none")]
mod board {
    use core::cell::RefCell;

    use cortex_m::interrupt::Mutex;
    use cortex_m::peripheral::SYST;
    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m_rt::entry;
    use cortex_m_semihosting::debug;
    use defmt_semihosting as _;
    use estimator_core::Input;
    use estimator_core::coeffs::N_TAPS;
    use estimator_core::controller::Blocks;
    use firmware_sim::frames::{
        HEADER_LEN, INPUT_LEN, MAGIC_INPUT, MAGIC_OUTPUT, OUTPUT_LEN, OutputRecord, Trailer, decode_header,
        decode_input, encode_header, encode_output, encode_trailer,
    };
    use firmware_sim::io::{
        AlphaSource, BlowingMeasurement, BlowingOutput, FixedRateLoop, PressureFrontEnd, RollEncoder, TickCounter,
    };
    use semihosting::fs::File;
    use semihosting::io::{Read, Write};

    /// The core clock: the STM32F405's 168 MHz (and what QEMU's netduinoplus2 models).
    const CORE_CLOCK_HZ: u32 = 168_000_000;
    /// The model's rate (`dt_s` = 1 ms).
    const RATE_HZ: u32 = 1_000;
    /// SysTick reload: one wrap per step.
    const RELOAD: u32 = CORE_CLOCK_HZ / RATE_HZ - 1;
    /// Iterations of the calibration loop (`subs`/`bne`: 2 instructions each).
    const CALIBRATION_LOOPS: u32 = 200_000;

    /// Feedforward on; the board has no balance, so no feedback.
    const BLOCKS: Blocks = Blocks { feedforward: true, feedback: false };

    /// The estimator over the compiled-in tables (`estimator_core::coeffs::BUILT_IN`, in flash)
    /// with their sparse models as generated code: what flies.
    #[cfg(not(feature = "interpreted"))]
    type Loop = FixedRateLoop<'static, estimator_core::coeffs::CompiledDefault>;
    #[cfg(not(feature = "interpreted"))]
    const FRESH: Loop = FixedRateLoop::built_in(BLOCKS);

    /// With the feature `interpreted`: the same tables with the sparse models read from them,
    /// the cost of a coefficient set loaded at run time.
    #[cfg(feature = "interpreted")]
    type Loop = FixedRateLoop<'static>;
    #[cfg(feature = "interpreted")]
    const FRESH: Loop = FixedRateLoop::new(&estimator_core::coeffs::BUILT_IN, BLOCKS);

    /// The estimator and the controller: in a static, never allocated.
    static LOOP: Mutex<RefCell<Loop>> = Mutex::new(RefCell::new(FRESH));

    /// SysTick as the step timer: counts down from [`RELOAD`] at the core clock.
    struct SysTickCounter;

    impl TickCounter for SysTickCounter {
        fn now(&mut self) -> u32 {
            SYST::get_current()
        }

        fn elapsed(&self, start: u32, end: u32) -> u32 {
            // Down-counter: at most one wrap within a step (a step is far below 1 ms).
            if start >= end { start - end } else { start + (RELOAD + 1) - end }
        }
    }

    /// The QEMU board: sensors and valves bound to semihosting files.
    struct ReplayBoard {
        input: File,
        sample: Input,
        demand: [f32; 2],
    }

    impl ReplayBoard {
        /// Loads the next sample; false at the end of the file.
        fn next_sample(&mut self) -> bool {
            let mut bytes = [0u8; INPUT_LEN];
            if self.input.read_exact(&mut bytes).is_err() {
                return false;
            }
            self.sample = decode_input(&bytes);
            true
        }
    }

    impl PressureFrontEnd for ReplayBoard {
        fn read(&mut self) -> [f32; N_TAPS] {
            self.sample.cp
        }
    }

    impl RollEncoder for ReplayBoard {
        fn angle_deg(&mut self) -> f32 {
            self.sample.phi_deg
        }
    }

    impl AlphaSource for ReplayBoard {
        fn alpha_deg(&mut self) -> f32 {
            self.sample.alpha_deg
        }
    }

    impl BlowingMeasurement for ReplayBoard {
        fn cmu(&mut self) -> [f32; 2] {
            [self.sample.cmu_port, self.sample.cmu_stbd]
        }
    }

    impl BlowingOutput for ReplayBoard {
        fn set_cmu(&mut self, cmu: [f32; 2]) {
            self.demand = cmu;
        }
    }

    #[entry]
    fn main() -> ! {
        let Some(mut core) = cortex_m::Peripherals::take() else { fail("core peripherals taken twice") };
        core.SYST.set_clock_source(SystClkSource::Core);
        core.SYST.set_reload(RELOAD);
        core.SYST.clear_current();
        core.SYST.enable_counter();
        let calibration_ticks = calibrate();
        defmt::println!("roll-moment estimator firmware: SysTick {=u32} Hz / {=u32} Hz", CORE_CLOCK_HZ, RATE_HZ);

        let Ok(mut input) = File::open(c"firmware-in.bin") else {
            // The board build would bind the traits to the ADC front end, the encoder and the valve
            // drivers here and step on every SysTick wrap; only the QEMU replay exists so far.
            fail("no firmware-in.bin: only the QEMU replay is implemented");
        };
        let mut header = [0u8; HEADER_LEN];
        if input.read_exact(&mut header).is_err() {
            fail("input header");
        }
        let Ok(n_samples) = decode_header(&header, MAGIC_INPUT, INPUT_LEN) else { fail("input header") };
        let Ok(mut output) = File::create(c"firmware-out.bin") else { fail("cannot create firmware-out.bin") };
        if output.write_all(&encode_header(MAGIC_OUTPUT, n_samples, OUTPUT_LEN)).is_err() {
            fail("output header");
        }
        defmt::println!("replaying {=u32} samples", n_samples);

        let mut board = ReplayBoard { input, sample: empty_sample(), demand: [0.0; 2] };
        let mut ticks = SysTickCounter;
        let mut trailer = Trailer {
            calibration_instructions: 2 * (CALIBRATION_LOOPS + 1),
            calibration_ticks,
            core_clock_hz: CORE_CLOCK_HZ,
            ..Trailer::default()
        };
        while trailer.steps < n_samples && board.next_sample() {
            // Replay: step as fast as the reads deliver. The board would wait for the tick here:
            // `while !core.SYST.has_wrapped() {}`.
            let result = cortex_m::interrupt::free(|cs| LOOP.borrow(cs).borrow_mut().step(&mut board, &mut ticks));
            let record = OutputRecord {
                output: result.output,
                demand: result.demand,
                controller_flags: result.controller_health.flags,
                ticks_estimator: result.ticks_estimator,
                ticks_total: result.ticks_total,
            };
            if output.write_all(&encode_output(&record)).is_err() {
                fail("output record");
            }
            trailer.steps += 1;
            trailer.estimator_ticks_sum += u64::from(result.ticks_estimator);
            trailer.estimator_ticks_max = trailer.estimator_ticks_max.max(result.ticks_estimator);
            trailer.total_ticks_sum += u64::from(result.ticks_total);
            trailer.total_ticks_max = trailer.total_ticks_max.max(result.ticks_total);
        }
        let (stack_used, stack_size) = stack_high_water();
        trailer.stack_used = stack_used;
        trailer.stack_size = stack_size;
        if output.write_all(&encode_trailer(&trailer)).is_err() {
            fail("trailer");
        }
        drop(output);
        defmt::println!(
            "done: {=u32} steps, last demand {=f32} {=f32}, stack {=u32} of {=u32} bytes",
            trailer.steps,
            board.demand[0],
            board.demand[1],
            stack_used,
            stack_size
        );
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// SysTick ticks of a loop of `2 * (CALIBRATION_LOOPS + 1)` instructions: with QEMU's
    /// `-icount shift=0` (1 ns per instruction) and a 168 MHz SysTick this is 0.168 per instruction.
    fn calibrate() -> u32 {
        let mut ticks = SysTickCounter;
        let start = ticks.now();
        cortex_m::asm::delay(CALIBRATION_LOOPS);
        let end = ticks.now();
        ticks.elapsed(start, end)
    }

    /// All NaN: nothing measured yet.
    fn empty_sample() -> Input {
        Input { phi_deg: f32::NAN, alpha_deg: f32::NAN, cmu_port: f32::NAN, cmu_stbd: f32::NAN, cp: [f32::NAN; N_TAPS] }
    }

    /// Stack bytes used so far (from the lowest word that lost cortex-m-rt's paint) and available.
    fn stack_high_water() -> (u32, u32) {
        unsafe extern "C" {
            static _stack_end: u32;
            static _stack_start: u32;
        }
        let bottom = (&raw const _stack_end) as usize;
        let top = (&raw const _stack_start) as usize;
        let mut lowest = bottom;
        // SAFETY: [bottom, top) is the stack region of link.x, word-aligned RAM that cortex-m-rt
        // painted at reset; reading it is side-effect free.
        while lowest < top
            && unsafe { core::ptr::read_volatile(lowest as *const u32) } == cortex_m_rt::STACK_PAINT_VALUE
        {
            lowest += 4;
        }
        ((top - lowest) as u32, (top - bottom) as u32)
    }

    /// Logs `why` and exits through semihosting with failure.
    fn fail(why: &str) -> ! {
        defmt::println!("firmware failed: {=str}", why);
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::println!("panic: {}", defmt::Display2Format(info));
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }
}
