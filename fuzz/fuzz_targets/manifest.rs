//! cargo-fuzz target: the manifest loader must accept or reject every input with a typed error
//! (naming the file, for the text formats), and never panic
//! (`xtask::fuzz::check_input`).
#![no_main]

use xtask::fuzz::{Target, check_input};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(broken) = check_input(Target::Manifest, data) {
        panic!("contract broken: {broken}");
    }
});
