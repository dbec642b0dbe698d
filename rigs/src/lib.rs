//! The estimator on rigs other than the host replay.
//!
//! - [`qemu`]: the firmware (or the C example over the C interface) in QEMU's STM32F405, every
//!   output compared with the host replay, instructions per step counted;
//! - [`hil`]: the firmware's real-time loop in QEMU, fed a recorded run over its serial link;
//! - [`sil`]: the closed-loop comparison of the controller scenarios as a report.

pub mod hil;
pub mod qemu;
pub mod sil;
