//! The committed header, `include/roll_estimator.h`, compiles as C99 and as C++11 with every
//! warning an error: the small translation units beside this file include it (twice) and expand
//! its start-up check, and the C++ one asserts the status codes and struct sizes it promises.
//! Only the host compilers are needed (`-fsyntax-only`: nothing is linked).

use std::path::Path;
use std::process::Command;

/// Compiles `source` (in this folder) with `compiler` and `flags`; fails with the compiler's
/// messages, or with how to install it when it cannot be run.
fn assert_compiles(compiler: &str, package: &str, flags: &[&str], source: &str) {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut command = Command::new(compiler);
    command
        .args(flags)
        .args(["-Wall", "-Wextra", "-Werror", "-pedantic", "-fsyntax-only", "-I"])
        .arg(crate_dir.join("include"))
        .arg(crate_dir.join("tests").join(source));
    let output = command
        .output()
        .unwrap_or_else(|error| panic!("cannot run `{compiler}` ({error}): install it (`apt-get install {package}`)"));
    assert!(
        output.status.success(),
        "roll_estimator.h does not compile in {source}: {command:?}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

#[test]
fn the_header_compiles_as_cpp11_with_warnings_as_errors() {
    assert_compiles("c++", "g++", &["-x", "c++", "-std=c++11", "-Wold-style-cast"], "header_cpp.cpp");
}

#[test]
fn the_header_compiles_as_c99_with_warnings_as_errors() {
    assert_compiles("cc", "gcc", &["-x", "c", "-std=c99", "-Wstrict-prototypes"], "header_c.c");
}
