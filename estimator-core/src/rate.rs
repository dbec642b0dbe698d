//! Roll rate and acceleration from the encoder angle by first-order filtered differentiation,
//! `y[k] = p y[k-1] + (1 - p) (u[k] - u[k-1]) / dt`: the exact discretisation of a
//! differentiator followed by a first-order low-pass with the input held over the step.

use crate::coeffs::RateFilter;
use crate::real::Real;

/// State of the two cascaded differentiators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateEstimator<R = f32> {
    last_phi_rad: R,
    phi_dot_rad_s: R,
    last_phi_dot_rad_s: R,
    phi_ddot_rad_s2: R,
    primed: bool,
}

/// Roll rate and acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RollRates<R = f32> {
    /// Filtered roll rate, rad/s.
    pub phi_dot_rad_s: R,
    /// Filtered roll acceleration, rad/s^2.
    pub phi_ddot_rad_s2: R,
}

impl<R: Real> RateEstimator<R> {
    /// At rest, waiting for its first angle.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            last_phi_rad: R::ZERO,
            phi_dot_rad_s: R::ZERO,
            last_phi_dot_rad_s: R::ZERO,
            phi_ddot_rad_s2: R::ZERO,
            primed: false,
        }
    }

    /// The filtered roll rate of the last step, rad/s.
    #[must_use]
    pub const fn phi_dot_rad_s(&self) -> R {
        self.phi_dot_rad_s
    }

    /// Advances with the roll angle of this step (finite, already validated by the caller);
    /// `rate_hz = 1 / dt`.
    pub fn step(&mut self, filter: &RateFilter<R>, rate_hz: R, phi_rad: R) -> RollRates<R> {
        if !self.primed {
            self.last_phi_rad = phi_rad;
            self.primed = true;
        }
        let raw_rate = (phi_rad - self.last_phi_rad) * rate_hz;
        self.phi_dot_rad_s = filter.rate_pole * self.phi_dot_rad_s + (R::ONE - filter.rate_pole) * raw_rate;
        let raw_accel = (self.phi_dot_rad_s - self.last_phi_dot_rad_s) * rate_hz;
        self.phi_ddot_rad_s2 = filter.accel_pole * self.phi_ddot_rad_s2 + (R::ONE - filter.accel_pole) * raw_accel;
        self.last_phi_rad = phi_rad;
        self.last_phi_dot_rad_s = self.phi_dot_rad_s;
        if !(self.phi_dot_rad_s.is_finite() && self.phi_ddot_rad_s2.is_finite()) {
            *self = Self::new();
        }
        RollRates { phi_dot_rad_s: self.phi_dot_rad_s, phi_ddot_rad_s2: self.phi_ddot_rad_s2 }
    }
}

impl<R: Real> Default for RateEstimator<R> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_rate_converges_to_the_slope() {
        let filter = RateFilter { rate_pole: (-core::f32::consts::TAU * 20.0 * 1e-3f32).exp(), accel_pole: 0.9 };
        let mut rates = RateEstimator::new();
        let mut last = RollRates { phi_dot_rad_s: 0.0, phi_ddot_rad_s2: 0.0 };
        for k in 0..2000 {
            last = rates.step(&filter, 1e3, 0.5 * k as f32 * 1e-3);
        }
        assert!((last.phi_dot_rad_s - 0.5).abs() < 1e-4, "{last:?}");
        assert!(last.phi_ddot_rad_s2.abs() < 1e-3);
    }
}
