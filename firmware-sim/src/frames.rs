//! The binary sample format between the host and the firmware in QEMU (`no_std`).
//!
//! Both files start with a 16-byte header: a 4-byte magic, then little-endian `u32`s: format
//! [`VERSION`], number of records, record length in bytes. Every value is little-endian; floats
//! are IEEE-754 `f32` bit patterns, so both sides see identical inputs (NaN = not measured).
//!
//! - Input file ([`MAGIC_INPUT`]): one [`INPUT_LEN`]-byte record per sample: `phi_deg`,
//!   `alpha_deg`, `cmu_port`, `cmu_stbd`, `cp[12]` (16 `f32`).
//! - Output file ([`MAGIC_OUTPUT`]): one [`OUTPUT_LEN`]-byte [`OutputRecord`] per step, then a
//!   [`TRAILER_LEN`]-byte [`Trailer`] with the timing and memory figures. The header's record
//!   count is the number of records the firmware meant to write; a short file means it stopped.

use estimator_core::controller::Demand;
use estimator_core::{Health, Input, Output};

/// Magic of an input file.
pub const MAGIC_INPUT: [u8; 4] = *b"RMEI";
/// Magic of an output file.
pub const MAGIC_OUTPUT: [u8; 4] = *b"RMEO";
/// Magic of the output file's trailer.
pub const MAGIC_TRAILER: [u8; 4] = *b"RMET";
/// Format version.
pub const VERSION: u32 = 1;
/// Header length, bytes.
pub const HEADER_LEN: usize = 16;
/// Input record length, bytes (16 `f32`).
pub const INPUT_LEN: usize = 16 * 4;
/// Output record length, bytes (20 words).
pub const OUTPUT_LEN: usize = 20 * 4;
/// Trailer length, bytes.
pub const TRAILER_LEN: usize = 4 + 4 * 13;

/// Why a header did not decode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// Wrong magic (not this kind of file).
    Magic,
    /// Another format version.
    Version(u32),
    /// Another record length.
    RecordLen(u32),
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Magic => write!(f, "wrong magic"),
            Self::Version(version) => write!(f, "format version {version}, expected {VERSION}"),
            Self::RecordLen(len) => write!(f, "record length {len}"),
        }
    }
}

/// A header: `magic`, version, `n_records`, `record_len`.
#[must_use]
pub fn encode_header(magic: [u8; 4], n_records: u32, record_len: usize) -> [u8; HEADER_LEN] {
    let mut bytes = [0; HEADER_LEN];
    bytes[..4].copy_from_slice(&magic);
    bytes[4..8].copy_from_slice(&VERSION.to_le_bytes());
    bytes[8..12].copy_from_slice(&n_records.to_le_bytes());
    bytes[12..16].copy_from_slice(&(record_len as u32).to_le_bytes());
    bytes
}

/// Checks a header against the expected magic and record length; returns the record count.
pub fn decode_header(bytes: &[u8; HEADER_LEN], magic: [u8; 4], record_len: usize) -> Result<u32, FrameError> {
    if bytes[..4] != magic {
        return Err(FrameError::Magic);
    }
    let version = word(bytes, 1);
    if version != VERSION {
        return Err(FrameError::Version(version));
    }
    let len = word(bytes, 3);
    if len as usize != record_len {
        return Err(FrameError::RecordLen(len));
    }
    Ok(word(bytes, 2))
}

/// The `i`-th little-endian `u32` of `bytes`.
fn word(bytes: &[u8], i: usize) -> u32 {
    let mut le = [0; 4];
    le.copy_from_slice(&bytes[4 * i..4 * i + 4]);
    u32::from_le_bytes(le)
}

/// Writes `value` as the `i`-th little-endian `u32` of `bytes`.
fn put(bytes: &mut [u8], i: usize, value: u32) {
    bytes[4 * i..4 * i + 4].copy_from_slice(&value.to_le_bytes());
}

/// One sample's input record.
#[must_use]
pub fn encode_input(input: &Input) -> [u8; INPUT_LEN] {
    let mut bytes = [0; INPUT_LEN];
    let head = [input.phi_deg, input.alpha_deg, input.cmu_port, input.cmu_stbd];
    for (i, value) in head.iter().chain(input.cp.iter()).enumerate() {
        put(&mut bytes, i, value.to_bits());
    }
    bytes
}

/// Decodes one input record (bit-exact, NaN payloads included).
#[must_use]
pub fn decode_input(bytes: &[u8; INPUT_LEN]) -> Input {
    let float = |i: usize| f32::from_bits(word(bytes, i));
    Input {
        phi_deg: float(0),
        alpha_deg: float(1),
        cmu_port: float(2),
        cmu_stbd: float(3),
        cp: core::array::from_fn(|tap| float(4 + tap)),
    }
}

/// What the firmware writes per step: the estimator's [`Output`] (every field, health bits
/// included), the controller's [`Demand`] and health flags, and the step's SysTick ticks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputRecord {
    /// The estimator's output.
    pub output: Output,
    /// The controller's demand.
    pub demand: Demand,
    /// Health flags the controller set this step (kept apart from the estimator's).
    pub controller_flags: u16,
    /// SysTick ticks of `Estimator::step` alone.
    pub ticks_estimator: u32,
    /// SysTick ticks of the estimator and the controller.
    pub ticks_total: u32,
}

/// The output's `f32` fields in record order ([`Output::estimates`]).
#[must_use]
pub const fn output_fields(output: &Output) -> [f32; 10] {
    output.estimates()
}

/// Names of [`output_fields`], in order.
pub const OUTPUT_FIELD_NAMES: [&str; 10] = Output::ESTIMATE_NAMES;

/// One step's output record.
#[must_use]
pub fn encode_output(record: &OutputRecord) -> [u8; OUTPUT_LEN] {
    let mut bytes = [0; OUTPUT_LEN];
    for (i, value) in output_fields(&record.output).iter().enumerate() {
        put(&mut bytes, i, value.to_bits());
    }
    let health = &record.output.health;
    put(&mut bytes, 10, u32::from(health.flags));
    put(&mut bytes, 11, u32::from(health.cp_missing));
    put(&mut bytes, 12, u32::from(health.cp_rejected));
    put(&mut bytes, 13, u32::from(health.cp_isolated));
    put(&mut bytes, 14, record.demand.cmu[0].to_bits());
    put(&mut bytes, 15, record.demand.cmu[1].to_bits());
    put(&mut bytes, 16, record.demand.moment.to_bits());
    put(&mut bytes, 17, u32::from(record.controller_flags));
    put(&mut bytes, 18, record.ticks_estimator);
    put(&mut bytes, 19, record.ticks_total);
    bytes
}

/// Decodes one output record.
#[must_use]
pub fn decode_output(bytes: &[u8; OUTPUT_LEN]) -> OutputRecord {
    let float = |i: usize| f32::from_bits(word(bytes, i));
    let bits = |i: usize| word(bytes, i) as u16;
    OutputRecord {
        output: Output {
            cl_egk: float(0),
            cl_pressure: float(1),
            cl_roll: float(2),
            cl_afc_port: float(3),
            cl_afc_stbd: float(4),
            cl_afc: float(5),
            cl_linear: float(6),
            coupling: float(7),
            cl: float(8),
            phi_dot_rad_s: float(9),
            health: Health { flags: bits(10), cp_missing: bits(11), cp_rejected: bits(12), cp_isolated: bits(13) },
        },
        demand: Demand { cmu: [float(14), float(15)], moment: float(16) },
        controller_flags: bits(17),
        ticks_estimator: word(bytes, 18),
        ticks_total: word(bytes, 19),
    }
}

/// The end of an output file: timing and memory figures of the whole run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Trailer {
    /// Steps run.
    pub steps: u32,
    /// Sum of the estimator's ticks over the steps.
    pub estimator_ticks_sum: u64,
    /// Largest estimator step, ticks.
    pub estimator_ticks_max: u32,
    /// Sum of the estimator + controller ticks over the steps.
    pub total_ticks_sum: u64,
    /// Largest estimator + controller step, ticks.
    pub total_ticks_max: u32,
    /// Instructions of the calibration loop (a counted `subs`/`bne` loop).
    pub calibration_instructions: u32,
    /// SysTick ticks the calibration loop took.
    pub calibration_ticks: u32,
    /// The core clock the firmware configured SysTick for, Hz.
    pub core_clock_hz: u32,
    /// Stack bytes ever used (paint-stack high-water mark).
    pub stack_used: u32,
    /// Stack bytes available (from the end of the statics to the top of RAM).
    pub stack_size: u32,
}

/// The trailer's bytes.
#[must_use]
pub fn encode_trailer(trailer: &Trailer) -> [u8; TRAILER_LEN] {
    let mut bytes = [0; TRAILER_LEN];
    bytes[..4].copy_from_slice(&MAGIC_TRAILER);
    let words = [
        trailer.steps,
        trailer.estimator_ticks_sum as u32,
        (trailer.estimator_ticks_sum >> 32) as u32,
        trailer.estimator_ticks_max,
        trailer.total_ticks_sum as u32,
        (trailer.total_ticks_sum >> 32) as u32,
        trailer.total_ticks_max,
        trailer.calibration_instructions,
        trailer.calibration_ticks,
        trailer.core_clock_hz,
        trailer.stack_used,
        trailer.stack_size,
        0,
    ];
    for (i, value) in words.into_iter().enumerate() {
        put(&mut bytes, i + 1, value);
    }
    bytes
}

/// Decodes a trailer.
pub fn decode_trailer(bytes: &[u8; TRAILER_LEN]) -> Result<Trailer, FrameError> {
    if bytes[..4] != MAGIC_TRAILER {
        return Err(FrameError::Magic);
    }
    let w = |i: usize| word(bytes, i + 1);
    Ok(Trailer {
        steps: w(0),
        estimator_ticks_sum: u64::from(w(1)) | (u64::from(w(2)) << 32),
        estimator_ticks_max: w(3),
        total_ticks_sum: u64::from(w(4)) | (u64::from(w(5)) << 32),
        total_ticks_max: w(6),
        calibration_instructions: w(7),
        calibration_ticks: w(8),
        core_clock_hz: w(9),
        stack_used: w(10),
        stack_size: w(11),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_bit_exactly() {
        let input = Input {
            phi_deg: -12.5,
            alpha_deg: 20.0,
            cmu_port: f32::NAN,
            cmu_stbd: 0.01,
            cp: core::array::from_fn(|tap| tap as f32 * -0.1),
        };
        let decoded = decode_input(&encode_input(&input));
        assert_eq!(decoded.phi_deg.to_bits(), input.phi_deg.to_bits());
        assert!(decoded.cmu_port.is_nan());
        assert_eq!(decoded.cp, input.cp);
        let record = OutputRecord {
            output: Output {
                cl: 0.25,
                health: Health { flags: 3, cp_missing: 0x800, cp_rejected: 1, cp_isolated: 2 },
                ..Output::default()
            },
            demand: Demand { cmu: [0.01, 0.0], moment: -0.002 },
            controller_flags: 7,
            ticks_estimator: 1234,
            ticks_total: 2345,
        };
        assert_eq!(decode_output(&encode_output(&record)), record);
        let trailer = Trailer { steps: 9, estimator_ticks_sum: 1 << 40, total_ticks_max: 5, ..Trailer::default() };
        assert_eq!(decode_trailer(&encode_trailer(&trailer)), Ok(trailer));
        let header = encode_header(MAGIC_INPUT, 42, INPUT_LEN);
        assert_eq!(decode_header(&header, MAGIC_INPUT, INPUT_LEN), Ok(42));
        assert_eq!(decode_header(&header, MAGIC_OUTPUT, INPUT_LEN), Err(FrameError::Magic));
    }
}
