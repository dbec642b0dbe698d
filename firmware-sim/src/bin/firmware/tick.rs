//! The loop's clock: SysTick's exception at [`RATE_HZ`] steps the estimator and the controller
//! on the oldest waiting sample, and nothing else.
//!
//! SysTick is the Cortex-M4's own timer, clocked by the core (168 MHz) and reloaded in hardware
//! every [`PERIOD_TICKS`], exactly: the time base most flight-controller firmware schedules on.
//! (TIM2 would do on a board, but QEMU 7.2's model of the STM32's general-purpose timers does
//! not keep a periodic update event: measured, its period wandered from 3.7 to 5.6 ms.) The
//! same counter times each step and, with the tick count, each sample's latency ([`now`]). A tick
//! with no sample waiting is an idle tick (the link was late); a tick that comes while the
//! previous step still runs is an overrun. Both are counted and reported, never silent.

use core::cell::RefCell;

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::interrupt::Mutex;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};
use cortex_m_rt::exception;
use estimator_core::Input;
use estimator_core::sparse::Interpreted;
use firmware_sim::io::{FixedRateLoop, InputBoard, StepResult, TickCounter};
use firmware_sim::link::{Estimate, LinkReport, SampleInput, WARM_UP_STEPS};
use heapless::spsc::{Consumer, Producer};

use crate::clocks::CORE_CLOCK_HZ;

/// The model's rate (`dt_s` = 1 ms).
pub const RATE_HZ: u32 = 1_000;
/// Core-clock ticks per loop period.
pub const PERIOD_TICKS: u32 = CORE_CLOCK_HZ / RATE_HZ;

/// Periods since [`start`], counted by the exception.
static PERIODS: AtomicU32 = AtomicU32::new(0);

/// Core-clock ticks since [`start`] (wraps after 25 s: differences of a few periods are exact).
pub fn now() -> u32 {
    cortex_m::interrupt::free(|_| {
        let periods = PERIODS.load(Ordering::Relaxed);
        let current = SYST::get_current();
        // A wrap whose exception has not run yet: the counter restarted near the top.
        let pending = SCB::is_pendst_pending() && current > PERIOD_TICKS / 2;
        let periods = periods.wrapping_add(u32::from(pending));
        periods.wrapping_mul(PERIOD_TICKS).wrapping_add(PERIOD_TICKS - 1 - current)
    })
}

/// SysTick as the step timer: counts down from `PERIOD_TICKS - 1` at the core clock.
pub struct SysTickCounter;

impl TickCounter for SysTickCounter {
    fn now(&mut self) -> u32 {
        SYST::get_current()
    }

    fn elapsed(&self, start: u32, end: u32) -> u32 {
        // Down-counter: at most one wrap within a step (a step is far below a period).
        if start >= end { start - end } else { start + PERIOD_TICKS - end }
    }
}

/// A sample waiting for its tick.
#[derive(Debug, Clone, Copy)]
pub struct Pending {
    /// The sender's sequence number.
    pub seq: u32,
    /// The inputs.
    pub input: SampleInput,
    /// [`now`] when its frame was complete.
    pub arrival: u32,
}

/// The estimator flying the built-in tables (generated code) or a loaded blob (interpreted).
// The variants differ in size by the generated code's evaluator state only (zero-sized).
pub enum Flying {
    /// `estimator_core::coeffs::BUILT_IN` with its sparse models as generated code.
    BuiltIn(FixedRateLoop<'static, estimator_core::coeffs::CompiledDefault>),
    /// A coefficient set received over the link.
    Loaded(FixedRateLoop<'static, Interpreted>),
}

impl Flying {
    fn step(&mut self, board: &mut InputBoard, ticks: &mut SysTickCounter) -> StepResult {
        match self {
            Self::BuiltIn(fixed_rate) => fixed_rate.step(board, ticks),
            Self::Loaded(fixed_rate) => fixed_rate.step(board, ticks),
        }
    }
}

/// What the timer interrupt owns.
pub struct Ticker {
    flying: &'static mut Flying,
    samples: Consumer<'static, Pending>,
    estimates: Producer<'static, Estimate>,
    stats: LinkReport,
    /// SysTick at the previous tick.
    last_tick: Option<u32>,
}

/// The interrupt's state, handed over by [`start`] and borrowed by [`with_ticker`].
static TICKER: Mutex<RefCell<Option<Ticker>>> = Mutex::new(RefCell::new(None));

/// Programs SysTick for [`RATE_HZ`], hands the estimator and the queues to the exception, and
/// starts it.
pub fn start(
    syst: &mut SYST,
    flying: &'static mut Flying,
    samples: Consumer<'static, Pending>,
    estimates: Producer<'static, Estimate>,
) {
    cortex_m::interrupt::free(|cs| {
        TICKER.borrow(cs).replace(Some(Ticker {
            flying,
            samples,
            estimates,
            stats: LinkReport { period_ticks: [u32::MAX, 0], ..LinkReport::default() },
            last_tick: None,
        }));
    });
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(PERIOD_TICKS - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}

/// Runs `f` on the interrupt's state with the interrupts masked (the main loop's access: the
/// report, a new coefficient set).
pub fn with_ticker<R>(f: impl FnOnce(&mut Ticker) -> R) -> Option<R> {
    cortex_m::interrupt::free(|cs| TICKER.borrow(cs).borrow_mut().as_mut().map(f))
}

impl Ticker {
    /// The loop's counters so far.
    pub const fn stats(&self) -> &LinkReport {
        &self.stats
    }

    /// Flies `flying` from the next tick on.
    pub fn fly(&mut self, flying: Flying) {
        *self.flying = flying;
    }

    /// One tick: steps the oldest waiting sample, if any.
    fn tick(&mut self) {
        PERIODS.fetch_add(1, Ordering::Relaxed);
        let tick_start = now();
        let stats = &mut self.stats;
        if let Some(last) = self.last_tick.replace(tick_start) {
            let period = tick_start.wrapping_sub(last);
            stats.period_ticks = [stats.period_ticks[0].min(period), stats.period_ticks[1].max(period)];
        }
        stats.ticks = stats.ticks.wrapping_add(1);
        let Some(pending) = self.samples.dequeue() else {
            stats.idle_ticks = stats.idle_ticks.wrapping_add(1);
            return;
        };
        // The sensors and valves of a rig on the serial link: the sample, and the demand going
        // back out with the estimate.
        let mut board = InputBoard::new(Input::from(&pending.input));
        let mut systick = SysTickCounter;
        let result = self.flying.step(&mut board, &mut systick);
        let latency_ticks = now().wrapping_sub(pending.arrival);
        stats.steps = stats.steps.wrapping_add(1);
        if stats.steps > WARM_UP_STEPS {
            stats.estimator_ticks_max = stats.estimator_ticks_max.max(result.ticks_estimator);
            stats.estimator_ticks_sum += u64::from(result.ticks_estimator);
            stats.total_ticks_max = stats.total_ticks_max.max(result.ticks_total);
            stats.total_ticks_sum += u64::from(result.ticks_total);
        }
        stats.latency_ticks_max = stats.latency_ticks_max.max(latency_ticks);
        stats.latency_ticks_sum += u64::from(latency_ticks);
        let estimate = Estimate::from_step(pending.seq, &result, latency_ticks);
        if self.estimates.enqueue(estimate).is_err() {
            stats.dropped_estimates = stats.dropped_estimates.wrapping_add(1);
        }
        // Another tick while this one ran: the step overran its period.
        if SCB::is_pendst_pending() {
            stats.overruns = stats.overruns.wrapping_add(1);
        }
    }
}

#[exception]
fn SysTick() {
    // The step runs with the interrupts enabled: the state is taken out for it and put back,
    // so the serial interrupt (of higher priority) is never held off for a whole step. The main
    // loop cannot run in between (it is not an interrupt), so it always finds the state home.
    let Some(mut ticker) = cortex_m::interrupt::free(|cs| TICKER.borrow(cs).borrow_mut().take()) else {
        return;
    };
    ticker.tick();
    cortex_m::interrupt::free(|cs| TICKER.borrow(cs).replace(Some(ticker)));
}
