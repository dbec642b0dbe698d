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
//! physical prior before any fit.
//!
//! # Rules
//!
//! No allocation, no panic (also on NaN, infinity or huge input: a missing value is held and
//! flagged), O(1) per step, sizes fixed at compile time, the estimator can live in a `static`
//! ([`Estimator::new`] is `const`), f32 throughout.
//!
//! # Features
//!
//! - `defmt`: `defmt::Format` for errors and flags on the target.
//!
//! MSRV: the workspace's pinned toolchain (Rust 1.95).
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code, missing_docs)]

pub mod blob;
pub mod coeffs;
pub mod controller;
pub mod coupling;
pub mod egk;
pub mod estimator;
pub mod fusion;
pub mod health;
pub mod plant;
pub mod pressure;
pub mod prior;
pub mod rate;
pub mod sparse;
pub mod time;
pub mod trig;

pub use coeffs::CoefficientSet;

/// True when `value` is finite and `|value| <= limit` (false for NaN, unlike `!(|v| > limit)`).
pub(crate) fn bounded(value: f32, limit: f32) -> bool {
    value.abs() <= limit
}
pub use estimator::{Estimator, Input, Output};
pub use health::Health;
