//! Drivers that bind the loop's I/O traits ([`crate::io`]) to `embedded-hal` 1.0 peripherals
//! (`no_std`): a pressure scanner on SPI, the jets' Cmu through an ADC, the valves on PWM.
//!
//! embedded-hal has traits for SPI and PWM but none for an ADC or an encoder, so those are the
//! small traits of [`crate::io`] ([`crate::io::RollEncoder`]) and [`CountsSource`] here. A board
//! support file builds these drivers from its HAL's SPI device and PWM channels; a different
//! scanner or valve only needs another implementation of the same `io` trait.

use embedded_hal::pwm::SetDutyCycle;
use embedded_hal::spi::SpiDevice;
use estimator_core::coeffs::N_TAPS;

use crate::io::{BlowingMeasurement, BlowingOutput, PressureFrontEnd};

/// A linear calibration from raw counts to a physical value: `value = (counts - zero) * scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linear {
    /// Counts at zero.
    pub zero: f32,
    /// Value per count.
    pub scale: f32,
}

impl Linear {
    /// The value of `counts`.
    #[must_use]
    pub fn apply(&self, counts: u16) -> f32 {
        (f32::from(counts) - self.zero) * self.scale
    }
}

/// Counts a converter reports when its input is beyond its range (a blocked or burst tube, an
/// open sensor): read as "not measured" (NaN), never as a value.
const RAIL_LOW: u16 = 0x0000;
const RAIL_HIGH: u16 = 0xFFFF;

/// A 12-channel pressure scanner on SPI: one transaction per step clocks out every channel's
/// 16-bit conversion, big-endian, channel 1 first (the frame of multiplexed scanners and of
/// daisy-chained 16-bit SPI ADCs). Each channel's [`Linear`] calibration gives its Cp directly
/// (the scanner's zero and the tunnel's dynamic pressure folded into it at the rig's
/// calibration).
#[derive(Debug)]
pub struct PressureScanner<S> {
    spi: S,
    calibration: [Linear; N_TAPS],
    /// Transactions that failed (every channel read as NaN that step).
    pub errors: u32,
}

impl<S: SpiDevice> PressureScanner<S> {
    /// A scanner on `spi` with one calibration per channel.
    pub const fn new(spi: S, calibration: [Linear; N_TAPS]) -> Self {
        Self { spi, calibration, errors: 0 }
    }
}

impl<S: SpiDevice> PressureFrontEnd for PressureScanner<S> {
    fn read(&mut self) -> [f32; N_TAPS] {
        let mut frame = [0u8; 2 * N_TAPS];
        if self.spi.read(&mut frame).is_err() {
            self.errors = self.errors.wrapping_add(1);
            return [f32::NAN; N_TAPS];
        }
        core::array::from_fn(|tap| {
            let counts = u16::from_be_bytes([frame[2 * tap], frame[2 * tap + 1]]);
            if counts == RAIL_LOW || counts == RAIL_HIGH { f32::NAN } else { self.calibration[tap].apply(counts) }
        })
    }
}

/// One ADC conversion (embedded-hal 1.0 has no ADC trait): the latest counts of a channel, or
/// `None` when no conversion completed.
pub trait CountsSource {
    /// The latest conversion.
    fn counts(&mut self) -> Option<u16>;
}

/// The jets' Cmu from their plenum-pressure transducers through an ADC, one [`Linear`]
/// calibration per jet (from the rig's balance calibration of Cmu against plenum pressure).
#[derive(Debug)]
pub struct CmuSensors<P, S> {
    port: P,
    starboard: S,
    calibration: [Linear; 2],
}

impl<P: CountsSource, S: CountsSource> CmuSensors<P, S> {
    /// The two jets' channels and calibrations (`[port, starboard]`).
    pub const fn new(port: P, starboard: S, calibration: [Linear; 2]) -> Self {
        Self { port, starboard, calibration }
    }
}

impl<P: CountsSource, S: CountsSource> BlowingMeasurement for CmuSensors<P, S> {
    fn cmu(&mut self) -> [f32; 2] {
        let read = |counts: Option<u16>, calibration: &Linear| match counts {
            Some(counts) if counts != RAIL_LOW && counts != RAIL_HIGH => calibration.apply(counts),
            _ => f32::NAN,
        };
        [read(self.port.counts(), &self.calibration[0]), read(self.starboard.counts(), &self.calibration[1])]
    }
}

/// The blowing valves on two PWM channels: the Cmu demand through the valve's static map, taken
/// as linear from closed (duty 0) to `cmu_full_open` (duty 1); a valve whose flow is not
/// linear in its duty gets its own [`BlowingOutput`].
#[derive(Debug)]
pub struct PwmValves<P, S> {
    port: P,
    starboard: S,
    /// Cmu at full duty.
    pub cmu_full_open: f32,
    /// Duty updates the PWM refused.
    pub errors: u32,
}

impl<P: SetDutyCycle, S: SetDutyCycle> PwmValves<P, S> {
    /// The two valves' PWM channels (`[port, starboard]`) and the Cmu of a fully open valve.
    pub const fn new(port: P, starboard: S, cmu_full_open: f32) -> Self {
        Self { port, starboard, cmu_full_open, errors: 0 }
    }

    /// The duty, in parts of `max`, for a Cmu demand (NaN or negative: closed; beyond full
    /// open: open).
    fn duty(&self, cmu: f32, max: u16) -> u16 {
        let fraction = cmu / self.cmu_full_open;
        if fraction.is_nan() || fraction <= 0.0 {
            0
        } else if fraction >= 1.0 {
            max
        } else {
            (fraction * f32::from(max) + 0.5) as u16
        }
    }
}

impl<P: SetDutyCycle, S: SetDutyCycle> BlowingOutput for PwmValves<P, S> {
    fn set_cmu(&mut self, cmu: [f32; 2]) {
        let port = self.duty(cmu[0], self.port.max_duty_cycle());
        let starboard = self.duty(cmu[1], self.starboard.max_duty_cycle());
        let failed =
            self.port.set_duty_cycle(port).is_err() as u32 + self.starboard.set_duty_cycle(starboard).is_err() as u32;
        self.errors = self.errors.wrapping_add(failed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::spi::{ErrorKind, ErrorType, Operation};

    /// An SPI device that answers every read with `frame`, or fails.
    struct FakeScanner {
        frame: [u8; 2 * N_TAPS],
        fail: bool,
    }

    impl ErrorType for FakeScanner {
        type Error = ErrorKind;
    }

    impl SpiDevice for FakeScanner {
        fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
            if self.fail {
                return Err(ErrorKind::Other);
            }
            for operation in operations {
                if let Operation::Read(buffer) = operation {
                    buffer.copy_from_slice(&self.frame[..buffer.len()]);
                }
            }
            Ok(())
        }
    }

    struct FakePwm {
        duty: u16,
    }

    impl embedded_hal::pwm::ErrorType for FakePwm {
        type Error = core::convert::Infallible;
    }

    impl SetDutyCycle for FakePwm {
        fn max_duty_cycle(&self) -> u16 {
            1000
        }
        fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
            self.duty = duty;
            Ok(())
        }
    }

    #[test]
    fn the_scanner_calibrates_each_channel_and_reads_a_railed_one_as_missing() {
        let mut frame = [0u8; 2 * N_TAPS];
        for tap in 0..N_TAPS {
            frame[2 * tap..2 * tap + 2].copy_from_slice(&(30_000 + 100 * tap as u16).to_be_bytes());
        }
        frame[6..8].copy_from_slice(&RAIL_HIGH.to_be_bytes());
        let calibration = [Linear { zero: 32_768.0, scale: 1e-4 }; N_TAPS];
        let mut scanner = PressureScanner::new(FakeScanner { frame, fail: false }, calibration);
        let cp = scanner.read();
        assert!((cp[0] - (30_000.0 - 32_768.0) * 1e-4).abs() < 1e-6);
        assert!((cp[11] - (31_100.0 - 32_768.0) * 1e-4).abs() < 1e-6);
        assert!(cp[3].is_nan(), "a railed channel is not measured");
        let mut failing = PressureScanner::new(FakeScanner { frame, fail: true }, calibration);
        assert!(failing.read().iter().all(|value| value.is_nan()));
        assert_eq!(failing.errors, 1);
    }

    #[test]
    fn the_valves_map_the_demand_to_duty_and_close_on_nan() {
        let mut valves = PwmValves::new(FakePwm { duty: 7 }, FakePwm { duty: 7 }, 0.02);
        valves.set_cmu([0.005, 0.03]);
        assert_eq!((valves.port.duty, valves.starboard.duty), (250, 1000));
        valves.set_cmu([f32::NAN, -1.0]);
        assert_eq!((valves.port.duty, valves.starboard.duty), (0, 0));
    }

    struct Counts(Option<u16>);

    impl CountsSource for Counts {
        fn counts(&mut self) -> Option<u16> {
            self.0
        }
    }

    #[test]
    fn a_missing_conversion_is_a_missing_cmu() {
        let calibration = [Linear { zero: 1000.0, scale: 1e-6 }; 2];
        let mut sensors = CmuSensors::new(Counts(Some(5000)), Counts(None), calibration);
        let [port, starboard] = sensors.cmu();
        assert!((port - 0.004).abs() < 1e-7 && starboard.is_nan());
    }
}
