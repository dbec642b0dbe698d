//! The synthetic wind tunnel, the dataset format, the software-in-the-loop harness and the
//! firmware for the STM32F405.
//!
//! No wind-tunnel recordings of the paper's experiment exist, so [`tunnel`] is our "real": a
//! physical model of the rolling UCAS wing in the IIT Fejer tunnel that is deliberately richer
//! than the estimator's model families. It writes datasets in the contract format of
//! [`dataset`], which every tool reads.
#![cfg_attr(not(feature = "std"), no_std)]
#![deny(missing_docs)]

#[cfg(feature = "std")]
pub mod atomic;
#[cfg(feature = "std")]
pub mod campaign;
#[cfg(feature = "std")]
pub mod dataset;
#[cfg(feature = "std")]
pub mod tunnel;
