//! One module per group of subcommands: each runs one command from its flags and prints its
//! summary.

pub(crate) mod data;
pub(crate) mod diagnosis;
pub(crate) mod firmware;
pub(crate) mod model;
pub(crate) mod reliability;
