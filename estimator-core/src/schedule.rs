//! Where an angle of attack lies in the coefficient set's schedule (`alpha_schedule_deg`, the
//! first `n_alpha` breakpoints, ascending): the eGK parameters and the pressure path's map to
//! `C_l` are tabulated at the breakpoints and interpolated linearly between them, held
//! constant outside (gain scheduling; the paper fits its models at each angle of attack).

use crate::coeffs::{CoefficientSet, N_ALPHA};
use crate::real::Real;

/// The two breakpoints around an angle of attack and the weight of the upper one: a scheduled
/// value is `(1 - weight) v[lower] + weight v[upper]`. Both indices are below [`N_ALPHA`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SchedulePosition<R = f32> {
    /// The breakpoint at or below alpha (the first one below the schedule).
    pub lower: usize,
    /// The breakpoint above alpha (equal to `lower` outside the schedule).
    pub upper: usize,
    /// Weight of `upper`, in `[0, 1]`; zero outside the schedule.
    pub weight: R,
}

impl<R: Real> SchedulePosition<R> {
    /// At the first breakpoint.
    pub const FIRST: Self = Self { lower: 0, upper: 0, weight: R::ZERO };
}

/// The position of `alpha_deg` in `set`'s schedule. A NaN alpha gives the last breakpoint.
#[must_use]
pub fn position(set: &CoefficientSet, alpha_deg: f32) -> SchedulePosition {
    let n_alpha = usize::from(set.n_alpha).clamp(1, N_ALPHA);
    position_in(&set.alpha_schedule_deg[..n_alpha], alpha_deg)
}

/// The position of `alpha_deg` among `breakpoints_deg` (ascending; none is one at the first
/// position). A NaN alpha gives the last breakpoint.
#[must_use]
pub fn position_in<R: Real>(breakpoints_deg: &[R], alpha_deg: R) -> SchedulePosition<R> {
    let n_alpha = breakpoints_deg.len().max(1);
    let upper = breakpoints_deg.iter().position(|&breakpoint| breakpoint > alpha_deg).unwrap_or(n_alpha);
    if upper == 0 {
        return SchedulePosition::FIRST;
    }
    let last = SchedulePosition { lower: n_alpha - 1, upper: n_alpha - 1, weight: R::ZERO };
    // `0 < upper < n_alpha`, but the optimiser cannot see it through `position`: `get` keeps
    // the step free of a bounds-check panic (the link-time check of firmware-sim's
    // `panic_check` binary), and the fallback is never taken.
    let (Some(&low_deg), Some(&high_deg)) = (breakpoints_deg.get(upper.wrapping_sub(1)), breakpoints_deg.get(upper))
    else {
        return last;
    };
    let span = high_deg - low_deg;
    let weight = if span > R::ZERO { (alpha_deg - low_deg) / span } else { R::ZERO };
    SchedulePosition { lower: upper - 1, upper, weight }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::prior::PRIOR;

    #[test]
    fn inside_between_and_outside_the_schedule() {
        let mut set = PRIOR;
        set.n_alpha = 3;
        set.alpha_schedule_deg[..3].copy_from_slice(&[0.0, 10.0, 20.0]);
        assert_eq!(position(&set, -5.0), SchedulePosition::FIRST);
        assert_eq!(position(&set, 0.0), SchedulePosition { lower: 0, upper: 1, weight: 0.0 });
        assert_eq!(position(&set, 15.0), SchedulePosition { lower: 1, upper: 2, weight: 0.5 });
        assert_eq!(position(&set, 20.0), SchedulePosition { lower: 2, upper: 2, weight: 0.0 });
        assert_eq!(position(&set, 90.0), SchedulePosition { lower: 2, upper: 2, weight: 0.0 });
        assert_eq!(position(&set, f32::NAN), SchedulePosition { lower: 2, upper: 2, weight: 0.0 });
        set.n_alpha = 0;
        assert_eq!(position(&set, 15.0), SchedulePosition::FIRST);
    }
}
