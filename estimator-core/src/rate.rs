//! Roll rate and acceleration from the encoder angle by first-order filtered differentiation,
//! `y[k] = p y[k-1] + (1 - p) (u[k] - u[k-1]) / dt`: the exact discretisation of a
//! differentiator followed by a first-order low-pass with the input held over the step.

use crate::coeffs::RateFilter;

/// State of the two cascaded differentiators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateEstimator {
    last_phi_rad: f32,
    phi_dot_rad_s: f32,
    last_phi_dot_rad_s: f32,
    phi_ddot_rad_s2: f32,
    primed: bool,
}

/// Roll rate and acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RollRates {
    /// Filtered roll rate, rad/s.
    pub phi_dot_rad_s: f32,
    /// Filtered roll acceleration, rad/s^2.
    pub phi_ddot_rad_s2: f32,
}

impl RateEstimator {
    /// At rest, waiting for its first angle.
    #[must_use]
    pub const fn new() -> Self {
        Self { last_phi_rad: 0.0, phi_dot_rad_s: 0.0, last_phi_dot_rad_s: 0.0, phi_ddot_rad_s2: 0.0, primed: false }
    }

    /// The filtered roll rate of the last step, rad/s.
    #[must_use]
    pub const fn phi_dot_rad_s(&self) -> f32 {
        self.phi_dot_rad_s
    }

    /// Advances with the roll angle of this step (finite, already validated by the caller);
    /// `rate_hz = 1 / dt`.
    pub fn step(&mut self, filter: &RateFilter, rate_hz: f32, phi_rad: f32) -> RollRates {
        if !self.primed {
            self.last_phi_rad = phi_rad;
            self.primed = true;
        }
        let raw_rate = (phi_rad - self.last_phi_rad) * rate_hz;
        self.phi_dot_rad_s = filter.rate_pole * self.phi_dot_rad_s + (1.0 - filter.rate_pole) * raw_rate;
        let raw_accel = (self.phi_dot_rad_s - self.last_phi_dot_rad_s) * rate_hz;
        self.phi_ddot_rad_s2 = filter.accel_pole * self.phi_ddot_rad_s2 + (1.0 - filter.accel_pole) * raw_accel;
        self.last_phi_rad = phi_rad;
        self.last_phi_dot_rad_s = self.phi_dot_rad_s;
        if !(self.phi_dot_rad_s.is_finite() && self.phi_ddot_rad_s2.is_finite()) {
            *self = Self::new();
        }
        RollRates { phi_dot_rad_s: self.phi_dot_rad_s, phi_ddot_rad_s2: self.phi_ddot_rad_s2 }
    }
}

impl Default for RateEstimator {
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
