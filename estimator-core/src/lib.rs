//! Real-time roll-moment estimator for a rolling delta wing with trailing-edge blowing.
//!
//! This crate is the fixed-step core that the firmware, the software-in-the-loop harness and the
//! host replay all run: `no_std`, no allocation, f32, and no panics. The caller owns time and
//! storage; the core never reads a clock.
//!
//! Units and frames: roll angle `phi` is positive starboard wing down about the body x-axis
//! pointing forward from the apex; the roll moment coefficient `C_l = Mx / (q S b)`.
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code, missing_docs)]

pub mod time;
