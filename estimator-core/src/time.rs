//! Fixed-step time: the core is stepped by the caller at a fixed rate and never reads a clock.

/// Default step rate of the estimator, matching the paper's 1 kHz recordings.
pub const DEFAULT_RATE_HZ: f32 = 1000.0;

/// Default step, `1 / DEFAULT_RATE_HZ`.
pub const DEFAULT_DT_S: f32 = 1.0 / DEFAULT_RATE_HZ;

/// A step counter: the index of the current fixed step since the estimator was reset.
///
/// Time is a newtype rather than a bare `f32` of seconds so that it never loses resolution over
/// long runs (an `f32` second counter loses millisecond resolution after about 4.6 hours).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct Tick(pub u32);

impl Tick {
    /// The next tick, wrapping after `u32::MAX` steps (about 50 days at 1 kHz).
    #[must_use]
    pub const fn next(self) -> Self {
        Self(self.0.wrapping_add(1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_wraps_instead_of_overflowing() {
        assert_eq!(Tick(u32::MAX).next(), Tick(0));
        assert_eq!(Tick(41).next(), Tick(42));
    }
}
