//! The jets' Cmu from the controller's demand, for the steps whose blowing measurement is
//! missing: the demands the caller notes after each step go into a history,
//! and a missing Cmu is predicted from the previous step's Cmu and the demand one dead time ago
//! through the fitted [`ActuatorResponse`].
//!
//! The prediction starts from the previous step's Cmu, measured or predicted, so a lost sample
//! continues from the last measurement (the one-step-ahead predictor of the response), and a
//! long loss runs the response on the demands alone.

use crate::coeffs::{ActuatorResponse, DEMAND_SLOTS};
use crate::real::Real;

/// Mask of a ring index into the demand history.
const SLOT_MASK: usize = DEMAND_SLOTS - 1;

const _: () = assert!(DEMAND_SLOTS.is_power_of_two() && DEMAND_SLOTS <= 256, "the ring index is a u8 mask");

/// The demands noted so far, newest last, for both jets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemandHistory<R = f32> {
    /// `[port, starboard]` demand per slot; slots not written yet are zero (no blowing).
    demands: [[R; 2]; DEMAND_SLOTS],
    /// Slot of the newest demand.
    newest: u8,
    /// True once a demand was noted: without one, a missing Cmu is held.
    noted: bool,
}

impl<R: Real> DemandHistory<R> {
    /// No demand noted yet.
    #[must_use]
    pub const fn new() -> Self {
        Self { demands: [[R::ZERO; 2]; DEMAND_SLOTS], newest: 0, noted: false }
    }

    /// True once a demand was noted.
    #[must_use]
    pub const fn noted(&self) -> bool {
        self.noted
    }

    /// Notes the demand of this step, `[port, starboard]`, limited to `[0, cmu_limit]`; a
    /// non-finite demand repeats the jet's previous one (the valve holds its last command).
    /// Constant time; never panics.
    pub fn note(&mut self, demand: [R; 2], cmu_limit: R) {
        let previous = self.newest_demands();
        let slot = (usize::from(self.newest) + 1) & SLOT_MASK;
        let limited: [R; 2] = core::array::from_fn(|side| {
            let value = demand.get(side).copied().unwrap_or(R::NAN);
            if value.is_finite() {
                crate::min_num(crate::max_num(value, R::ZERO), cmu_limit)
            } else {
                previous.get(side).copied().unwrap_or(R::ZERO)
            }
        });
        if let Some(entry) = self.demands.get_mut(slot) {
            *entry = limited;
        }
        self.newest = slot as u8;
        self.noted = true;
    }

    /// The Cmu of jet `side` at this step through `response`, from its Cmu at the previous step:
    /// `pole previous + (1 - pole) gain demand[k - 1 - delay_steps]`. A dead time beyond the
    /// history reads its oldest slot. Not limited (the caller limits and checks it).
    #[must_use]
    pub fn predict(&self, response: &ActuatorResponse<R>, side: usize, previous_cmu: R) -> R {
        let age = usize::from(response.delay_steps).min(SLOT_MASK);
        let slot = (usize::from(self.newest) + DEMAND_SLOTS - age) & SLOT_MASK;
        let demand = self.demands.get(slot).and_then(|pair| pair.get(side)).copied().unwrap_or(R::ZERO);
        response.pole * previous_cmu + (R::ONE - response.pole) * response.gain * demand
    }

    fn newest_demands(&self) -> [R; 2] {
        self.demands.get(usize::from(self.newest) & SLOT_MASK).copied().unwrap_or([R::ZERO; 2])
    }
}

impl<R: Real> Default for DemandHistory<R> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMIT: f32 = 0.1;

    #[test]
    fn the_identity_gives_the_last_demand() {
        let mut history = DemandHistory::new();
        assert!(!history.noted());
        history.note([0.004, 0.007], LIMIT);
        assert!(history.noted());
        assert_eq!(history.predict(&ActuatorResponse::IDENTITY, 0, 0.9), 0.004);
        assert_eq!(history.predict(&ActuatorResponse::IDENTITY, 1, 0.9), 0.007);
    }

    #[test]
    fn the_dead_time_reads_the_demand_that_many_notes_back() {
        let mut history = DemandHistory::new();
        for step in 0..(3 * DEMAND_SLOTS) {
            history.note([step as f32 * 1e-4, 0.0], 1e6);
        }
        let newest = (3 * DEMAND_SLOTS - 1) as f32 * 1e-4;
        for delay_steps in [0u8, 1, 5, 63] {
            let response = ActuatorResponse { delay_steps, pole: 0.0, gain: 1.0 };
            let expected = newest - f32::from(delay_steps) * 1e-4;
            assert!((history.predict(&response, 0, 0.0) - expected).abs() < 1e-6, "{delay_steps}");
        }
        // Beyond the history: its oldest slot, never a panic.
        let response = ActuatorResponse { delay_steps: u8::MAX, pole: 0.0, gain: 1.0 };
        let oldest = newest - (DEMAND_SLOTS - 1) as f32 * 1e-4;
        assert!((history.predict(&response, 0, 0.0) - oldest).abs() < 1e-6);
    }

    #[test]
    fn the_lag_settles_on_gain_times_demand() {
        let mut history = DemandHistory::new();
        let response = ActuatorResponse { delay_steps: 2, pole: 0.7, gain: 0.9 };
        let mut cmu = 0.0;
        for _ in 0..200 {
            history.note([0.008, 0.0], LIMIT);
            cmu = history.predict(&response, 0, cmu);
        }
        assert!((cmu - 0.9 * 0.008).abs() < 1e-7, "{cmu}");
    }

    #[test]
    fn bad_demands_are_limited_or_held() {
        let mut history = DemandHistory::new();
        history.note([0.005, 0.003], LIMIT);
        history.note([f32::NAN, f32::INFINITY], LIMIT);
        let identity = ActuatorResponse::IDENTITY;
        assert_eq!([0, 1].map(|side| history.predict(&identity, side, 0.0)), [0.005, 0.003]);
        history.note([-1.0, 1e30], LIMIT);
        assert_eq!([0, 1].map(|side| history.predict(&identity, side, 0.0)), [0.0, LIMIT]);
    }
}
