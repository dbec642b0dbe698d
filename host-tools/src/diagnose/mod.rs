//! Sim-to-real gap diagnosis.

pub mod ledger;
