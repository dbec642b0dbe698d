//! The C example (`estimator-ffi/c-example`): the estimator's C interface flown by a C program
//! on the STM32F405 under QEMU. The static library is built for the Cortex-M4F with the
//! firmware profile (fat LTO), the program is compiled and linked by the example's Makefile with
//! Debian's `arm-none-eabi-gcc` and newlib's semihosting I/O (`rdimon`), and it reads and writes
//! the same files as the Rust firmware, so [`super::qemu_replay`] compares it with the host
//! replay the same way.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};

use super::{TARGET, workspace_root};

/// The C compiler (Debian's `gcc-arm-none-eabi`, installed by `./ci.sh setup`), passed to the
/// Makefile as `CC`.
pub const CC: &str = "arm-none-eabi-gcc";

/// GNU make, which runs `estimator-ffi/c-example/Makefile`.
const MAKE: &str = "make";

/// The blob the C example loads when it finds it in its working folder (else the built-in
/// tables fly).
pub const MODEL_FILE: &str = "model.bin";

/// Builds `libroll_estimator.a` for the Cortex-M4F and links the C example against it with its
/// Makefile (which holds the compiler's flags); returns the ELF. Everything goes to
/// `target/c-example`, apart from the workspace's target folder.
pub fn build_c_example() -> anyhow::Result<PathBuf> {
    let root = workspace_root();
    let target_dir = root.join("target").join("c-example");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .args(["build", "-p", "estimator-ffi", "--target", TARGET, "--profile", "firmware", "--target-dir"])
        .arg(&target_dir)
        .status()
        .context("running cargo to build the C library")?;
    if !status.success() {
        bail!("building libroll_estimator.a failed ({status})");
    }
    let sources = root.join("estimator-ffi").join("c-example");
    // make would report a missing compiler only as a failed recipe.
    Command::new(CC)
        .arg("--version")
        .output()
        .map_err(|error| {
            anyhow::anyhow!(
                "cannot run {CC} ({error}): install it (`apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi`, or `./ci.sh setup`)"
            )
        })?;
    let output = Command::new(MAKE)
        .arg("-C")
        .arg(&sources)
        .arg(format!("CC={CC}"))
        .arg(make_variable("LIB_DIR", &target_dir.join(TARGET).join("firmware"))?)
        .arg(make_variable("INCLUDE_DIR", &root.join("estimator-ffi").join("include"))?)
        .arg(make_variable("OUT_DIR", &target_dir)?)
        .output()
        .map_err(|error| anyhow::anyhow!("cannot run {MAKE} ({error}): install it (`apt-get install make`)"))?;
    if !output.status.success() {
        bail!(
            "building the C example with {} failed:\n{}{}",
            sources.join("Makefile").display(),
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        );
    }
    Ok(target_dir.join("replay.elf"))
}

/// `NAME=value` for make's command line, which overrides the Makefile's own value; make splits a
/// value at blanks, so a folder with one is refused here rather than misread there.
fn make_variable(name: &str, value: &Path) -> anyhow::Result<OsString> {
    if value.to_string_lossy().contains(char::is_whitespace) {
        bail!("make cannot build the C example in {}: the path has a blank", value.display());
    }
    let mut variable = OsString::from(format!("{name}="));
    variable.push(value);
    Ok(variable)
}

/// Runs the C example in `dir` (with its input file, and `blob` as [`MODEL_FILE`] if given) and
/// returns its exit status: 0, a `rollest_status` code, its I/O failures (101 to 104), or a
/// library that is not its header's (105: version, 106: struct sizes).
pub fn exit_status(elf: &Path, dir: &Path, blob: Option<&[u8]>) -> anyhow::Result<i32> {
    place_blob(dir, blob)?;
    let status = Command::new(super::QEMU)
        .current_dir(dir)
        .args(["-machine", "netduinoplus2", "-semihosting-config", "enable=on,target=native", "-nographic"])
        .args(["-icount", "shift=0", "-kernel"])
        .arg(elf)
        .output()
        .with_context(|| format!("running {}", super::QEMU))?
        .status;
    status.code().context("QEMU was killed")
}

/// Writes `blob` as the example's model file in `dir`, or removes one left there.
pub(super) fn place_blob(dir: &Path, blob: Option<&[u8]>) -> anyhow::Result<()> {
    let path = dir.join(MODEL_FILE);
    match blob {
        Some(bytes) => std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display())),
        None if path.exists() => std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display())),
        None => Ok(()),
    }
}
