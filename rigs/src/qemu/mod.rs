//! The firmware in QEMU against the host replay: builds firmware-sim's `firmware` binary for the
//! STM32F405, writes one run's inputs in the binary frame format
//! ([`firmware_sim::frames`]), runs the ELF in `qemu-system-arm -machine netduinoplus2` with
//! semihosting and `-icount shift=0`, and compares every output field with
//! [`model_fit::replay::replay_run`] on the same f32 inputs ([`model_fit::replay::input_at`]); or the
//! same for the C example that flies the estimator through its C interface ([`c_example`]).

pub mod c_example;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use estimator_core::Output;
use firmware_sim::dataset::Run;
use firmware_sim::frames::{
    self, HEADER_LEN, INPUT_LEN, MAGIC_INPUT, MAGIC_OUTPUT, OUTPUT_FIELD_NAMES, OUTPUT_LEN, OutputRecord, TRAILER_LEN,
    Trailer,
};

/// The input file the firmware opens (in QEMU's working directory).
pub const INPUT_FILE: &str = "firmware-in.bin";
/// The output file the firmware writes.
pub const OUTPUT_FILE: &str = "firmware-out.bin";
/// QEMU's semihosting stdout: the firmware's defmt log (binary; `defmt-print -e ELF`).
pub const LOG_FILE: &str = "defmt.bin";
/// The target of the firmware.
pub const TARGET: &str = "thumbv7em-none-eabihf";
/// The QEMU binary.
pub const QEMU: &str = "qemu-system-arm";

/// The workspace root (host-tools' parent folder).
#[must_use]
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// How the firmware evaluates the sparse models of its built-in tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SparseCode {
    /// As generated straight-line code (`estimator_core::coeffs::CompiledDefault`): what flies.
    Compiled,
    /// From the tables, as a coefficient set loaded at run time would be (feature `interpreted`).
    Interpreted,
}

/// Builds the firmware (the `firmware` profile: release with fat LTO) and returns the ELF's
/// path. It uses its own target folder (`target/firmware`, or `target/firmware-interpreted`),
/// so that it can run while another cargo holds the workspace's.
pub fn build_firmware(code: SparseCode) -> anyhow::Result<PathBuf> {
    match code {
        SparseCode::Compiled => build_firmware_with("qemu", "firmware"),
        SparseCode::Interpreted => build_firmware_with("qemu,interpreted", "firmware-interpreted"),
    }
}

/// Builds the QEMU firmware with firmware-sim's `features` (which include `qemu`) in its own
/// target folder `target/FOLDER`; returns the ELF's path.
pub fn build_firmware_with(features: &str, folder: &str) -> anyhow::Result<PathBuf> {
    let root = workspace_root();
    let target_dir = root.join("target").join(folder);
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .args(["build", "-p", "firmware-sim", "--bin", "firmware", "--no-default-features", "--features", features])
        .args(["--target", TARGET, "--profile", "firmware", "--target-dir"])
        .arg(&target_dir)
        .status()
        .context("running cargo to build the firmware")?;
    if !status.success() {
        bail!("building the firmware ({features}) failed ({status})");
    }
    Ok(target_dir.join(TARGET).join("firmware").join("firmware"))
}

/// The first `n_samples` samples of `run` as an input file (all of them when `None`).
#[must_use]
pub fn input_bytes(run: &Run, n_samples: Option<usize>) -> Vec<u8> {
    let n = n_samples.map_or(run.channels.len(), |n| n.min(run.channels.len()));
    let mut bytes = Vec::with_capacity(HEADER_LEN + n * INPUT_LEN);
    bytes.extend_from_slice(&frames::encode_header(MAGIC_INPUT, n as u32, INPUT_LEN));
    for k in 0..n {
        bytes.extend_from_slice(&frames::encode_input(&model_fit::replay::input_at(run, k)));
    }
    bytes
}

/// Decodes an output file: the records and the trailer.
pub fn decode_output_file(bytes: &[u8]) -> anyhow::Result<(Vec<OutputRecord>, Trailer)> {
    let header: &[u8; HEADER_LEN] = bytes.get(..HEADER_LEN).and_then(|h| h.try_into().ok()).context("no header")?;
    let n = frames::decode_header(header, MAGIC_OUTPUT, OUTPUT_LEN).map_err(|e| anyhow::anyhow!("header: {e}"))?;
    let body = &bytes[HEADER_LEN..];
    if body.len() < TRAILER_LEN || !(body.len() - TRAILER_LEN).is_multiple_of(OUTPUT_LEN) {
        bail!("output file of {} bytes is truncated", bytes.len());
    }
    let (records, trailer) = body.split_at(body.len() - TRAILER_LEN);
    let records: Vec<OutputRecord> = records
        .chunks_exact(OUTPUT_LEN)
        .map(|chunk| frames::decode_output(chunk.try_into().expect("exact chunk")))
        .collect();
    let trailer = frames::decode_trailer(trailer.try_into().expect("trailer length"))
        .map_err(|e| anyhow::anyhow!("trailer: {e}"))?;
    if records.len() != n as usize || trailer.steps != n {
        bail!("the firmware wrote {} of {n} records ({} steps)", records.len(), trailer.steps);
    }
    Ok((records, trailer))
}

/// One run of the firmware in QEMU.
#[derive(Debug, Clone)]
pub struct FirmwareRun {
    /// Every step's record.
    pub records: Vec<OutputRecord>,
    /// Timing and memory figures.
    pub trailer: Trailer,
    /// Wall-clock time of QEMU, s.
    pub wall_s: f64,
}

/// Starts `elf` in QEMU's STM32F405 board (`netduinoplus2`) with semihosting, working in `dir`,
/// its semihosting output in `log`, with the further QEMU arguments `args`.
pub fn spawn(elf: &Path, dir: &Path, log: &Path, args: &[&str]) -> anyhow::Result<std::process::Child> {
    let log = std::fs::File::create(log).with_context(|| format!("creating {}", log.display()))?;
    Command::new(QEMU)
        .current_dir(dir)
        .args(["-machine", "netduinoplus2", "-semihosting-config", "enable=on,target=native"])
        .args(args)
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|error| {
            anyhow::anyhow!(
                "cannot start {QEMU} ({error}): install it (`apt-get install qemu-system-arm`, or `./ci.sh setup`)"
            )
        })
}

/// Runs `elf` in QEMU in `dir` (which holds [`INPUT_FILE`]); fails on a non-zero exit, on
/// `timeout`, or when `qemu-system-arm` is not installed.
pub fn run_firmware(elf: &Path, dir: &Path, timeout: Duration) -> anyhow::Result<FirmwareRun> {
    let started = Instant::now();
    let mut child = spawn(elf, dir, &dir.join(LOG_FILE), &["-nographic", "-icount", "shift=0"])?;
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if started.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            bail!("{QEMU} did not finish within {} s", timeout.as_secs_f64());
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let wall_s = started.elapsed().as_secs_f64();
    if !status.success() {
        let mut stderr = String::new();
        if let Some(mut pipe) = child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut pipe, &mut stderr);
        }
        bail!("the firmware failed in QEMU ({status}); log in {}; {stderr}", dir.join(LOG_FILE).display());
    }
    let bytes = std::fs::read(dir.join(OUTPUT_FILE)).context("reading the firmware's output")?;
    let (records, trailer) = decode_output_file(&bytes)?;
    Ok(FirmwareRun { records, trailer, wall_s })
}

/// `|a - b|`, 0 for identical bits (NaN = NaN), infinite when only one is NaN.
pub(crate) fn abs_diff(a: f32, b: f32) -> f32 {
    if a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()) {
        0.0
    } else if a.is_nan() || b.is_nan() {
        f32::INFINITY
    } else {
        (a - b).abs()
    }
}

/// Firmware against host replay.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// Max abs difference per output field ([`OUTPUT_FIELD_NAMES`] order).
    pub max_abs: [f32; 10],
    /// Steps whose health bits differ.
    pub health_mismatches: usize,
    /// Steps compared.
    pub steps: usize,
}

impl Comparison {
    /// The largest difference over every field.
    #[must_use]
    pub fn max(&self) -> f32 {
        self.max_abs.iter().copied().fold(0.0, f32::max)
    }
}

/// Compares step by step (a length mismatch counts every missing step as a health mismatch).
#[must_use]
pub fn compare(host: &[Output], firmware: &[OutputRecord]) -> Comparison {
    let mut max_abs = [0.0f32; 10];
    let mut health_mismatches = host.len().abs_diff(firmware.len());
    for (host, firmware) in host.iter().zip(firmware) {
        let (a, b) = (frames::output_fields(host), frames::output_fields(&firmware.output));
        for field in 0..10 {
            max_abs[field] = max_abs[field].max(abs_diff(a[field], b[field]));
        }
        health_mismatches += usize::from(host.health != firmware.output.health);
    }
    Comparison { max_abs, health_mismatches, steps: host.len().min(firmware.len()) }
}

/// Instructions per step, from SysTick ticks and the calibration loop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepCost {
    /// SysTick ticks per instruction measured on the calibration loop (0.168 expected: 168 MHz
    /// SysTick, 1 ns per instruction with `-icount shift=0`).
    pub ticks_per_instruction: f64,
    /// Mean instructions of `Estimator::step`.
    pub estimator_mean: f64,
    /// Max instructions of `Estimator::step`.
    pub estimator_max: f64,
    /// Mean instructions of estimator + controller.
    pub total_mean: f64,
    /// Max instructions of estimator + controller.
    pub total_max: f64,
}

/// The step cost of a run.
#[must_use]
pub fn step_cost(trailer: &Trailer) -> StepCost {
    let per = f64::from(trailer.calibration_ticks) / f64::from(trailer.calibration_instructions.max(1));
    let steps = f64::from(trailer.steps.max(1));
    let instructions = |ticks: f64| if per > 0.0 { ticks / per } else { f64::NAN };
    StepCost {
        ticks_per_instruction: per,
        estimator_mean: instructions(trailer.estimator_ticks_sum as f64 / steps),
        estimator_max: instructions(f64::from(trailer.estimator_ticks_max)),
        total_mean: instructions(trailer.total_ticks_sum as f64 / steps),
        total_max: instructions(f64::from(trailer.total_ticks_max)),
    }
}

/// Flash and RAM of the ELF, like `size -A`: allocated sections by address range.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Memory {
    /// Bytes in flash (code, read-only data, vector table, and the `.data` load image).
    pub flash: u64,
    /// Bytes of static RAM (`.data`, `.bss`, `.uninit`); the rest of RAM is stack.
    pub ram: u64,
    /// `(name, address, size)` of every allocated section.
    pub sections: Vec<(String, u64, u64)>,
}

/// Reads the section headers of a 32-bit little-endian ELF.
pub fn memory(elf: &[u8]) -> anyhow::Result<Memory> {
    let u16_at = |at: usize| elf.get(at..at + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let u32_at = |at: usize| elf.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    if elf.get(..6) != Some(&[0x7f, b'E', b'L', b'F', 1, 1][..]) {
        bail!("not a 32-bit little-endian ELF");
    }
    let header = || -> Option<(usize, usize, usize, usize)> {
        Some((
            u32_at(0x20)? as usize,
            usize::from(u16_at(0x2e)?),
            usize::from(u16_at(0x30)?),
            usize::from(u16_at(0x32)?),
        ))
    };
    let (shoff, shentsize, shnum, shstrndx) = header().context("truncated ELF header")?;
    let section = |i: usize| -> Option<[u32; 6]> {
        let at = shoff + i * shentsize;
        Some([u32_at(at)?, u32_at(at + 4)?, u32_at(at + 8)?, u32_at(at + 12)?, u32_at(at + 16)?, u32_at(at + 20)?])
    };
    let strtab = section(shstrndx).context("no section name table")?[4] as usize;
    let name = |offset: u32| -> String {
        let start = strtab + offset as usize;
        let bytes = elf.get(start..).unwrap_or_default();
        let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
        String::from_utf8_lossy(&bytes[..end]).into_owned()
    };
    const SHF_ALLOC: u32 = 2;
    const SHT_NOBITS: u32 = 8;
    let (mut flash, mut ram, mut sections) = (0u64, 0u64, Vec::new());
    for i in 0..shnum {
        let [name_at, kind, flags, addr, _, size] = section(i).context("truncated section header")?;
        if flags & SHF_ALLOC == 0 || size == 0 {
            continue;
        }
        let size64 = u64::from(size);
        if (0x0800_0000..0x0810_0000).contains(&addr) {
            flash += size64;
        } else if (0x2000_0000..0x2002_0000).contains(&addr) || (0x1000_0000..0x1001_0000).contains(&addr) {
            ram += size64;
            if kind != SHT_NOBITS {
                flash += size64;
            }
        }
        sections.push((name(name_at), u64::from(addr), size64));
    }
    Ok(Memory { flash, ram, sections })
}

/// Everything `qemu-replay` measured.
#[derive(Debug, Clone)]
pub struct QemuReplay {
    /// The ELF that ran.
    pub elf: PathBuf,
    /// The firmware's records and trailer.
    pub firmware: FirmwareRun,
    /// Against the host replay.
    pub comparison: Comparison,
    /// Instructions per step.
    pub cost: StepCost,
    /// Flash and RAM of the ELF.
    pub memory: Memory,
    /// Whether the program ran the controller after each step (the Rust firmware does, the C
    /// example does not).
    pub controller: bool,
}

/// What flies in QEMU.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Program {
    /// The Rust firmware over its built-in tables, their sparse models evaluated as `code` says.
    Firmware(SparseCode),
    /// The C example over the C interface: the built-in tables, or a blob it loads at run time.
    CExample {
        /// A coefficient blob (`model.bin`); `None` flies the built-in tables.
        blob: Option<Vec<u8>>,
    },
}

/// Builds `program`, runs the first `n_samples` of `run` in QEMU with its files in `dir`, and
/// compares with the host replay of the same samples on the same tables (which interprets
/// them).
pub fn qemu_replay(
    run: &Run,
    n_samples: Option<usize>,
    dir: &Path,
    timeout: Duration,
    program: &Program,
) -> anyhow::Result<QemuReplay> {
    let (elf, set) = match program {
        Program::Firmware(code) => (build_firmware(*code)?, estimator_core::coeffs::BUILT_IN),
        Program::CExample { blob } => {
            let set = match blob {
                Some(bytes) => {
                    estimator_core::blob::decode(bytes).map_err(|error| anyhow::anyhow!("the blob: {error}"))?
                }
                None => estimator_core::coeffs::BUILT_IN,
            };
            (c_example::build_c_example()?, set)
        }
    };
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    if let Program::CExample { blob } = program {
        c_example::place_blob(dir, blob.as_deref())?;
    }
    let input = input_bytes(run, n_samples);
    let n = (input.len() - HEADER_LEN) / INPUT_LEN;
    std::fs::File::create(dir.join(INPUT_FILE))
        .and_then(|mut file| file.write_all(&input))
        .with_context(|| format!("writing {}", dir.join(INPUT_FILE).display()))?;
    let firmware = run_firmware(&elf, dir, timeout)?;
    let mut host = model_fit::replay::replay_run(&set, run);
    host.truncate(n);
    let comparison = compare(&host, &firmware.records);
    let cost = step_cost(&firmware.trailer);
    let memory = memory(&std::fs::read(&elf).with_context(|| format!("reading {}", elf.display()))?)?;
    let controller = matches!(program, Program::Firmware(_));
    Ok(QemuReplay { elf, firmware, comparison, cost, memory, controller })
}

/// A human-readable summary.
#[must_use]
pub fn summary(replay: &QemuReplay) -> String {
    use std::fmt::Write as _;
    let mut text = String::new();
    let c = &replay.comparison;
    let _ = writeln!(
        text,
        "firmware {} in QEMU netduinoplus2: {} steps in {:.2} s",
        replay.elf.display(),
        c.steps,
        replay.firmware.wall_s
    );
    let _ = writeln!(text, "max |firmware - host replay| per field:");
    for (name, value) in OUTPUT_FIELD_NAMES.iter().zip(c.max_abs) {
        let _ = writeln!(text, "  {name:<14} {value:e}");
    }
    let _ = writeln!(text, "health bits differing: {} steps", c.health_mismatches);
    let cost = &replay.cost;
    let t = &replay.firmware.trailer;
    let _ = writeln!(
        text,
        "SysTick at {} Hz: {:.4} ticks per instruction on the calibration loop ({} instructions, {} ticks)",
        t.core_clock_hz, cost.ticks_per_instruction, t.calibration_instructions, t.calibration_ticks
    );
    let _ = writeln!(
        text,
        "instructions per step, estimator:              mean {:.0}, max {:.0}",
        cost.estimator_mean, cost.estimator_max
    );
    if replay.controller {
        let _ = writeln!(
            text,
            "instructions per step, estimator + controller: mean {:.0}, max {:.0}",
            cost.total_mean, cost.total_max
        );
    }
    let m = &replay.memory;
    let _ = writeln!(
        text,
        "flash {} bytes, static RAM {} bytes, stack high-water {} of {} bytes",
        m.flash, m.ram, t.stack_used, t.stack_size
    );
    for (name, addr, size) in &m.sections {
        let _ = writeln!(text, "  {name:<16} {addr:#010x} {size:>8}");
    }
    text
}
