//! The clock tree: 168 MHz from the internal oscillator through the PLL.
//!
//! RM0090 (STM32F405 reference manual) section 6.3: HSI 16 MHz / M 16 * N 336 / P 2 = 168 MHz
//! (Q 7 gives the 48 MHz USB clock), AHB /1, APB1 /4 (42 MHz, its timers 84 MHz), APB2 /2
//! (84 MHz), flash 5 wait states at 3.3 V (table 10). The internal oscillator needs no board
//! knowledge (a flight controller's crystal is 8, 16 or 25 MHz); it is trimmed to 1 % at the
//! factory, inside a UART's tolerance. QEMU's netduinoplus2 has no RCC (its registers read 0)
//! and runs at 168 MHz from reset, so every wait here is bounded: when the PLL never reports
//! ready the firmware carries on and says so.

use stm32f4::stm32f405 as pac;

/// The core clock after [`configure`]: 168 MHz (and QEMU's fixed SYSCLK).
pub const CORE_CLOCK_HZ: u32 = 168_000_000;

/// Polls of a ready flag before the set-up gives up on it (about 1 ms at 16 MHz; the PLL locks
/// in 100 us, RM0090 datasheet table 34).
const READY_POLLS: u32 = 20_000;

/// What the clock set-up reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ClockState {
    /// The PLL locked and drives the core at [`CORE_CLOCK_HZ`].
    Pll,
    /// The RCC never reported ready (QEMU, or a broken part): running on what reset gave.
    Unconfirmed,
}

/// Sets the PLL up and switches the core to it; enables the clocks of USART1 and GPIOA.
pub fn configure(rcc: &pac::RCC, flash: &pac::FLASH) -> ClockState {
    rcc.apb2enr().modify(|_, w| w.usart1en().set_bit());
    rcc.ahb1enr().modify(|_, w| w.gpioaen().set_bit());
    // Wait states before the faster clock (RM0090 3.5.1).
    flash.acr().modify(|_, w| unsafe { w.latency().bits(5) }.prften().set_bit().icen().set_bit().dcen().set_bit());
    rcc.cfgr().modify(|_, w| w.hpre().div1().ppre1().div4().ppre2().div2());
    rcc.pllcfgr().write(|w| unsafe { w.pllm().bits(16).plln().bits(336).pllq().bits(7) }.pllp().div2().pllsrc().hsi());
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    if !poll(|| rcc.cr().read().pllrdy().bit_is_set()) {
        return ClockState::Unconfirmed;
    }
    rcc.cfgr().modify(|_, w| w.sw().pll());
    if poll(|| rcc.cfgr().read().sws().is_pll()) { ClockState::Pll } else { ClockState::Unconfirmed }
}

/// True when `ready` held within [`READY_POLLS`] polls.
fn poll(mut ready: impl FnMut() -> bool) -> bool {
    (0..READY_POLLS).any(|_| ready())
}
