//! Hardware-in-the-loop in QEMU: the firmware's real-time loop on an emulated STM32F405
//! (`qemu-system-arm -machine netduinoplus2`), fed a recorded run over its serial link.
//!
//! QEMU connects the firmware's USART1 to a Unix socket (a QEMU chardev) and waits for the
//! host before it starts the guest. The host reads the firmware's `Hello`, sends a coefficient
//! blob when asked to (chunks, then a commit, answered with the firmware's verdict), then the
//! run's samples as [`firmware_sim::link`] frames, one in flight at a time: the firmware's
//! 1 kHz timer steps each at its next tick and answers with the estimate, which releases the
//! next sample. `Stop` ends the run with the firmware's report (ticks, idle ticks, overruns,
//! bad frames, step times, latencies, stack) and QEMU's exit.
//!
//! The reference is the same fixed-rate loop (estimator and controller,
//! [`firmware_sim::io::FixedRateLoop`]) run on the host over the same f32 samples with the
//! tables the firmware reports it flies: the built-in ones, or the loaded blob. Every output
//! field is compared bit for bit.

use std::io::{Read as _, Write as _};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use estimator_core::CoefficientSet;
use firmware_sim::dataset::Run;
use firmware_sim::io::{FixedRateLoop, InputBoard, TickCounter};
use firmware_sim::link::{
    self, BLOB_CHUNK_LEN, BlobRejection, Estimate, FIRMWARE_BLOCKS, FrameDecoder, FromFirmware, LinkReport,
    MAX_FRAME_LEN, SampleInput, Tables, ToFirmware,
};
use serde::Serialize;

use crate::qemu::{self, QEMU, SparseCode};

/// How long the host waits for one answer of the firmware (QEMU runs in real time when idle).
const ANSWER_TIMEOUT: Duration = Duration::from_secs(20);

/// Names of the compared outputs, in the order of [`HilComparison::max_abs`]: the estimator's
/// estimates, its four health words, the demand and the controller's flags.
pub const COMPARED_FIELDS: [&str; 18] = {
    let mut names = [""; 18];
    let mut i = 0;
    while i < 10 {
        names[i] = estimator_core::Output::ESTIMATE_NAMES[i];
        i += 1;
    }
    let rest = [
        "health_flags",
        "cp_missing",
        "cp_rejected",
        "cp_isolated",
        "demand_cmu_port",
        "demand_cmu_stbd",
        "demand_moment",
        "controller_flags",
    ];
    while i < 18 {
        names[i] = rest[i - 10];
        i += 1;
    }
    names
};

/// One step as compared: every field as an f32 bit pattern (integers widened exactly).
fn fields(estimate: &Estimate) -> [f32; 18] {
    let mut out = [0.0f32; 18];
    out[..10].copy_from_slice(&estimate.estimates);
    for (slot, word) in out[10..14].iter_mut().zip(estimate.health) {
        *slot = f32::from(word);
    }
    out[14] = estimate.demand_cmu[0];
    out[15] = estimate.demand_cmu[1];
    out[16] = estimate.demand_moment;
    out[17] = f32::from(estimate.controller_flags);
    out
}

/// The firmware against the host's loop.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HilComparison {
    /// Steps compared.
    pub steps: usize,
    /// Largest |firmware - host| per field of [`COMPARED_FIELDS`] (0 for identical bits, NaN
    /// against NaN included; infinite where only one side is NaN).
    pub max_abs: Vec<f32>,
    /// Steps where any field's bits differ.
    pub steps_not_identical: usize,
}

/// Compares step by step; a missing step counts as not identical.
#[must_use]
pub fn compare(host: &[Estimate], firmware: &[Estimate]) -> HilComparison {
    let mut max_abs = vec![0.0f32; COMPARED_FIELDS.len()];
    let mut steps_not_identical = host.len().abs_diff(firmware.len());
    for (host, firmware) in host.iter().zip(firmware) {
        let (a, b) = (fields(host), fields(firmware));
        let mut identical = host.seq == firmware.seq;
        for field in 0..a.len() {
            identical &= a[field].to_bits() == b[field].to_bits();
            let diff = qemu::abs_diff(a[field], b[field]);
            max_abs[field] = max_abs[field].max(diff);
        }
        steps_not_identical += usize::from(!identical);
    }
    HilComparison { steps: host.len().min(firmware.len()), max_abs, steps_not_identical }
}

/// No clock on the host: every step takes 0 ticks.
struct NoTicks;

impl TickCounter for NoTicks {
    fn now(&mut self) -> u32 {
        0
    }
    fn elapsed(&self, _: u32, _: u32) -> u32 {
        0
    }
}

/// The host's run of the firmware's loop (estimator and controller) over `samples`, with the
/// built-in tables as generated code or with `set`, interpreted: what the firmware flies.
#[must_use]
pub fn host_loop(samples: &[SampleInput], set: Option<&CoefficientSet>) -> Vec<Estimate> {
    enum Reference<'a> {
        BuiltIn(FixedRateLoop<'static, estimator_core::coeffs::CompiledDefault>),
        Loaded(FixedRateLoop<'a>),
    }
    let mut reference = match set {
        None => Reference::BuiltIn(FixedRateLoop::built_in(FIRMWARE_BLOCKS)),
        Some(set) => Reference::Loaded(FixedRateLoop::new(set, FIRMWARE_BLOCKS)),
    };
    samples
        .iter()
        .enumerate()
        .map(|(seq, sample)| {
            let mut board = InputBoard::new(estimator_core::Input::from(sample));
            let result = match &mut reference {
                Reference::BuiltIn(fixed_rate) => fixed_rate.step(&mut board, &mut NoTicks),
                Reference::Loaded(fixed_rate) => fixed_rate.step(&mut board, &mut NoTicks),
            };
            Estimate::from_step(seq as u32, &result, 0)
        })
        .collect()
}

/// What the firmware said of the blob it was sent.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BlobOutcome {
    /// The blob's file.
    pub file: PathBuf,
    /// Its length, bytes.
    pub len: usize,
    /// Accepted: the firmware flies it.
    pub accepted: bool,
    /// The firmware's reason when it refused it.
    pub rejection: Option<String>,
}

/// Instructions and latencies from the firmware's report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HilTiming {
    /// SysTick ticks per instruction on the calibration loop (0.168 under `-icount shift=0`).
    pub ticks_per_instruction: f64,
    /// Mean instructions of `Estimator::step` after the warm-up steps.
    pub estimator_mean: f64,
    /// Largest instructions of `Estimator::step` after the warm-up steps.
    pub estimator_max: f64,
    /// Mean instructions of the estimator and the controller after the warm-up.
    pub total_mean: f64,
    /// Largest, estimator and controller, after the warm-up.
    pub total_max: f64,
    /// Mean latency from a sample frame's arrival to the end of its step, us.
    pub latency_mean_us: f64,
    /// Largest such latency, us.
    pub latency_max_us: f64,
    /// Shortest and longest time between two ticks of the loop, us.
    pub period_us: [f64; 2],
}

/// Everything a hardware-in-the-loop run measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HilRun {
    /// The run's file.
    pub run: PathBuf,
    /// Samples streamed.
    pub samples: usize,
    /// The tables the firmware flew.
    pub tables: &'static str,
    /// The blob sent, if any.
    pub blob: Option<BlobOutcome>,
    /// Against the host's loop.
    pub comparison: HilComparison,
    /// The firmware's own counters (ticks of the core clock).
    pub report: LinkReport,
    /// Step instructions and latency.
    pub timing: HilTiming,
    /// Wall-clock time of the QEMU run, s.
    pub wall_s: f64,
}

fn timing(report: &LinkReport) -> HilTiming {
    let per = f64::from(report.calibration_ticks) / f64::from(report.calibration_instructions.max(1));
    let timed = f64::from(report.steps.saturating_sub(link::WARM_UP_STEPS).max(1));
    let instructions = |ticks: f64| if per > 0.0 { ticks / per } else { f64::NAN };
    let us = |ticks: f64| ticks / f64::from(report.core_clock_hz.max(1)) * 1e6;
    HilTiming {
        ticks_per_instruction: per,
        estimator_mean: instructions(report.estimator_ticks_sum as f64 / timed),
        estimator_max: instructions(f64::from(report.estimator_ticks_max)),
        total_mean: instructions(report.total_ticks_sum as f64 / timed),
        total_max: instructions(f64::from(report.total_ticks_max)),
        latency_mean_us: us(report.latency_ticks_sum as f64 / f64::from(report.steps.max(1))),
        latency_max_us: us(f64::from(report.latency_ticks_max)),
        period_us: report.period_ticks.map(|ticks| us(f64::from(ticks))),
    }
}

/// The host's end of the serial link.
struct Port {
    stream: UnixStream,
    reader: std::io::BufReader<UnixStream>,
    decoder: FrameDecoder,
    /// Frames the host could not decode.
    bad_frames: usize,
}

impl Port {
    fn send(&mut self, message: &ToFirmware<'_>) -> anyhow::Result<()> {
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = link::encode(message, &mut frame).map_err(|e| anyhow::anyhow!("encoding a frame: {e}"))?;
        self.stream.write_all(&frame[..len]).context("writing to the firmware's serial link")
    }

    /// The next message from the firmware.
    fn receive(&mut self) -> anyhow::Result<FromFirmware> {
        let mut byte = [0u8; 1];
        loop {
            match self.reader.read(&mut byte) {
                Ok(0) => bail!("the firmware closed its serial link"),
                Ok(_) => {}
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                    bail!("the firmware did not answer within {} s", ANSWER_TIMEOUT.as_secs())
                }
                Err(e) => return Err(e).context("reading the firmware's serial link"),
            }
            match self.decoder.push(byte[0]) {
                Some(Ok(())) => match self.decoder.message::<FromFirmware>() {
                    Ok(message) => return Ok(message),
                    Err(_) => self.bad_frames += 1,
                },
                Some(Err(_)) => self.bad_frames += 1,
                None => {}
            }
        }
    }
}

/// QEMU with the firmware, killed when dropped.
struct Emulator {
    child: Child,
}

impl Drop for Emulator {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Starts QEMU with `elf`, its USART1 on a Unix socket in `socket_dir`, its semihosting
/// output in `log`, and connects to the socket.
fn boot(elf: &Path, socket_dir: &Path, work_dir: &Path, log: &Path) -> anyhow::Result<(Emulator, Port)> {
    let socket = socket_dir.join("link.sock");
    let chardev = format!("socket,id=link,path={},server=on,wait=on", socket.display());
    let args = ["-display", "none", "-monitor", "none", "-icount", "shift=0,sleep=off", "-chardev", &chardev];
    let child = qemu::spawn(elf, work_dir, log, &[&args[..], &["-serial", "chardev:link"]].concat())?;
    let mut emulator = Emulator { child };
    let started = Instant::now();
    let stream = loop {
        match UnixStream::connect(&socket) {
            Ok(stream) => break stream,
            Err(error) => {
                if let Some(status) = emulator.child.try_wait()? {
                    bail!("{QEMU} exited ({status}) before its serial link opened: {}", stderr_of(&mut emulator));
                }
                if started.elapsed() > ANSWER_TIMEOUT {
                    bail!("{QEMU}'s serial link {} did not open: {error}", socket.display());
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    };
    stream.set_read_timeout(Some(ANSWER_TIMEOUT)).context("setting the link's timeout")?;
    let reader = std::io::BufReader::new(stream.try_clone().context("cloning the link's socket")?);
    Ok((emulator, Port { stream, reader, decoder: FrameDecoder::new(), bad_frames: 0 }))
}

fn stderr_of(emulator: &mut Emulator) -> String {
    let mut text = String::new();
    if let Some(mut pipe) = emulator.child.stderr.take() {
        let _ = pipe.read_to_string(&mut text);
    }
    text
}

/// Sends `blob` and returns the firmware's verdict.
fn send_blob(port: &mut Port, blob: &[u8]) -> anyhow::Result<Result<Tables, BlobRejection>> {
    port.send(&ToFirmware::BlobStart { len: u32::try_from(blob.len()).context("blob over 4 GiB")? })?;
    for (i, chunk) in blob.chunks(BLOB_CHUNK_LEN).enumerate() {
        port.send(&ToFirmware::BlobChunk { offset: (i * BLOB_CHUNK_LEN) as u32, bytes: chunk })?;
    }
    port.send(&ToFirmware::BlobCommit)?;
    match port.receive()? {
        FromFirmware::Blob(verdict) => Ok(verdict),
        other => bail!("expected the firmware's verdict on the blob, got {other:?}"),
    }
}

/// The first `n_samples` samples of `run` (all when `None`), as the link carries them.
#[must_use]
pub fn samples_of(run: &Run, n_samples: Option<usize>) -> Vec<SampleInput> {
    let n = n_samples.map_or(run.channels.len(), |n| n.min(run.channels.len()));
    (0..n).map(|k| SampleInput::from(&model_fit::replay::input_at(run, k))).collect()
}

/// Builds the firmware, boots it in QEMU with its files in `dir`, sends the blob `blob` (its
/// file and bytes) if given, streams `samples` and compares with the host's loop.
pub fn hil(
    run_file: &Path,
    samples: &[SampleInput],
    blob: Option<(&Path, &[u8])>,
    dir: &Path,
) -> anyhow::Result<HilRun> {
    let elf = qemu::build_firmware(SparseCode::Compiled)?;
    // A Unix socket's path is limited to about 100 bytes: it lives in its own short folder.
    let socket_dir = tempfile::Builder::new().prefix("hil").tempdir().context("creating the socket folder")?;
    let started = Instant::now();
    let (mut emulator, mut port) = boot(&elf, socket_dir.path(), dir, &dir.join(qemu::LOG_FILE))?;
    let FromFirmware::Hello { protocol, .. } = port.receive()? else {
        bail!("the firmware did not start with Hello");
    };
    if protocol != link::PROTOCOL_VERSION {
        bail!("the firmware speaks link protocol {protocol}, this host {}", link::PROTOCOL_VERSION);
    }
    let mut loaded: Option<CoefficientSet> = None;
    let blob_outcome = match blob {
        None => None,
        Some((file, bytes)) => {
            let verdict = send_blob(&mut port, bytes)?;
            if verdict.is_ok() {
                let set = estimator_core::blob::decode(bytes).map_err(|error| {
                    anyhow::anyhow!("the firmware accepted {} but the host reads it as: {error}", file.display())
                })?;
                loaded = Some(set);
            }
            Some(BlobOutcome {
                file: file.to_path_buf(),
                len: bytes.len(),
                accepted: verdict.is_ok(),
                rejection: verdict.err().map(|reason| reason.to_string()),
            })
        }
    };
    let mut firmware = Vec::with_capacity(samples.len());
    for (seq, input) in samples.iter().enumerate() {
        port.send(&ToFirmware::Sample { seq: seq as u32, input: *input })?;
        match port.receive()? {
            FromFirmware::Estimate(estimate) if estimate.seq == seq as u32 => firmware.push(estimate),
            other => bail!("sample {seq}: expected its estimate, got {other:?}"),
        }
    }
    port.send(&ToFirmware::Stop)?;
    let report = match port.receive()? {
        FromFirmware::Report(report) => report,
        other => bail!("expected the firmware's report, got {other:?}"),
    };
    let status = loop {
        if let Some(status) = emulator.child.try_wait()? {
            break status;
        }
        if started.elapsed() > ANSWER_TIMEOUT + Duration::from_secs(samples.len() as u64 / 100) {
            bail!("{QEMU} did not exit after Stop");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    if !status.success() {
        bail!("the firmware failed in QEMU ({status}): {}", stderr_of(&mut emulator));
    }
    let wall_s = started.elapsed().as_secs_f64();
    let host = host_loop(samples, loaded.as_ref());
    let mut report_json = report;
    report_json.bad_frames += port.bad_frames as u32;
    Ok(HilRun {
        run: run_file.to_path_buf(),
        samples: samples.len(),
        tables: if loaded.is_some() { "loaded blob" } else { "built-in" },
        blob: blob_outcome,
        comparison: compare(&host, &firmware),
        report: report_json,
        timing: timing(&report),
        wall_s,
    })
}

/// A human-readable summary.
#[must_use]
pub fn summary(run: &HilRun) -> String {
    use std::fmt::Write as _;
    let mut text = String::new();
    let c = &run.comparison;
    let _ = writeln!(
        text,
        "hil {}: {} samples over the serial link at 1 kHz in QEMU netduinoplus2 ({:.1} s), tables: {}",
        run.run.display(),
        run.samples,
        run.wall_s,
        run.tables
    );
    if let Some(blob) = &run.blob {
        let verdict = blob.rejection.as_deref().map_or("accepted".to_owned(), |why| format!("rejected: {why}"));
        let _ = writeln!(text, "blob {} ({} bytes): {verdict}", blob.file.display(), blob.len);
    }
    let _ = writeln!(
        text,
        "max |firmware - host loop| per output ({} steps, {} not bit-identical):",
        c.steps, c.steps_not_identical
    );
    for (name, value) in COMPARED_FIELDS.iter().zip(&c.max_abs) {
        let _ = writeln!(text, "  {name:<17} {value:e}");
    }
    let r = &run.report;
    let _ = writeln!(
        text,
        "loop: {} ticks, {} steps, {} idle ticks, {} overruns, {} bad frames, {} dropped samples, {} dropped estimates",
        r.ticks, r.steps, r.idle_ticks, r.overruns, r.bad_frames, r.dropped_samples, r.dropped_estimates
    );
    let t = &run.timing;
    let _ = writeln!(
        text,
        "instructions per step after the first {} (SysTick {:.4} ticks per instruction):",
        link::WARM_UP_STEPS,
        t.ticks_per_instruction
    );
    let _ = writeln!(text, "  estimator:              mean {:.0}, max {:.0}", t.estimator_mean, t.estimator_max);
    let _ = writeln!(text, "  estimator + controller: mean {:.0}, max {:.0}", t.total_mean, t.total_max);
    let _ = writeln!(
        text,
        "latency from a sample frame's arrival to the end of its step: mean {:.0} us, max {:.0} us",
        t.latency_mean_us, t.latency_max_us
    );
    let _ = writeln!(
        text,
        "tick period {:.1} to {:.1} us; stack {} of {} bytes",
        t.period_us[0], t.period_us[1], r.stack[0], r.stack[1]
    );
    text
}

/// The figures over every run of a `hil` call.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HilTotals {
    /// Runs.
    pub runs: usize,
    /// Steps compared.
    pub steps: usize,
    /// Steps where any output's bits differ from the host's loop.
    pub steps_not_identical: usize,
    /// Largest |firmware - host| over every output and run.
    pub max_abs: f32,
    /// Overruns, bad frames and dropped samples or estimates, summed.
    pub overruns: u64,
    /// Bad frames (firmware and host).
    pub bad_frames: u64,
    /// Samples or estimates dropped.
    pub dropped: u64,
    /// Largest estimator step after the warm-up, instructions.
    pub estimator_max: f64,
    /// Mean estimator step after the warm-up, instructions (mean of the runs' means).
    pub estimator_mean: f64,
    /// Largest estimator + controller step, instructions.
    pub total_max: f64,
    /// Largest arrival-to-output latency, us.
    pub latency_max_us: f64,
    /// Blobs the firmware refused.
    pub blobs_rejected: usize,
}

/// [`HilTotals`] of `runs`.
#[must_use]
pub fn totals_json(runs: &[HilRun]) -> HilTotals {
    let sum = |f: &dyn Fn(&HilRun) -> u32| runs.iter().map(|run| u64::from(f(run))).sum::<u64>();
    let max = |f: &dyn Fn(&HilRun) -> f64| runs.iter().map(f).fold(0.0, f64::max);
    HilTotals {
        runs: runs.len(),
        steps: runs.iter().map(|run| run.comparison.steps).sum(),
        steps_not_identical: runs.iter().map(|run| run.comparison.steps_not_identical).sum(),
        max_abs: runs.iter().flat_map(|run| run.comparison.max_abs.iter().copied()).fold(0.0, f32::max),
        overruns: sum(&|run| run.report.overruns),
        bad_frames: sum(&|run| run.report.bad_frames),
        dropped: sum(&|run| run.report.dropped_samples + run.report.dropped_estimates),
        estimator_max: max(&|run| run.timing.estimator_max),
        estimator_mean: runs.iter().map(|run| run.timing.estimator_mean).sum::<f64>() / runs.len().max(1) as f64,
        total_max: max(&|run| run.timing.total_max),
        latency_max_us: max(&|run| run.timing.latency_max_us),
        blobs_rejected: runs.iter().filter(|run| run.blob.as_ref().is_some_and(|blob| !blob.accepted)).count(),
    }
}

/// The totals as text.
#[must_use]
pub fn totals(runs: &[HilRun]) -> String {
    let t = totals_json(runs);
    format!(
        "all runs ({}): {} steps, {} not bit-identical to the host loop (largest difference {:e}); \
         {} overruns, {} bad frames, {} dropped; estimator instructions per step after the first {}: \
         mean {:.0}, max {:.0} (with the controller: max {:.0}); latency max {:.0} us; blobs rejected: {}\n",
        t.runs,
        t.steps,
        t.steps_not_identical,
        t.max_abs,
        t.overruns,
        t.bad_frames,
        t.dropped,
        link::WARM_UP_STEPS,
        t.estimator_mean,
        t.estimator_max,
        t.total_max,
        t.latency_max_us,
        t.blobs_rejected
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimate(seq: u32, cl: f32) -> Estimate {
        Estimate {
            seq,
            estimates: [cl; 10],
            health: [0; 4],
            demand_cmu: [0.001, f32::NAN],
            demand_moment: 0.0,
            controller_flags: 0,
            ticks_estimator: 7,
            ticks_total: 9,
            latency_ticks: 11,
        }
    }

    #[test]
    fn identical_bits_compare_equal_nan_included_and_timing_is_not_compared() {
        let host = [estimate(0, 0.01), estimate(1, f32::NAN)];
        let mut firmware = host;
        firmware[1].ticks_estimator = 99;
        let c = compare(&host, &firmware);
        assert_eq!((c.steps, c.steps_not_identical), (2, 0));
        assert!(c.max_abs.iter().all(|&d| d == 0.0));
    }

    #[test]
    fn a_differing_bit_a_nan_and_a_missing_step_are_counted() {
        let host = [estimate(0, 0.01), estimate(1, 0.02), estimate(2, 0.03)];
        let mut firmware = vec![estimate(0, 0.01), estimate(1, 0.02)];
        firmware[0].estimates[0] = f32::from_bits(0.01f32.to_bits() + 1);
        firmware[0].health[2] = 4;
        firmware[1].estimates[1] = f32::NAN;
        let c = compare(&host, &firmware);
        assert_eq!((c.steps, c.steps_not_identical), (2, 3));
        assert!(c.max_abs[0] > 0.0 && c.max_abs[0] < 1e-8, "{:?}", c.max_abs);
        assert_eq!(c.max_abs[1], f32::INFINITY);
        assert_eq!(c.max_abs[12], 4.0, "cp_rejected");
    }

    #[test]
    fn the_host_loop_steps_the_firmware_loop_and_notes_its_demand() {
        let input = SampleInput { phi_deg: 5.0, alpha_deg: 20.0, cmu: [0.0, 0.0], cp: [-0.4; 12] };
        let samples = vec![input; 50];
        let built_in = host_loop(&samples, None);
        let loaded = host_loop(&samples, Some(&estimator_core::coeffs::BUILT_IN));
        assert_eq!(compare(&built_in, &loaded).steps_not_identical, 0, "generated code = interpreted tables");
        assert!(built_in.iter().all(|e| e.demand_cmu.iter().all(|c| c.is_finite())));
        assert_eq!(built_in.last().map(|e| e.seq), Some(49));
    }
}
