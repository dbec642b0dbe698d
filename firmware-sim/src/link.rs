//! The serial link between the firmware and a rig or a companion computer (`no_std`).
//!
//! Every message is a `postcard` serialization of [`ToFirmware`] or [`FromFirmware`], framed as
//!
//! ```text
//! COBS( PROTOCOL_VERSION (1 byte) ‖ postcard(message) ‖ CRC-32 of the two, little-endian ) 0x00
//! ```
//!
//! COBS (Cheshire and Baker, "Consistent Overhead Byte Stuffing", IEEE/ACM Trans. Networking
//! 7(2), 1999) leaves no zero byte inside a frame, so the 0x00 delimiter resynchronises a
//! receiver after any lost or corrupted byte: at most the frame it hit is lost. The CRC is
//! CRC-32/ISO-HDLC (the zlib CRC, the same as the coefficient blob's); a frame whose CRC,
//! version or message does not check is counted and dropped by [`FrameDecoder`], never acted on.
//! Floats travel as their IEEE-754 bits (postcard writes `f32` as four little-endian bytes), so
//! both ends see bit-identical values, NaN (not measured) included.

use serde::{Deserialize, Serialize};

/// Version of the link protocol: the first byte of every frame. Bump it with any change of a
/// message.
pub const PROTOCOL_VERSION: u8 = 1;

/// Largest encoded frame, delimiter included, bytes. The largest message is a blob chunk of
/// [`BLOB_CHUNK_LEN`] bytes (about 140 bytes framed); a longer run of bytes without a delimiter
/// is dropped as one bad frame.
pub const MAX_FRAME_LEN: usize = 256;

/// Largest payload of one [`ToFirmware::BlobChunk`], bytes.
pub const BLOB_CHUNK_LEN: usize = 128;

/// The controller blocks the firmware flies: feedforward on; a board has no balance, so no
/// feedback. The host's reference replay of a hardware-in-the-loop run uses the same.
pub const FIRMWARE_BLOCKS: estimator_core::controller::Blocks =
    estimator_core::controller::Blocks { feedforward: true, feedback: false };

/// Bytes of the version and the CRC around a message.
const ENVELOPE_LEN: usize = 1 + 4;

/// CRC-32/ISO-HDLC (zlib, PNG), as the coefficient blob uses.
const FRAME_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The inputs of one step as they travel: the estimator's [`estimator_core::Input`] field by
/// field (NaN = not measured).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SampleInput {
    /// Roll angle, deg.
    pub phi_deg: f32,
    /// Angle of attack, deg.
    pub alpha_deg: f32,
    /// Measured `[port, starboard]` Cmu.
    pub cmu: [f32; 2],
    /// Pressure coefficients `cp01`..`cp12`.
    pub cp: [f32; estimator_core::coeffs::N_TAPS],
}

impl From<&estimator_core::Input> for SampleInput {
    fn from(input: &estimator_core::Input) -> Self {
        Self { phi_deg: input.phi_deg, alpha_deg: input.alpha_deg, cmu: [input.cmu_port, input.cmu_stbd], cp: input.cp }
    }
}

impl From<&SampleInput> for estimator_core::Input {
    fn from(sample: &SampleInput) -> Self {
        Self {
            phi_deg: sample.phi_deg,
            alpha_deg: sample.alpha_deg,
            cmu_port: sample.cmu[0],
            cmu_stbd: sample.cmu[1],
            cp: sample.cp,
        }
    }
}

/// What the rig or the companion computer sends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ToFirmware<'a> {
    /// One sample, stepped at the next tick of the loop (in order; `seq` comes back in the
    /// [`Estimate`]).
    Sample {
        /// The sender's sequence number.
        seq: u32,
        /// The inputs.
        input: SampleInput,
    },
    /// Starts the transfer of a coefficient blob (`estimator_core::blob`) of `len` bytes.
    BlobStart {
        /// Blob length, bytes.
        len: u32,
    },
    /// Bytes of the blob at `offset` (chunks in order, each at most [`BLOB_CHUNK_LEN`] bytes).
    BlobChunk {
        /// Offset of the first byte in the blob.
        offset: u32,
        /// The bytes.
        #[serde(borrow)]
        bytes: &'a [u8],
    },
    /// The blob is complete: validate it and fly it (answered by [`FromFirmware::Blob`]).
    BlobCommit,
    /// Asks for the [`LinkReport`].
    Report,
    /// The run is over: the firmware answers with its [`LinkReport`] and stops (under QEMU it
    /// exits).
    Stop,
}

/// Which coefficient set the loop flies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Tables {
    /// The tables compiled into the firmware (`estimator_core::coeffs::BUILT_IN`).
    BuiltIn,
    /// A blob received over the link.
    Loaded,
}

/// Why a blob was refused (the firmware keeps flying the tables it had).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum BlobRejection {
    /// The announced length exceeds the firmware's blob buffer.
    TooLarge {
        /// Announced bytes.
        len: u32,
        /// The buffer's bytes.
        capacity: u32,
    },
    /// A chunk was not at the next offset, or no transfer was started.
    OutOfOrder {
        /// Offset expected.
        expected: u32,
        /// Offset received.
        found: u32,
    },
    /// Committed before every byte arrived.
    Incomplete {
        /// Bytes received.
        received: u32,
        /// Bytes announced.
        len: u32,
    },
    /// A set was loaded since boot and the estimator flies it: reset the board to load another.
    AlreadyLoaded,
    /// The blob's own checks failed (`estimator_core::blob::DecodeError`, by name).
    Blob(BlobFault),
}

/// The blob check that failed, as `estimator_core::blob::DecodeError` names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum BlobFault {
    /// Shorter than its header.
    TooShort,
    /// Not `RLCS`.
    BadMagic,
    /// Another container version.
    UnsupportedVersion,
    /// Written for another layout of the coefficient set.
    SchemaMismatch {
        /// This firmware's schema hash.
        expected: u32,
        /// The blob's.
        found: u32,
    },
    /// Reserved header bytes set.
    ReservedNonZero,
    /// Truncated or with trailing bytes.
    LengthMismatch,
    /// The payload's CRC differs from the header's.
    CrcMismatch {
        /// CRC in the header.
        expected: u32,
        /// CRC of the payload received.
        found: u32,
    },
    /// The payload is not a coefficient set.
    Decode,
    /// Bytes left after the coefficient set.
    TrailingPayload,
    /// A value is out of range.
    Invalid,
}

impl From<estimator_core::blob::DecodeError> for BlobFault {
    fn from(error: estimator_core::blob::DecodeError) -> Self {
        use estimator_core::blob::DecodeError as E;
        match error {
            E::TooShort { .. } => Self::TooShort,
            E::BadMagic { .. } => Self::BadMagic,
            E::UnsupportedVersion { .. } => Self::UnsupportedVersion,
            E::SchemaMismatch { expected, found } => Self::SchemaMismatch { expected, found },
            E::ReservedNonZero { .. } => Self::ReservedNonZero,
            E::LengthMismatch { .. } => Self::LengthMismatch,
            E::CrcMismatch { expected, found } => Self::CrcMismatch { expected, found },
            E::Decode(_) => Self::Decode,
            E::TrailingPayload { .. } => Self::TrailingPayload,
            E::Invalid(_) => Self::Invalid,
        }
    }
}

impl core::fmt::Display for BlobRejection {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::TooLarge { len, capacity } => write!(f, "blob of {len} bytes exceeds the firmware's {capacity}"),
            Self::OutOfOrder { expected, found } => write!(f, "chunk at offset {found}, expected {expected}"),
            Self::Incomplete { received, len } => write!(f, "committed after {received} of {len} bytes"),
            Self::AlreadyLoaded => f.write_str("a set is loaded already: reset the board to load another"),
            Self::Blob(BlobFault::SchemaMismatch { expected, found }) => {
                write!(f, "schema mismatch: the firmware reads {expected:#010x}, the blob is {found:#010x}")
            }
            Self::Blob(BlobFault::CrcMismatch { expected, found }) => {
                write!(f, "payload crc mismatch: header {expected:#010x}, payload {found:#010x}")
            }
            Self::Blob(fault) => write!(f, "blob check failed: {fault:?}"),
        }
    }
}

/// One step's outputs: everything the firmware's file replay records (`crate::frames`), with
/// the sample's sequence number and its latency.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// The sample's `seq`.
    pub seq: u32,
    /// [`estimator_core::Output::estimates`], in its order.
    pub estimates: [f32; 10],
    /// The estimator's health: `[flags, cp_missing, cp_rejected, cp_isolated]`.
    pub health: [u16; 4],
    /// The controller's `[port, starboard]` Cmu demand.
    pub demand_cmu: [f32; 2],
    /// The moment the demand asks of the jets.
    pub demand_moment: f32,
    /// Flags the controller set.
    pub controller_flags: u16,
    /// Core-clock ticks of `Estimator::step`.
    pub ticks_estimator: u32,
    /// Core-clock ticks of the estimator and the controller.
    pub ticks_total: u32,
    /// Core-clock ticks from the sample frame's arrival to the end of its step.
    pub latency_ticks: u32,
}

impl Estimate {
    /// The estimate of sample `seq` from its step's result, with its latency in core-clock ticks.
    #[must_use]
    pub const fn from_step(seq: u32, result: &crate::io::StepResult, latency_ticks: u32) -> Self {
        let health = result.output.health;
        Self {
            seq,
            estimates: result.output.estimates(),
            health: [health.flags, health.cp_missing, health.cp_rejected, health.cp_isolated],
            demand_cmu: result.demand.cmu,
            demand_moment: result.demand.moment,
            controller_flags: result.controller_health.flags,
            ticks_estimator: result.ticks_estimator,
            ticks_total: result.ticks_total,
            latency_ticks,
        }
    }
}

/// The loop's health over the run so far: what a rig must watch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct LinkReport {
    /// Ticks of the loop's timer.
    pub ticks: u32,
    /// Steps run (one per tick that had a sample).
    pub steps: u32,
    /// Ticks with no sample waiting (the link delivered none in time).
    pub idle_ticks: u32,
    /// Ticks that came before the previous step had finished.
    pub overruns: u32,
    /// Frames dropped: bad COBS, CRC, version or message, or longer than [`MAX_FRAME_LEN`].
    pub bad_frames: u32,
    /// Samples dropped because the queue to the loop was full.
    pub dropped_samples: u32,
    /// Estimates dropped because the queue to the link was full.
    pub dropped_estimates: u32,
    /// Largest `Estimator::step`, core-clock ticks, over the steps after the first
    /// [`WARM_UP_STEPS`].
    pub estimator_ticks_max: u32,
    /// Sum of the estimator's ticks over the steps after the warm-up.
    pub estimator_ticks_sum: u64,
    /// Largest estimator + controller step after the warm-up, ticks.
    pub total_ticks_max: u32,
    /// Sum of the estimator + controller ticks after the warm-up.
    pub total_ticks_sum: u64,
    /// Largest arrival-to-output latency, ticks.
    pub latency_ticks_max: u32,
    /// Sum of the latencies, ticks.
    pub latency_ticks_sum: u64,
    /// Core-clock ticks of a counted loop of [`LinkReport::calibration_instructions`]
    /// instructions (under QEMU's `-icount shift=0`, 0.168 ticks per instruction at 168 MHz).
    pub calibration_ticks: u32,
    /// Instructions of the calibration loop.
    pub calibration_instructions: u32,
    /// The core clock, Hz.
    pub core_clock_hz: u32,
    /// Stack bytes used so far, and available.
    pub stack: [u32; 2],
    /// Shortest and longest time between two ticks, core-clock ticks (the loop's jitter; the
    /// first tick has no predecessor and is left out).
    pub period_ticks: [u32; 2],
}

/// Steps left out of the step-time maxima: the first steps touch cold state (first-sample
/// initialisation paths), which a flight controller runs before arming.
pub const WARM_UP_STEPS: u32 = 100;

/// What the firmware sends.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum FromFirmware {
    /// At boot and after a blob is accepted: the protocol, the coefficient schema and the
    /// tables flown.
    Hello {
        /// [`PROTOCOL_VERSION`].
        protocol: u8,
        /// `estimator_core::blob::SCHEMA_HASH` of this build.
        schema_hash: u32,
        /// The tables the loop flies.
        tables: Tables,
        /// The loop's rate, Hz.
        rate_hz: u32,
    },
    /// One step.
    Estimate(Estimate),
    /// The answer to [`ToFirmware::BlobCommit`] (or to a chunk that cannot be taken).
    Blob(Result<Tables, BlobRejection>),
    /// The answer to [`ToFirmware::Report`] and [`ToFirmware::Stop`].
    Report(LinkReport),
}

/// Why a frame was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// Longer than [`MAX_FRAME_LEN`] without a delimiter.
    TooLong,
    /// Not valid COBS.
    Cobs,
    /// Shorter than the version and the CRC.
    TooShort,
    /// The CRC does not match.
    Crc,
    /// Another protocol version.
    Version(u8),
    /// The CRC matches but the bytes are not a message.
    Message,
    /// The output buffer is too small (encoding).
    BufferTooSmall,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooLong => write!(f, "frame longer than {MAX_FRAME_LEN} bytes"),
            Self::Cobs => f.write_str("not a COBS frame"),
            Self::TooShort => f.write_str("frame shorter than its version and CRC"),
            Self::Crc => f.write_str("CRC mismatch"),
            Self::Version(version) => write!(f, "protocol version {version}, expected {PROTOCOL_VERSION}"),
            Self::Message => f.write_str("not a message of this protocol"),
            Self::BufferTooSmall => f.write_str("output buffer too small"),
        }
    }
}

/// Encodes `message` as one frame, delimiter included, into `out`; returns its length.
///
/// # Errors
///
/// [`FrameError::BufferTooSmall`] when `out` (or [`MAX_FRAME_LEN`]) cannot hold it.
pub fn encode<T: Serialize>(message: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_FRAME_LEN];
    let body_len = {
        let (version, rest) = raw.split_first_mut().ok_or(FrameError::BufferTooSmall)?;
        *version = PROTOCOL_VERSION;
        let room = rest.len().saturating_sub(4);
        let body = postcard::to_slice(message, rest.get_mut(..room).ok_or(FrameError::BufferTooSmall)?)
            .map_err(|_| FrameError::BufferTooSmall)?;
        body.len()
    };
    let crc_at = 1 + body_len;
    let crc = FRAME_CRC.checksum(raw.get(..crc_at).ok_or(FrameError::BufferTooSmall)?);
    raw.get_mut(crc_at..crc_at + 4).ok_or(FrameError::BufferTooSmall)?.copy_from_slice(&crc.to_le_bytes());
    let raw = raw.get(..crc_at + 4).ok_or(FrameError::BufferTooSmall)?;
    let limit = out.len().min(MAX_FRAME_LEN);
    let encoded = cobs::try_encode(raw, out.get_mut(..limit.saturating_sub(1)).ok_or(FrameError::BufferTooSmall)?)
        .map_err(|_| FrameError::BufferTooSmall)?;
    *out.get_mut(encoded).ok_or(FrameError::BufferTooSmall)? = 0;
    Ok(encoded + 1)
}

/// Reassembles frames from a byte stream: feed every received byte to [`FrameDecoder::push`];
/// a delimiter completes a frame, which [`FrameDecoder::message`] then checks and decodes.
#[derive(Debug, Clone)]
pub struct FrameDecoder {
    buffer: heapless::Vec<u8, MAX_FRAME_LEN>,
    overflowed: bool,
    frame_len: Option<usize>,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// Empty, waiting for the first byte.
    #[must_use]
    pub const fn new() -> Self {
        Self { buffer: heapless::Vec::new(), overflowed: false, frame_len: None }
    }

    /// Takes one byte. Returns `Some(Ok(()))` when it completed a frame (read it with
    /// [`FrameDecoder::message`] before the next push), `Some(Err(_))` when it completed a
    /// frame that cannot be one (too long, bad COBS, CRC or version), `None` otherwise. Empty
    /// frames (two delimiters in a row, a line idle between frames) are ignored.
    pub fn push(&mut self, byte: u8) -> Option<Result<(), FrameError>> {
        if self.frame_len.take().is_some() {
            self.buffer.clear();
        }
        if byte != 0 {
            if self.buffer.push(byte).is_err() {
                self.overflowed = true;
            }
            return None;
        }
        if core::mem::take(&mut self.overflowed) {
            self.buffer.clear();
            return Some(Err(FrameError::TooLong));
        }
        if self.buffer.is_empty() {
            return None;
        }
        let checked = self.check();
        if checked.is_err() {
            self.buffer.clear();
        }
        Some(checked)
    }

    /// Un-stuffs the buffered frame in place and checks its length, CRC and version.
    fn check(&mut self) -> Result<(), FrameError> {
        let len = cobs::decode_in_place(&mut self.buffer).map_err(|_| FrameError::Cobs)?;
        let raw = self.buffer.get(..len).ok_or(FrameError::Cobs)?;
        if len < ENVELOPE_LEN + 1 {
            return Err(FrameError::TooShort);
        }
        let (body, crc) = raw.split_at(len - 4);
        let expected = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
        if FRAME_CRC.checksum(body) != expected {
            return Err(FrameError::Crc);
        }
        if body[0] != PROTOCOL_VERSION {
            return Err(FrameError::Version(body[0]));
        }
        self.frame_len = Some(len);
        Ok(())
    }

    /// The message of the frame the last [`FrameDecoder::push`] completed.
    ///
    /// # Errors
    ///
    /// [`FrameError::Message`] when no frame is complete or its bytes are not a `T`.
    pub fn message<'a, T: Deserialize<'a>>(&'a self) -> Result<T, FrameError> {
        let len = self.frame_len.ok_or(FrameError::Message)?;
        let body = self.buffer.get(1..len - 4).ok_or(FrameError::Message)?;
        match postcard::take_from_bytes::<T>(body) {
            Ok((message, [])) => Ok(message),
            _ => Err(FrameError::Message),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(seq: u32) -> ToFirmware<'static> {
        ToFirmware::Sample {
            seq,
            input: SampleInput {
                phi_deg: -12.5,
                alpha_deg: 20.0,
                cmu: [0.004, f32::NAN],
                cp: core::array::from_fn(|tap| -0.5 + 0.01 * tap as f32),
            },
        }
    }

    /// Feeds `bytes` and collects what each completed frame gave.
    fn feed(decoder: &mut FrameDecoder, bytes: &[u8]) -> Vec<Result<ToFirmware<'static>, FrameError>> {
        let mut out = Vec::new();
        for &byte in bytes {
            match decoder.push(byte) {
                Some(Ok(())) => out.push(decoder.message::<ToFirmware<'_>>().map(|m| m.clone_static())),
                Some(Err(error)) => out.push(Err(error)),
                None => {}
            }
        }
        out
    }

    impl ToFirmware<'_> {
        /// A copy that borrows nothing (tests only; chunks become `BlobStart`).
        fn clone_static(&self) -> ToFirmware<'static> {
            match *self {
                ToFirmware::Sample { seq, input } => ToFirmware::Sample { seq, input },
                ToFirmware::BlobStart { len } => ToFirmware::BlobStart { len },
                ToFirmware::BlobChunk { offset, .. } => ToFirmware::BlobStart { len: offset },
                ToFirmware::BlobCommit => ToFirmware::BlobCommit,
                ToFirmware::Report => ToFirmware::Report,
                ToFirmware::Stop => ToFirmware::Stop,
            }
        }
    }

    fn bits(message: &ToFirmware<'_>) -> Vec<u32> {
        match message {
            ToFirmware::Sample { seq, input } => {
                let mut out = vec![*seq, input.phi_deg.to_bits(), input.alpha_deg.to_bits()];
                out.extend(input.cmu.iter().chain(&input.cp).map(|v| v.to_bits()));
                out
            }
            _ => Vec::new(),
        }
    }

    #[test]
    fn a_frame_round_trips_bit_for_bit_with_no_zero_inside() {
        let mut out = [0u8; MAX_FRAME_LEN];
        let len = encode(&sample(7), &mut out).unwrap();
        assert_eq!(out[len - 1], 0);
        assert!(out[..len - 1].iter().all(|&b| b != 0), "COBS leaves no zero inside");
        let mut decoder = FrameDecoder::new();
        let got = feed(&mut decoder, &out[..len]);
        assert_eq!(got.len(), 1);
        assert_eq!(bits(got[0].as_ref().unwrap()), bits(&sample(7)), "NaN and every bit kept");
    }

    #[test]
    fn a_flipped_bit_is_a_bad_frame_and_the_next_frame_decodes() {
        let mut one = [0u8; MAX_FRAME_LEN];
        let len = encode(&sample(1), &mut one).unwrap();
        let mut two = [0u8; MAX_FRAME_LEN];
        let len2 = encode(&sample(2), &mut two).unwrap();
        for bit in [3usize, 77, 200, 8 * (len - 3) + 5] {
            let mut stream = one[..len].to_vec();
            stream[bit / 8 % (len - 1)] ^= 1 << (bit % 8);
            stream.extend_from_slice(&two[..len2]);
            let got = feed(&mut FrameDecoder::new(), &stream);
            assert!(got.len() >= 2, "bit {bit}: {got:?}");
            assert!(got[..got.len() - 1].iter().all(Result::is_err), "bit {bit}: {got:?}");
            assert_eq!(bits(got.last().unwrap().as_ref().unwrap()), bits(&sample(2)), "bit {bit}");
        }
    }

    #[test]
    fn an_overlong_run_without_delimiter_is_one_bad_frame() {
        let mut stream = vec![0x55u8; 3 * MAX_FRAME_LEN];
        stream.push(0);
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = encode(&ToFirmware::Stop, &mut frame).unwrap();
        stream.extend_from_slice(&frame[..len]);
        let got = feed(&mut FrameDecoder::new(), &stream);
        assert_eq!(got, vec![Err(FrameError::TooLong), Ok(ToFirmware::Stop)]);
    }

    #[test]
    fn another_version_is_refused() {
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = encode(&ToFirmware::Report, &mut frame).unwrap();
        let mut raw = [0u8; MAX_FRAME_LEN];
        let raw_len = cobs::decode(&frame[..len - 1], &mut raw).unwrap();
        raw[0] = PROTOCOL_VERSION + 1;
        let crc = FRAME_CRC.checksum(&raw[..raw_len - 4]);
        raw[raw_len - 4..raw_len].copy_from_slice(&crc.to_le_bytes());
        let mut stream = vec![0u8; MAX_FRAME_LEN];
        let n = cobs::encode(&raw[..raw_len], &mut stream);
        stream.truncate(n);
        stream.push(0);
        assert_eq!(feed(&mut FrameDecoder::new(), &stream), vec![Err(FrameError::Version(PROTOCOL_VERSION + 1))]);
    }

    #[test]
    fn a_blob_chunk_borrows_its_bytes_from_the_frame() {
        let bytes: Vec<u8> = (0..BLOB_CHUNK_LEN as u8).collect();
        let mut frame = [0u8; MAX_FRAME_LEN];
        let len = encode(&ToFirmware::BlobChunk { offset: 256, bytes: &bytes }, &mut frame).unwrap();
        let mut decoder = FrameDecoder::new();
        let mut done = false;
        for &byte in &frame[..len] {
            if decoder.push(byte) == Some(Ok(())) {
                let ToFirmware::BlobChunk { offset, bytes: got } = decoder.message().unwrap() else { panic!() };
                assert_eq!((offset, got), (256, &bytes[..]));
                done = true;
            }
        }
        assert!(done);
    }

    #[test]
    fn every_reply_fits_a_frame() {
        let estimate = Estimate {
            seq: u32::MAX,
            estimates: [f32::MAX; 10],
            health: [u16::MAX; 4],
            demand_cmu: [1.0; 2],
            demand_moment: 1.0,
            controller_flags: u16::MAX,
            ticks_estimator: u32::MAX,
            ticks_total: u32::MAX,
            latency_ticks: u32::MAX,
        };
        let report = LinkReport {
            estimator_ticks_sum: u64::MAX,
            total_ticks_sum: u64::MAX,
            latency_ticks_sum: u64::MAX,
            ticks: u32::MAX,
            ..LinkReport::default()
        };
        let rejection = BlobRejection::Blob(BlobFault::SchemaMismatch { expected: u32::MAX, found: u32::MAX });
        let mut frame = [0u8; MAX_FRAME_LEN];
        for message in [
            FromFirmware::Estimate(estimate),
            FromFirmware::Report(report),
            FromFirmware::Blob(Err(rejection)),
            FromFirmware::Hello { protocol: 1, schema_hash: u32::MAX, tables: Tables::Loaded, rate_hz: 1000 },
        ] {
            let len = encode(&message, &mut frame).unwrap();
            let mut decoder = FrameDecoder::new();
            let mut got = None;
            for &byte in &frame[..len] {
                if decoder.push(byte) == Some(Ok(())) {
                    got = Some(decoder.message::<FromFirmware>().unwrap());
                }
            }
            assert_eq!(got.as_ref(), Some(&message));
        }
    }
}
