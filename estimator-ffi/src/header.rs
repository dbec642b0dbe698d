//! The text of `include/roll_estimator.h`: cbindgen's output for this crate with
//! `cbindgen.toml`, finished with what cbindgen cannot write. Compiled twice, so that the two
//! cannot disagree: by `cargo xtask header`, which writes or checks the file (a `#[path]` module
//! there), and by this crate's test that the committed header is fresh.
//!
//! cbindgen 0.29 evaluates no `const fn` and rewrites no doc text (its only documentation
//! settings are `documentation`, `documentation_style` and `documentation_length`), so here:
//! - `#define ROLLEST_VERSION` is written from the crate's version as cbindgen read it from Cargo
//!   (the number `rollest_version()` computes from `CARGO_PKG_VERSION_*`);
//! - the `# Safety` heading that clippy's `missing_safety_doc` requires on a `pub unsafe fn`
//!   becomes `Preconditions:`, a C reader's word for what the caller must ensure.

use std::path::Path;

/// An exported function's `# Safety` heading as cbindgen writes it (doxygen style, top level),
/// and what the header says instead.
const SAFETY_HEADING: &str = " * # Safety\n *\n";
const PRECONDITIONS: &str = " * Preconditions:\n";

/// The header of the crate in `crate_dir`.
pub fn generate(crate_dir: &Path) -> Result<Vec<u8>, String> {
    let mut bindings = cbindgen::generate(crate_dir).map_err(|error| format!("cbindgen: {error}"))?;
    let version = version_number(&bindings.package_version)?;
    let define = format!(
        "\n/**\n * The version of this header's library, `major * 10000 + minor * 100 + patch` \
         (here {}):\n * compare it with `rollest_version()` at start-up.\n */\n#define ROLLEST_VERSION {version}\n",
        bindings.package_version
    );
    let after_includes = bindings.config.after_includes.take().unwrap_or_default();
    bindings.config.after_includes = Some(define + &after_includes);
    let mut text = Vec::new();
    bindings.write(&mut text);
    let text = String::from_utf8(text).map_err(|error| format!("cbindgen wrote non-UTF-8 text: {error}"))?;
    let text = text.replace(SAFETY_HEADING, PRECONDITIONS);
    if text.contains("# Safety") {
        return Err("a `# Safety` heading is left in the header: write it as `/// # Safety` followed by an empty \
                    `///` line"
            .into());
    }
    Ok(text.into_bytes())
}

/// `major * 10000 + minor * 100 + patch` of a Cargo version (`0.1.0` is 100; a pre-release or
/// build suffix is left out, as in `CARGO_PKG_VERSION_PATCH`).
fn version_number(version: &str) -> Result<u32, String> {
    let release = version.split(['-', '+']).next().unwrap_or_default();
    let parts: Vec<u32> = release.split('.').map(str::parse).collect::<Result<_, _>>().unwrap_or_default();
    match parts[..] {
        [major, minor, patch] if minor < 100 && patch < 100 => Ok(major * 10000 + minor * 100 + patch),
        _ => Err(format!("version {version:?} is not MAJOR.MINOR.PATCH with minor and patch below 100")),
    }
}
