//! The C example (`estimator-ffi/c-example`): the estimator's C interface flown by a C program
//! on the STM32F405 under QEMU. The static library is built for the Cortex-M4F with the
//! firmware profile (fat LTO), the program is compiled and linked with Debian's
//! `arm-none-eabi-gcc` and newlib's semihosting I/O (`rdimon`), and it reads and writes the same
//! files as the Rust firmware, so [`super::qemu_replay`] compares it with the host replay the
//! same way.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, bail};

use super::{TARGET, workspace_root};

/// The C compiler (Debian's `gcc-arm-none-eabi`, installed by `./ci.sh setup`).
pub const CC: &str = "arm-none-eabi-gcc";

/// The blob the C example loads when it finds it in its working folder (else the built-in
/// tables fly).
pub const MODEL_FILE: &str = "model.bin";

/// Flags of the Cortex-M4F with its single-precision FPU, hard-float ABI (the library's target,
/// `thumbv7em-none-eabihf`).
const CPU_FLAGS: [&str; 4] = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"];

/// Builds `libroll_estimator.a` for the Cortex-M4F and links the C example against it; returns
/// the ELF. Everything goes to `target/c-example`, apart from the workspace's target folder.
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
    let elf = target_dir.join("replay.elf");
    let output = Command::new(CC)
        .args(CPU_FLAGS)
        .args(["-O2", "-std=c11", "-Wall", "-Wextra", "-Werror", "-ffunction-sections", "-fdata-sections", "-I"])
        .arg(root.join("estimator-ffi").join("include"))
        .arg(sources.join("replay.c"))
        .arg(sources.join("startup.c"))
        .arg("-T")
        .arg(sources.join("stm32f405.ld"))
        // newlib's file I/O over semihosting; our own reset instead of its crt0.
        .args(["--specs=rdimon.specs", "-nostartfiles", "-Wl,--gc-sections", "-Wl,--no-warn-execstack", "-L"])
        .arg(target_dir.join(TARGET).join("firmware"))
        .args(["-lroll_estimator", "-lm", "-o"])
        .arg(&elf)
        .output()
        .map_err(|error| {
            anyhow::anyhow!(
                "cannot run {CC} ({error}): install it (`apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi`, or `./ci.sh setup`)"
            )
        })?;
    if !output.status.success() {
        bail!("compiling the C example failed:\n{}", String::from_utf8_lossy(&output.stderr));
    }
    Ok(elf)
}

/// Runs the C example in `dir` (with its input file, and `blob` as [`MODEL_FILE`] if given) and
/// returns its exit status: 0, a `rollest_status` code, or its I/O failures (101 to 104).
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
