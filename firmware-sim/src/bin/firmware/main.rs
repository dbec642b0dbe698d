//! The roll-moment estimator's firmware for the STM32F405 (Cortex-M4F, thumbv7em-none-eabihf),
//! the MCU of most F4 flight controllers.
//!
//! The loop ([`tick`]): SysTick's exception at 1 kHz steps the estimator and the
//! controller on the oldest sample the serial link delivered, and queues the estimate. The main
//! loop ([`board::run_link`]) moves bytes between USART1 ([`serial`]) and the queues, decodes and
//! checks frames ([`firmware_sim::link`]), loads a coefficient blob sent over the link, answers
//! reports, and sleeps (`wfi`) when there is nothing to do. SysTick also times each step and each
//! sample's latency.
//!
//! Features: `target` builds the board firmware (defmt over RTT: `probe-rs run` prints it);
//! `qemu` adds semihosting: defmt goes to QEMU's stdout, [`firmware_sim::link::ToFirmware::Stop`]
//! exits QEMU, and when the semihosting file `firmware-in.bin` exists the firmware replays it
//! instead of listening on the link ([`replay`], used by `host-tools qemu-replay`).
#![cfg_attr(target_os = "none", no_std)]
#![cfg_attr(target_os = "none", no_main)]
// cortex-m-rt's `#[entry]` and `#[interrupt]` expand to exported symbols, NVIC priorities and
// the USART's baud register are `unsafe` to write, and the stack high-water scan reads the
// painted RAM between two linker symbols: the only unsafe code of the package.
#![allow(unsafe_code)]

/// On the host (e.g. `--all-features`), the binary only says where it runs.
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the firmware runs on thumbv7em-none-eabihf (QEMU: host-tools hil or qemu-replay)");
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod clocks;
#[cfg(all(target_os = "none", feature = "qemu"))]
mod replay;
#[cfg(target_os = "none")]
mod serial;
#[cfg(target_os = "none")]
mod tick;

/// The firmware proper.
#[cfg(target_os = "none")]
mod board {
    use cortex_m::peripheral::scb::SystemHandler;
    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m_rt::entry;
    use estimator_core::CoefficientSet;
    use estimator_core::controller::Blocks;
    use firmware_sim::io::{FixedRateLoop, TickCounter};

    pub use crate::tick::SysTickCounter;
    use embedded_io::{Read, ReadReady, Write};
    use firmware_sim::link::{
        self, BlobRejection, Estimate, FrameDecoder, FromFirmware, LinkReport, MAX_FRAME_LEN, PROTOCOL_VERSION, Tables,
        ToFirmware,
    };
    use heapless::spsc::{Consumer, Producer, Queue};
    use static_cell::StaticCell;
    use stm32f4::stm32f405 as pac;

    use crate::clocks::{self, CORE_CLOCK_HZ};
    use crate::serial::{self, RxQueue, SerialPort, TxQueue};
    use crate::tick::{self, Flying, PERIOD_TICKS, Pending, RATE_HZ};

    #[cfg(not(feature = "qemu"))]
    use defmt_rtt as _;
    #[cfg(feature = "qemu")]
    use defmt_semihosting as _;

    /// Feedforward on; the board has no balance, so no feedback.
    pub const BLOCKS: Blocks = link::FIRMWARE_BLOCKS;
    /// Iterations of the calibration loop (`subs`/`bne`: 2 instructions each).
    const CALIBRATION_LOOPS: u32 = 200_000;
    /// Samples that may wait for their tick (a rig streaming at the loop's rate keeps one or two).
    const SAMPLE_QUEUE: usize = 8;
    /// Estimates that may wait for the link.
    const ESTIMATE_QUEUE: usize = 8;
    /// Priorities (upper 4 bits on the STM32F4; lower is more urgent): the USART above the loop's
    /// SysTick.
    const USART_PRIORITY: u8 = 0x40;
    const TIMER_PRIORITY: u8 = 0x80;

    static RX: StaticCell<RxQueue> = StaticCell::new();
    static TX: StaticCell<TxQueue> = StaticCell::new();
    static SAMPLES: StaticCell<Queue<Pending, SAMPLE_QUEUE>> = StaticCell::new();
    static ESTIMATES: StaticCell<Queue<Estimate, ESTIMATE_QUEUE>> = StaticCell::new();
    static FLYING: StaticCell<Flying> = StaticCell::new();
    static BLOB: StaticCell<heapless::Vec<u8, { estimator_core::blob::MAX_BLOB_LEN }>> = StaticCell::new();
    /// The one coefficient set a boot can load (the estimator borrows it for good; load another
    /// by resetting the board).
    static LOADED: StaticCell<CoefficientSet> = StaticCell::new();

    #[entry]
    fn main() -> ! {
        let Some(mut core) = cortex_m::Peripherals::take() else { fail("core peripherals taken twice") };
        let Some(device) = pac::Peripherals::take() else { fail("device peripherals taken twice") };
        let clock_state = clocks::configure(&device.RCC, &device.FLASH);
        core.SYST.set_clock_source(SystClkSource::Core);
        core.SYST.set_reload(PERIOD_TICKS - 1);
        core.SYST.clear_current();
        core.SYST.enable_counter();
        let calibration_ticks = calibrate();
        defmt::println!("roll-moment estimator firmware: clocks {}, core {=u32} Hz", clock_state, CORE_CLOCK_HZ);

        #[cfg(feature = "qemu")]
        if let Ok(input) = semihosting::fs::File::open(c"firmware-in.bin") {
            crate::replay::run(input, calibration_ticks, 2 * (CALIBRATION_LOOPS + 1));
        }

        defmt::println!("loop {=u32} Hz", RATE_HZ);
        let port = serial::start(device.USART1, &device.GPIOA, RX.init(Queue::new()), TX.init(Queue::new()));
        let (samples_in, samples_out) = SAMPLES.init(Queue::new()).split();
        let (estimates_in, estimates_out) = ESTIMATES.init(Queue::new()).split();
        let flying = FLYING.init(Flying::BuiltIn(FixedRateLoop::built_in(BLOCKS)));
        // SAFETY: setting priorities before the interrupts are enabled; no priority-based
        // critical section relies on them.
        unsafe {
            core.NVIC.set_priority(pac::Interrupt::USART1, USART_PRIORITY);
            core.SCB.set_priority(SystemHandler::SysTick, TIMER_PRIORITY);
            cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1);
        }
        tick::start(&mut core.SYST, flying, samples_out, estimates_in);
        let mut link = Link {
            port,
            samples: samples_in,
            estimates: estimates_out,
            decoder: FrameDecoder::new(),
            blob: BLOB.init(heapless::Vec::new()),
            blob_len: None,
            tables: Tables::BuiltIn,
            bad_frames: 0,
            dropped_samples: 0,
            calibration_ticks,
        };
        link.send(&link.hello());
        link.run()
    }

    /// The main loop's ends of the queues and what it keeps.
    struct Link {
        port: SerialPort,
        samples: Producer<'static, Pending>,
        estimates: Consumer<'static, Estimate>,
        decoder: FrameDecoder,
        blob: &'static mut heapless::Vec<u8, { estimator_core::blob::MAX_BLOB_LEN }>,
        /// The announced length of the blob being received.
        blob_len: Option<u32>,
        tables: Tables,
        bad_frames: u32,
        dropped_samples: u32,
        calibration_ticks: u32,
    }

    impl Link {
        /// Serves the link for ever (or until `Stop` under QEMU).
        fn run(&mut self) -> ! {
            loop {
                let mut busy = false;
                let mut bytes = [0u8; 64];
                while self.port.read_ready().unwrap_or(false) {
                    busy = true;
                    let n = self.port.read(&mut bytes).unwrap_or(0);
                    for &byte in &bytes[..n] {
                        match self.decoder.push(byte) {
                            Some(Ok(())) => self.handle_frame(),
                            Some(Err(_)) => self.bad_frames = self.bad_frames.wrapping_add(1),
                            None => {}
                        }
                    }
                }
                while let Some(estimate) = self.estimates.dequeue() {
                    busy = true;
                    self.send(&FromFirmware::Estimate(estimate));
                }
                if !busy {
                    // Sleep until an interrupt; checked with the interrupts masked so that one
                    // arriving between the check and the `wfi` still wakes it.
                    cortex_m::interrupt::free(|_| {
                        if !self.port.read_ready().unwrap_or(true) && !self.estimates.ready() {
                            cortex_m::asm::wfi();
                        }
                    });
                }
            }
        }

        fn handle_frame(&mut self) {
            let Ok(message) = self.decoder.message::<ToFirmware<'_>>() else {
                self.bad_frames = self.bad_frames.wrapping_add(1);
                return;
            };
            let reply = match message {
                ToFirmware::Sample { seq, input } => {
                    let arrival = tick::now();
                    if self.samples.enqueue(Pending { seq, input, arrival }).is_err() {
                        self.dropped_samples = self.dropped_samples.wrapping_add(1);
                    }
                    None
                }
                ToFirmware::BlobStart { len } => {
                    self.blob.clear();
                    let capacity = self.blob.capacity() as u32;
                    if len > capacity {
                        self.blob_len = None;
                        Some(FromFirmware::Blob(Err(BlobRejection::TooLarge { len, capacity })))
                    } else {
                        self.blob_len = Some(len);
                        None
                    }
                }
                ToFirmware::BlobChunk { offset, bytes } => {
                    let expected = self.blob.len() as u32;
                    let fits = self.blob_len.is_some_and(|len| expected as usize + bytes.len() <= len as usize);
                    if offset == expected && fits && self.blob.extend_from_slice(bytes).is_ok() {
                        None
                    } else {
                        self.blob_len = None;
                        Some(FromFirmware::Blob(Err(BlobRejection::OutOfOrder { expected, found: offset })))
                    }
                }
                ToFirmware::BlobCommit => Some(FromFirmware::Blob(self.commit_blob())),
                ToFirmware::Report => Some(FromFirmware::Report(self.report())),
                ToFirmware::Stop => {
                    let report = self.report();
                    self.send(&FromFirmware::Report(report));
                    self.stop();
                    None
                }
            };
            if let Some(reply) = reply {
                self.send(&reply);
            }
        }

        /// Checks the received blob and flies it; the built-in tables stay on any failure.
        fn commit_blob(&mut self) -> Result<Tables, BlobRejection> {
            let len = self.blob_len.take().unwrap_or(0);
            let received = self.blob.len() as u32;
            if received != len || len == 0 {
                return Err(BlobRejection::Incomplete { received, len });
            }
            if self.tables == Tables::Loaded {
                return Err(BlobRejection::AlreadyLoaded);
            }
            let set = estimator_core::blob::decode(self.blob).map_err(|error| {
                defmt::println!("blob rejected: {}", error);
                BlobRejection::Blob(error.into())
            })?;
            let set: &'static CoefficientSet = LOADED.init(set);
            tick::with_ticker(|ticker| ticker.fly(Flying::Loaded(FixedRateLoop::new(set, BLOCKS))));
            self.tables = Tables::Loaded;
            defmt::println!("blob of {=u32} bytes loaded", len);
            Ok(Tables::Loaded)
        }

        fn hello(&self) -> FromFirmware {
            FromFirmware::Hello {
                protocol: PROTOCOL_VERSION,
                schema_hash: estimator_core::blob::SCHEMA_HASH,
                tables: self.tables,
                rate_hz: RATE_HZ,
            }
        }

        fn report(&self) -> LinkReport {
            let mut report = tick::with_ticker(|ticker| *ticker.stats()).unwrap_or_default();
            report.bad_frames = self.bad_frames;
            report.dropped_samples = self.dropped_samples.wrapping_add(serial::lost());
            report.calibration_ticks = self.calibration_ticks;
            report.calibration_instructions = 2 * (CALIBRATION_LOOPS + 1);
            report.core_clock_hz = CORE_CLOCK_HZ;
            let (used, size) = stack_high_water();
            report.stack = [used, size];
            report
        }

        /// Queues one frame for the USART, waiting for room when the queue is full.
        fn send(&mut self, message: &FromFirmware) {
            let mut frame = [0u8; MAX_FRAME_LEN];
            if let Ok(len) = link::encode(message, &mut frame) {
                let _ = self.port.write_all(&frame[..len]);
            }
        }

        /// The end of a run: under QEMU, exit once the last byte is out; on a board, keep
        /// serving (a rig may start another run).
        fn stop(&mut self) {
            #[cfg(feature = "qemu")]
            {
                let _ = self.port.flush();
                defmt::println!("stop: {=u32} bad frames", self.bad_frames);
                cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_SUCCESS);
            }
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

    /// Stack bytes used so far (from the lowest word that lost cortex-m-rt's paint) and available.
    pub fn stack_high_water() -> (u32, u32) {
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

    /// Logs `why` and stops (under QEMU: exits with failure).
    pub fn fail(why: &str) -> ! {
        defmt::println!("firmware failed: {=str}", why);
        #[cfg(feature = "qemu")]
        cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        defmt::println!("panic: {}", defmt::Display2Format(info));
        fail("panic")
    }
}
