//! Health flags of a step: which inputs were missing or implausible, which pressure channels
//! were skipped, rejected or isolated, and which states had to be reset.

use crate::coeffs::N_TAPS;

/// Per-step health of the estimator. A set flag never means the output is unusable by itself;
/// it says which input was not used and which value was held instead.
///
/// `repr(C)`: the layout of C's `rollest_health` (estimator-ffi).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// Bit `i`: pressure channel `i` was missing (NaN) this step.
    pub cp_missing: u16,
    /// Bit `i`: pressure channel `i` failed the innovation gate this step.
    pub cp_rejected: u16,
    /// Bit `i`: pressure channel `i` is isolated as faulty (rejected persistently).
    pub cp_isolated: u16,
    /// Other flags, see the `Health::*` constants.
    pub flags: u16,
}

impl Health {
    /// The roll angle was missing or non-finite; the last valid one was extrapolated with the
    /// filtered roll rate (for at most 50 ms), then held.
    pub const PHI_HELD: u16 = 1 << 0;
    /// The angle of attack was missing or non-finite; the last valid one was held.
    pub const ALPHA_HELD: u16 = 1 << 1;
    /// A momentum coefficient was missing or non-finite; the last valid one was held (no
    /// demand was noted, see [`Health::CMU_FROM_DEMAND`]).
    pub const CMU_HELD: u16 = 1 << 2;
    /// An input was outside its physical range and was clamped.
    pub const INPUT_CLAMPED: u16 = 1 << 3;
    /// No pressure channel was usable: the pressure path only predicted, the fusion held.
    pub const PRESSURE_UNUSED: u16 = 1 << 4;
    /// A state became non-finite or left its range and was reset.
    pub const STATE_RESET: u16 = 1 << 5;
    /// A jet demand was saturated at 0 or at the largest Cmu (controller blocks).
    pub const CMU_SATURATED: u16 = 1 << 6;
    /// The measured roll moment for the feedback was missing; the integrator held.
    pub const FEEDBACK_HELD: u16 = 1 << 7;
    /// An estimate left its plausible range (far outside the fitted inputs) and was limited:
    /// the coupling correction beyond its limit, or `C_l,roll`, `C_l,linear` or `C_l` beyond the
    /// fitted envelope with its margin (`crate::coeffs::Envelope`).
    pub const ESTIMATE_LIMITED: u16 = 1 << 8;
    /// A momentum coefficient was missing or non-finite, and the controller's demand was known
    /// (`crate::Estimator::note_demand`): the jet's Cmu was predicted from the demands through the
    /// fitted actuator response (`crate::actuator`). Set instead of [`Health::CMU_HELD`].
    pub const CMU_FROM_DEMAND: u16 = 1 << 9;
    /// The pressure filter is still settling from its start at the mean pressures: every
    /// finite reading corrects it and none is gated (`crate::coeffs::PressureModel::settle_steps`).
    /// Not a fault.
    pub const PRESSURE_SETTLING: u16 = 1 << 10;

    /// True when no flag and no channel bit is set.
    #[must_use]
    pub const fn is_nominal(&self) -> bool {
        self.cp_missing == 0 && self.cp_rejected == 0 && self.cp_isolated == 0 && self.flags == 0
    }

    /// True when `flag` (one of the `Health::*` constants) is set.
    #[must_use]
    pub const fn has(&self, flag: u16) -> bool {
        self.flags & flag != 0
    }

    /// Sets `flag`.
    pub fn set(&mut self, flag: u16) {
        self.flags |= flag;
    }

    /// True when channel `tap` was rejected or is isolated.
    #[must_use]
    pub const fn channel_faulty(&self, tap: usize) -> bool {
        tap < N_TAPS && ((self.cp_rejected | self.cp_isolated) >> tap) & 1 != 0
    }
}
