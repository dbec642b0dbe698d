//! The synthetic wind tunnel, the dataset format, the software-in-the-loop harness and the
//! firmware for the STM32F405.
//!
//! No wind-tunnel recordings of the paper's experiment exist, so [`tunnel`] is our "real": a
//! physical model of the rolling UCAS wing in the IIT Fejer tunnel that is deliberately richer
//! than the estimator's model families. It writes datasets in the contract format of
//! [`dataset`], which every tool reads.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]
// The workspace forbids unsafe code; this package only denies it so that the firmware binary
// (src/bin/firmware.rs) can allow it locally. The library keeps the workspace's rule.
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
pub mod atomic;
#[cfg(feature = "std")]
pub mod campaign;
#[cfg(feature = "std")]
pub mod dataset;
pub mod frames;
pub mod io;
#[cfg(feature = "std")]
pub mod sil;
#[cfg(feature = "std")]
pub mod tunnel;
