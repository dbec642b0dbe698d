//! The file replay under QEMU (feature `qemu`): when the semihosting file `firmware-in.bin`
//! exists (the [`firmware_sim::frames`] input format), the firmware steps its samples as fast
//! as the reads deliver, without waiting for a tick, and writes every step's record to
//! `firmware-out.bin`, then a trailer with the timing, the SysTick calibration and the stack
//! high-water mark, and exits with status 0 (`host-tools qemu-replay`). The same estimator
//! and controller as the loop, over the same I/O traits.

use estimator_core::Input;
use estimator_core::coeffs::N_TAPS;
use firmware_sim::frames::{
    HEADER_LEN, INPUT_LEN, MAGIC_INPUT, MAGIC_OUTPUT, OUTPUT_LEN, OutputRecord, Trailer, decode_header, decode_input,
    encode_header, encode_output, encode_trailer,
};
use firmware_sim::io::{FixedRateLoop, InputBoard};
use semihosting::fs::File;
use semihosting::io::{Read, Write};

use crate::board::{BLOCKS, SysTickCounter, fail, stack_high_water};
use crate::clocks::CORE_CLOCK_HZ;

/// Reads the next sample of `input` into `board`; false at the end of the file.
fn next_sample(input: &mut File, board: &mut InputBoard) -> bool {
    let mut bytes = [0u8; INPUT_LEN];
    if input.read_exact(&mut bytes).is_err() {
        return false;
    }
    board.input = decode_input(&bytes);
    true
}

/// Replays `input` and exits QEMU.
pub fn run(mut input: File, calibration_ticks: u32, calibration_instructions: u32) -> ! {
    // The built-in tables with their sparse models as generated code (what flies), or with the
    // feature `interpreted` read from the tables (the cost of a set loaded at run time).
    #[cfg(not(feature = "interpreted"))]
    let mut fixed_rate = FixedRateLoop::built_in(BLOCKS);
    #[cfg(feature = "interpreted")]
    let mut fixed_rate = FixedRateLoop::new(&estimator_core::coeffs::BUILT_IN, BLOCKS);

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

    let nan = f32::NAN;
    let sample = Input { phi_deg: nan, alpha_deg: nan, cmu_port: nan, cmu_stbd: nan, cp: [nan; N_TAPS] };
    let mut board = InputBoard::new(sample);
    let mut ticks = SysTickCounter;
    let mut trailer =
        Trailer { calibration_instructions, calibration_ticks, core_clock_hz: CORE_CLOCK_HZ, ..Trailer::default() };
    while trailer.steps < n_samples && next_sample(&mut input, &mut board) {
        let result = fixed_rate.step(&mut board, &mut ticks);
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
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}
