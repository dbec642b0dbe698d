//! Real-time roll-moment estimator for a rolling delta wing with trailing-edge blowing.
//!
//! This crate is the fixed-step core that the firmware, the software-in-the-loop harness and the
//! host replay all run: `no_std`, no allocation, f32, and no panics. The caller owns time and
//! storage; the core never reads a clock.
//!
//! Units and frames: roll angle `phi` is positive starboard wing down about the body x-axis
//! pointing forward from the apex; the roll moment coefficient `C_l = Mx / (q S b)`.
//!
//! # Data flow of one step
//!
//! [`Estimator::step`] takes the roll angle, the angle of attack, the two jets' momentum
//! coefficients and the 12 pressure coefficients of one sample (any may be NaN) and returns
//! every stage's estimate with [`Health`] flags:
//!
//! ```text
//! phi --> rate --> egk ---------------------.
//!   \                                        fusion --> C_l,roll --.
//!    `--> pressure model + Kalman filter ---'                       +--> C_l,linear --> + coupling --> C_l
//! Cmu --> plant (port, starboard) ----------------------> C_l,AFC -'
//! ```
//!
//! The final estimates `C_l,roll`, `C_l,linear` and `C_l` are kept within the roll moments the
//! fit data measured, with a margin ([`coeffs::Envelope`]); a step that had to limit one is
//! flagged. After each step the caller notes the controller's Cmu demand
//! ([`Estimator::note_demand`]): when a jet's measured Cmu is missing, the plant then runs on the
//! Cmu predicted from the demands through the fitted actuator response ([`actuator`]) instead of
//! the last measured one.
//!
//! The stages are the paper's: the extended Goman-Khrabrov model ([`egk`]), the time-shifted
//! pressure model with its Kalman filter ([`pressure`]) and their fusion ([`fusion`]) form the
//! disturbance model; the SINDy difference equation of eq. 5 is the plant ([`plant`]); the
//! sparse operator of eqs. 8-12 corrects the superposition ([`coupling`]). The feedforward and
//! feedback blocks of Fig. 4 are in [`controller`].
//!
//! # Tables
//!
//! Every coefficient lives in a [`CoefficientSet`] ([`coeffs`]): fitted on the host, compiled in
//! as const tables or loaded from a checked postcard blob ([`blob`]). [`prior::PRIOR`] is the
//! physical prior before any fit, at the paper's geometry.
//!
//! # Rules
//!
//! No allocation, no panic (also on NaN, infinity or huge input: a missing value is held and
//! flagged), O(1) per step, sizes fixed at compile time, the estimator can live in a `static`
//! ([`Estimator::new`] is `const`). The flying [`Estimator`] is f32; its stages are generic over
//! the scalar ([`real::Real`]), so that the host tools run the same equations in f64.
//!
//! # Features
//!
//! - `defmt`: `defmt::Format` for errors and flags on the target.
//!
//! MSRV: the workspace's pinned toolchain (Rust 1.95).
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code, missing_docs)]

pub mod actuator;
pub mod blob;
pub mod coeffs;
pub mod controller;
pub mod coupling;
pub mod egk;
pub mod estimator;
pub mod exp;
pub mod fusion;
pub mod health;
pub mod plant;
pub mod pressure;
pub mod prior;
pub mod rate;
pub mod real;
pub mod schedule;
pub mod sparse;
pub mod time;
pub mod trig;

pub use coeffs::CoefficientSet;

/// True when `value` is finite and `|value| <= limit` (false for NaN, unlike `!(|v| > limit)`).
pub(crate) fn bounded<R: real::Real>(value: R, limit: R) -> bool {
    value.abs() <= limit
}

/// `a.max(b)` (IEEE maxNum: a NaN operand is ignored) as a comparison: the M4F has no VMAXNM,
/// so `f32::max` is a library call there.
#[inline]
pub(crate) fn max_num<R: real::Real>(a: R, b: R) -> R {
    if a > b || b.is_nan() { a } else { b }
}

/// `a.min(b)` (IEEE minNum: a NaN operand is ignored) as a comparison, for the same reason.
#[inline]
pub(crate) fn min_num<R: real::Real>(a: R, b: R) -> R {
    if a < b || b.is_nan() { a } else { b }
}
pub use estimator::{Estimator, Input, Output};
pub use health::Health;

#[cfg(test)]
mod tests {
    use super::{max_num, min_num};

    #[test]
    fn max_and_min_by_comparison_match_the_library() {
        let values = [f32::NAN, f32::NEG_INFINITY, -2.5, -0.0, 0.0, 1e-30, 3.0, f32::INFINITY];
        for a in values {
            for b in values {
                let same =
                    |x: f32, y: f32| x.to_bits() == y.to_bits() || (x == 0.0 && y == 0.0) || (x.is_nan() && y.is_nan());
                assert!(same(max_num(a, b), a.max(b)), "max({a}, {b})");
                assert!(same(min_num(a, b), a.min(b)), "min({a}, {b})");
            }
        }
    }
}
