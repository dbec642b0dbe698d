//! The synthetic wind tunnel, the dataset format, the software-in-the-loop harness and the
//! firmware for the STM32F405.
//!
//! No wind-tunnel recordings of the paper's experiment exist, so [`tunnel`] is our "real": a
//! physical model of the rolling UCAS wing in the IIT Fejer tunnel that is deliberately richer
//! than the estimator's model families. It writes datasets in the contract format of
//! [`dataset`], which every tool reads.
//!
//! - [`tunnel`] (std): the physics, its effects and a stepping API for closed loops; [`effect`]
//!   (std): the effect vocabulary the tunnel, the diagnosis and the validation share;
//!   [`campaign`] (std): scenarios and the paper's campaign;
//! - [`dataset`] (std): the on-disk format (`docs/spec/dataset-format.md`); [`atomic`] (std):
//!   folders written completely or not at all;
//! - [`sil`] (std): the estimator and controller in closed loop with the tunnel; [`fault`] (std):
//!   sensor faults injected into the estimator's inputs, in SIL runs and replays;
//! - [`io`], [`frames`] (no_std): the firmware's I/O traits and fixed-rate loop, and the binary
//!   sample records the QEMU replay exchanges through semihosting; [`link`] (no_std): the serial
//!   protocol of the real-time loop; [`drivers`] (no_std): the I/O traits bound to embedded-hal
//!   SPI and PWM;
//! - `src/bin/firmware/main.rs` (feature `target`): the STM32F405 firmware.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]
// The workspace forbids unsafe code; this package only denies it so that the firmware binary
// (src/bin/firmware/main.rs) can allow it locally. The library keeps the workspace's rule.
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
pub mod atomic;
#[cfg(feature = "std")]
pub mod campaign;
#[cfg(feature = "std")]
pub mod dataset;
pub mod drivers;
#[cfg(feature = "std")]
pub mod effect;
#[cfg(feature = "std")]
pub mod fault;
pub mod frames;
pub mod io;
pub mod link;
#[cfg(feature = "std")]
pub mod sil;
#[cfg(feature = "std")]
pub mod tunnel;
