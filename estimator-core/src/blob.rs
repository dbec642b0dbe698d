//! The coefficient blob: a [`CoefficientSet`] as a fixed 20-byte header followed by its
//! `postcard` serialization, so a fitted set can be loaded at run time instead of compiled in.
//!
//! Header layout (all integers little-endian):
//!
//! | bytes    | content                                                          |
//! |----------|------------------------------------------------------------------|
//! | `0..4`   | magic [`MAGIC`] = `b"RLCS"`                                      |
//! | `4..6`   | format version, u16 ([`BLOB_FORMAT_VERSION`])                    |
//! | `6..10`  | schema hash, u32 ([`SCHEMA_HASH`], FNV-1a of [`SCHEMA`])         |
//! | `10..14` | payload length in bytes, u32                                     |
//! | `14..18` | CRC-32 (ISO-HDLC, the zlib/PNG CRC) of the payload, u32          |
//! | `18..20` | reserved, zero                                                   |
//! | `20..`   | payload: `postcard` serialization of the [`CoefficientSet`]      |
//!
//! [`decode`] checks the header field by field, the CRC, the postcard decoding (which must use
//! every payload byte) and finally the meaning of the values ([`validate`]); each failure has its
//! own [`BlobError`] variant. Nothing here allocates or panics.

use core::fmt;

use crate::coeffs::{
    ActuatorResponse, CoefficientSet, ControllerParams, DEMAND_SLOTS, EgkParams, Envelope, FusionParams, MAX_DEGREE,
    MAX_TERMS, MAX_VARS, N_ALPHA, N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK, PlantParams, PressureModel, RateFilter,
    SCHEMA_VERSION,
};
use crate::sparse::{Monomial, SparseModel, Term};

/// First four bytes of every blob.
pub const MAGIC: [u8; 4] = *b"RLCS";

/// Version of the blob container (the header and the payload encoding). The layout of the
/// coefficient set itself is covered by [`SCHEMA_HASH`].
pub const BLOB_FORMAT_VERSION: u16 = 1;

/// Length of the fixed header, bytes.
pub const HEADER_LEN: usize = 20;

/// Description of the payload layout: the schema version, every size constant and the field
/// order and types of [`CoefficientSet`] and its nested structs.
///
/// Written by hand (const string formatting does not exist); a unit test checks that the
/// numbers in it are the current values of the constants. Update it with any change of a field
/// or size: its hash, [`SCHEMA_HASH`], is what makes an old blob fail to load.
pub const SCHEMA: &str = "rlcs coefficient set; schema_version=7; \
    N_TAPS=12; PRESSURE_RANK=10; N_PRESSURE_INPUTS=5; N_ALPHA=8; MAX_TERMS=16; MAX_VARS=6; MAX_DEGREE=3; \
    N_PLANT_VARS=5; N_COUPLING_VARS=6; DEMAND_SLOTS=64; \
    CoefficientSet{schema_version:u16,dt_s:f32,rate_filter:RateFilter,alpha_schedule_deg:[f32;N_ALPHA],\
    n_alpha:u8,egk:[EgkParams;N_ALPHA],pressure:PressureModel,fusion:FusionParams,plant:[PlantParams;2],\
    coupling:SparseModel,controller:ControllerParams,actuator:[ActuatorResponse;2],envelope:Envelope}; \
    RateFilter{rate_pole:f32,accel_pole:f32}; \
    EgkParams{tau1_s:f32,tau2_s:f32,breakdown_deg:f32,steepness_per_deg:f32,sideslip_gain:f32,\
    clbeta_per_rad:f32,clp:f32,clpdot:f32,clpp:f32,vortex_gain:f32,bias:f32,half_span_time_s:f32}; \
    PressureModel{rank:u8,a:[[f32;PRESSURE_RANK];PRESSURE_RANK],b:[[f32;N_PRESSURE_INPUTS];PRESSURE_RANK],\
    c:[[f32;PRESSURE_RANK];N_TAPS],cp_mean:[f32;N_TAPS],gain:[[f32;N_TAPS];PRESSURE_RANK],\
    innovation_std:[f32;N_TAPS],gate_sigma:f32,isolate_after:u16,settle_steps:u16,cl_weights:[[f32;N_TAPS];N_ALPHA],cl_offset:[f32;N_ALPHA]}; \
    FusionParams{rho:f32,gain:f32}; \
    PlantParams{slow_pole:f32,cmu_max:f32,model:SparseModel}; \
    SparseModel{terms:[Term;MAX_TERMS],n_terms:u8,gate_threshold:[f32;MAX_VARS]}; \
    Term{coeff:f32,monomial:Monomial}; \
    Monomial{factors:[u8;MAX_DEGREE],gate_mask:u8}; \
    ControllerParams{causality_pole:f32,feedback_kp:f32,feedback_ki:f32,cmu_max:f32,inversion_iterations:u8}; \
    ActuatorResponse{delay_steps:u8,pole:f32,gain:f32}; \
    Envelope{cl_roll:[f32;2],cl:[f32;2]}";

/// FNV-1a (32-bit) hash of [`SCHEMA`], computed at compile time.
pub const SCHEMA_HASH: u32 = fnv1a_32(SCHEMA.as_bytes());

/// CRC-32/ISO-HDLC (the zlib, PNG and Ethernet CRC) of the payload.
const PAYLOAD_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// f32 fields of one [`EgkParams`].
const F32_PER_EGK: usize = 12;
/// f32 fields of one [`SparseModel`]: the term coefficients and the gate thresholds.
const F32_PER_SPARSE: usize = MAX_TERMS + MAX_VARS;
/// u8 fields of one [`SparseModel`]: each term's factors and gate mask, and `n_terms`.
const U8_PER_SPARSE: usize = MAX_TERMS * (MAX_DEGREE + 1) + 1;
/// f32 fields of the [`PressureModel`]: `a`, `b`, `c`, `cp_mean`, `gain`, `innovation_std`,
/// `gate_sigma`, `cl_weights`, `cl_offset`.
const F32_PER_PRESSURE: usize = PRESSURE_RANK * PRESSURE_RANK
    + PRESSURE_RANK * N_PRESSURE_INPUTS
    + N_TAPS * PRESSURE_RANK
    + N_TAPS
    + PRESSURE_RANK * N_TAPS
    + N_TAPS
    + 1
    + N_ALPHA * N_TAPS
    + N_ALPHA;
/// Every f32 of a [`CoefficientSet`]: `dt_s`, the rate filter, the alpha schedule, the eGK
/// parameters, the pressure model, the fusion, the two plant models (slow pole, Cmu range
/// and sparse model) and the coupling, the controller, the two actuator responses (pole and
/// gain) and the envelope.
const N_F32: usize =
    1 + 2 + N_ALPHA + N_ALPHA * F32_PER_EGK + F32_PER_PRESSURE + 2 + 2 * 2 + 3 * F32_PER_SPARSE + 4 + 2 * 2 + 4;
/// Every u8 of a [`CoefficientSet`]: `n_alpha`, `pressure.rank`, the three sparse models,
/// `controller.inversion_iterations` and the two actuator responses' `delay_steps`.
const N_U8: usize = 1 + 1 + 3 * U8_PER_SPARSE + 1 + 2;
/// Every u16 of a [`CoefficientSet`]: `schema_version`, `pressure.isolate_after` and
/// `pressure.settle_steps`.
const N_U16: usize = 3;

/// Largest payload, bytes: postcard writes an f32 as 4 bytes, a u8 as 1 byte and a u16 as a
/// varint of at most 3 bytes; fixed-size arrays and structs add nothing. A unit test encodes a
/// worst-case set and checks that it is exactly this long.
pub const MAX_PAYLOAD_LEN: usize = 4 * N_F32 + N_U8 + 3 * N_U16;

/// Largest blob, bytes (header and payload): a buffer of this size always fits [`encode`].
pub const MAX_BLOB_LEN: usize = HEADER_LEN + MAX_PAYLOAD_LEN;

/// Why a blob could not be written or read, or a coefficient set is not usable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BlobError {
    /// The output buffer cannot hold the blob.
    BufferTooSmall {
        /// Bytes the blob needs.
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// `postcard` failed to serialize the set for a reason other than a full buffer.
    Encode,
    /// Fewer bytes than a header.
    TooShort {
        /// Bytes given.
        len: usize,
    },
    /// The first four bytes are not [`MAGIC`].
    BadMagic {
        /// The first four bytes found.
        found: [u8; 4],
    },
    /// The format version is not [`BLOB_FORMAT_VERSION`].
    UnsupportedVersion {
        /// The version in the header.
        found: u16,
    },
    /// The blob was written for another layout of the coefficient set.
    SchemaMismatch {
        /// This build's [`SCHEMA_HASH`].
        expected: u32,
        /// The hash in the header.
        found: u32,
    },
    /// The reserved header bytes are not zero.
    ReservedNonZero {
        /// Their value, little-endian.
        found: u16,
    },
    /// The declared payload length differs from the bytes after the header (truncated blob or
    /// trailing garbage).
    LengthMismatch {
        /// Payload length in the header.
        declared: u32,
        /// Bytes after the header.
        actual: usize,
    },
    /// The payload's CRC-32 differs from the header's.
    CrcMismatch {
        /// CRC in the header.
        expected: u32,
        /// CRC of the payload as received.
        found: u32,
    },
    /// The payload is not a postcard-encoded coefficient set.
    Decode(&'static str),
    /// The payload decodes but leaves bytes unused.
    TrailingPayload {
        /// Bytes left after the coefficient set.
        unused: usize,
    },
    /// The set decodes but a value is out of range; the text names the field.
    Invalid(&'static str),
}

impl fmt::Display for BlobError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooSmall { needed, available } => {
                write!(f, "output buffer too small: {available} bytes, the blob needs {needed}")
            }
            Self::Encode => f.write_str("coefficient set does not serialize"),
            Self::TooShort { len } => write!(f, "blob too short: {len} bytes, a header needs {HEADER_LEN}"),
            Self::BadMagic { found } => write!(f, "wrong magic: found {found:02x?}, expected {MAGIC:02x?} (\"RLCS\")"),
            Self::UnsupportedVersion { found } => {
                write!(f, "unsupported blob format version {found}, this build reads version {BLOB_FORMAT_VERSION}")
            }
            Self::SchemaMismatch { expected, found } => {
                write!(
                    f,
                    "coefficient schema mismatch: expected hash {expected:#010x}, found {found:#010x} (the blob was written for another layout of the coefficient set: refit it with this build's `host-tools fit`)"
                )
            }
            Self::ReservedNonZero { found } => write!(f, "reserved header bytes are not zero: {found:#06x}"),
            Self::LengthMismatch { declared, actual } => {
                write!(f, "payload length mismatch: the header declares {declared} bytes, {actual} follow")
            }
            Self::CrcMismatch { expected, found } => {
                write!(f, "payload crc mismatch: the header says {expected:#010x}, the payload has {found:#010x}")
            }
            Self::Decode(reason) => write!(f, "payload does not decode: {reason}"),
            Self::TrailingPayload { unused } => write!(f, "payload has {unused} unused trailing bytes"),
            Self::Invalid(what) => write!(f, "invalid coefficient set: {what}"),
        }
    }
}

impl core::error::Error for BlobError {}

/// The fixed header of a blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Header {
    magic: [u8; 4],
    version: u16,
    schema_hash: u32,
    payload_len: u32,
    crc: u32,
    reserved: u16,
}

impl Header {
    /// The header this build writes for a payload.
    fn for_payload(payload: &[u8]) -> Result<Self, BlobError> {
        let payload_len = u32::try_from(payload.len()).map_err(|_| BlobError::Encode)?;
        Ok(Self {
            magic: MAGIC,
            version: BLOB_FORMAT_VERSION,
            schema_hash: SCHEMA_HASH,
            payload_len,
            crc: PAYLOAD_CRC.checksum(payload),
            reserved: 0,
        })
    }

    fn to_bytes(self) -> [u8; HEADER_LEN] {
        let [m0, m1, m2, m3] = self.magic;
        let [v0, v1] = self.version.to_le_bytes();
        let [h0, h1, h2, h3] = self.schema_hash.to_le_bytes();
        let [l0, l1, l2, l3] = self.payload_len.to_le_bytes();
        let [c0, c1, c2, c3] = self.crc.to_le_bytes();
        let [r0, r1] = self.reserved.to_le_bytes();
        [m0, m1, m2, m3, v0, v1, h0, h1, h2, h3, l0, l1, l2, l3, c0, c1, c2, c3, r0, r1]
    }

    fn from_bytes(bytes: &[u8; HEADER_LEN]) -> Self {
        let [m0, m1, m2, m3, v0, v1, h0, h1, h2, h3, l0, l1, l2, l3, c0, c1, c2, c3, r0, r1] = *bytes;
        Self {
            magic: [m0, m1, m2, m3],
            version: u16::from_le_bytes([v0, v1]),
            schema_hash: u32::from_le_bytes([h0, h1, h2, h3]),
            payload_len: u32::from_le_bytes([l0, l1, l2, l3]),
            crc: u32::from_le_bytes([c0, c1, c2, c3]),
            reserved: u16::from_le_bytes([r0, r1]),
        }
    }
}

/// Length of the blob of `set` (header and payload), bytes; at most [`MAX_BLOB_LEN`].
#[must_use]
pub fn encoded_len(set: &CoefficientSet) -> usize {
    postcard::serialize_with_flavor(set, postcard::ser_flavors::Size::default())
        .ok()
        .and_then(|payload_len| payload_len.checked_add(HEADER_LEN))
        .unwrap_or(MAX_BLOB_LEN)
}

/// Writes the blob of `set` (header, then payload) to the start of `out` and returns its length.
///
/// The set is written as it is, without [`validate`]: check it first if the blob must load.
///
/// # Errors
///
/// [`BlobError::BufferTooSmall`] when `out` cannot hold the blob (a buffer of
/// [`MAX_BLOB_LEN`] bytes always can); [`BlobError::Encode`] if `postcard` fails otherwise.
pub fn encode(set: &CoefficientSet, out: &mut [u8]) -> Result<usize, BlobError> {
    let available = out.len();
    let too_small = || BlobError::BufferTooSmall { needed: encoded_len(set), available };
    let Some((header, rest)) = out.split_first_chunk_mut::<HEADER_LEN>() else {
        return Err(too_small());
    };
    let payload = match postcard::to_slice(set, rest) {
        Ok(payload) => payload,
        Err(postcard::Error::SerializeBufferFull) => return Err(too_small()),
        Err(_) => return Err(BlobError::Encode),
    };
    *header = Header::for_payload(payload)?.to_bytes();
    HEADER_LEN.checked_add(payload.len()).ok_or(BlobError::Encode)
}

/// Reads a blob: checks the header, the payload length and CRC, decodes the payload and
/// [`validate`]s the set.
///
/// # Errors
///
/// The first failed check, in the order of the [`BlobError`] variants from
/// [`BlobError::TooShort`] to [`BlobError::Invalid`].
pub fn decode(bytes: &[u8]) -> Result<CoefficientSet, BlobError> {
    let Some((header, payload)) = bytes.split_first_chunk::<HEADER_LEN>() else {
        return Err(BlobError::TooShort { len: bytes.len() });
    };
    let header = Header::from_bytes(header);
    if header.magic != MAGIC {
        return Err(BlobError::BadMagic { found: header.magic });
    }
    if header.version != BLOB_FORMAT_VERSION {
        return Err(BlobError::UnsupportedVersion { found: header.version });
    }
    if header.schema_hash != SCHEMA_HASH {
        return Err(BlobError::SchemaMismatch { expected: SCHEMA_HASH, found: header.schema_hash });
    }
    if header.reserved != 0 {
        return Err(BlobError::ReservedNonZero { found: header.reserved });
    }
    if usize::try_from(header.payload_len).ok() != Some(payload.len()) {
        return Err(BlobError::LengthMismatch { declared: header.payload_len, actual: payload.len() });
    }
    let crc = PAYLOAD_CRC.checksum(payload);
    if crc != header.crc {
        return Err(BlobError::CrcMismatch { expected: header.crc, found: crc });
    }
    let (set, unused) = postcard::take_from_bytes::<CoefficientSet>(payload)
        .map_err(|error| BlobError::Decode(postcard_reason(&error)))?;
    if !unused.is_empty() {
        return Err(BlobError::TrailingPayload { unused: unused.len() });
    }
    validate(&set)?;
    Ok(set)
}

/// Checks that a coefficient set is usable by the estimator.
///
/// The set must have this build's `schema_version`; every f32 in it (used or not, including the
/// sparse coefficients and thresholds) must be finite; `dt_s > 0`; `1 <= n_alpha <= N_ALPHA`
/// with the used breakpoints strictly ascending; the used eGK entries need `tau1_s > 0` and
/// `tau2_s >= 0`; `pressure.rank <= PRESSURE_RANK`, `pressure.gate_sigma > 0` and the
/// constants the pressure filter derives from its tables are finite; every sparse model has
/// `n_terms <= MAX_TERMS`; `controller.cmu_max > 0`; each actuator response has
/// `delay_steps < DEMAND_SLOTS`, `pole` in `[0, 1)` and `gain` in `(0, 10]`; each range of the
/// envelope is ordered (`low <= high`) within `[-ENVELOPE_LIMIT, ENVELOPE_LIMIT]`.
///
/// # Errors
///
/// [`BlobError::Invalid`] naming the first offending field.
pub fn validate(set: &CoefficientSet) -> Result<(), BlobError> {
    ensure(set.schema_version == SCHEMA_VERSION, "schema_version differs from this build's SCHEMA_VERSION")?;
    check_all_finite(set)?;
    ensure(set.dt_s > 0.0, "dt_s must be > 0")?;

    let n_alpha = usize::from(set.n_alpha);
    ensure((1..=N_ALPHA).contains(&n_alpha), "n_alpha must be in 1..=N_ALPHA")?;
    let used_alpha = set.alpha_schedule_deg.get(..n_alpha).unwrap_or(&[]);
    ensure(
        used_alpha.windows(2).all(|pair| matches!(pair, [lower, upper] if lower < upper)),
        "alpha_schedule_deg must be strictly ascending over the n_alpha used breakpoints",
    )?;
    for params in set.egk.iter().take(n_alpha) {
        ensure(params.tau1_s > 0.0, "egk.tau1_s must be > 0")?;
        ensure(params.tau2_s >= 0.0, "egk.tau2_s must be >= 0")?;
    }

    ensure(usize::from(set.pressure.rank) <= PRESSURE_RANK, "pressure.rank must be <= PRESSURE_RANK")?;
    ensure(modes_beyond_rank_are_zero(&set.pressure), "pressure modes beyond rank must be zero")?;
    ensure(set.pressure.gate_sigma > 0.0, "pressure.gate_sigma must be > 0")?;
    // Finite tables can still overflow in the constants the filter derives from them (found by
    // `cargo xtask fuzz --target blob`: a weight of 1e30 times a mode shape of 1e23).
    ensure(
        crate::pressure::PressureFilter::new(&set.pressure).derived_constants_are_finite(),
        "pressure tables overflow: the roll-moment map, its constant or a gate is not finite",
    )?;

    let [port, starboard] = &set.plant;
    ensure((0.0..1.0).contains(&port.slow_pole), "plant[0].slow_pole must be in [0, 1)")?;
    ensure((0.0..1.0).contains(&starboard.slow_pole), "plant[1].slow_pole must be in [0, 1)")?;
    ensure(port.cmu_max > 0.0, "plant[0].cmu_max must be > 0")?;
    ensure(starboard.cmu_max > 0.0, "plant[1].cmu_max must be > 0")?;
    let [port, starboard] = [&port.model, &starboard.model];
    ensure(usize::from(port.n_terms) <= MAX_TERMS, "plant[0].n_terms must be <= MAX_TERMS")?;
    ensure(usize::from(starboard.n_terms) <= MAX_TERMS, "plant[1].n_terms must be <= MAX_TERMS")?;
    ensure(usize::from(set.coupling.n_terms) <= MAX_TERMS, "coupling.n_terms must be <= MAX_TERMS")?;
    ensure(factors_in_table(port), "plant[0] factors must be variables or ONE_FACTOR, ascending")?;
    ensure(factors_in_table(starboard), "plant[1] factors must be variables or ONE_FACTOR, ascending")?;
    ensure(factors_in_table(&set.coupling), "coupling factors must be variables or ONE_FACTOR, ascending")?;

    ensure(set.controller.cmu_max > 0.0, "controller.cmu_max must be > 0")?;

    for (response, delay_what, pole_what, gain_what) in [
        (
            &set.actuator[0],
            "actuator[0].delay_steps must be < DEMAND_SLOTS",
            "actuator[0].pole must be in [0, 1)",
            "actuator[0].gain must be in (0, 10]",
        ),
        (
            &set.actuator[1],
            "actuator[1].delay_steps must be < DEMAND_SLOTS",
            "actuator[1].pole must be in [0, 1)",
            "actuator[1].gain must be in (0, 10]",
        ),
    ] {
        ensure(usize::from(response.delay_steps) < DEMAND_SLOTS, delay_what)?;
        ensure((0.0..1.0).contains(&response.pole), pole_what)?;
        ensure(response.gain > 0.0 && response.gain <= ACTUATOR_GAIN_LIMIT, gain_what)?;
    }
    ensure(envelope_range_ok(set.envelope.cl_roll), "envelope.cl_roll must be ordered within +-ENVELOPE_LIMIT")?;
    ensure(envelope_range_ok(set.envelope.cl), "envelope.cl must be ordered within +-ENVELOPE_LIMIT")
}

/// Largest actuator gain accepted: a jet that blows ten times its demand is a broken fit, not a
/// valve.
const ACTUATOR_GAIN_LIMIT: f32 = 10.0;

/// Largest |bound| of an envelope range: a roll moment coefficient of 1 is a hundred times the
/// authority of a trailing-edge jet and about 17 times the largest moment of the paper's wing
/// (0.06), and keeps the margin's arithmetic far from overflow.
pub const ENVELOPE_LIMIT: f32 = 1.0;

/// An envelope range `[low, high]` is ordered and within [`ENVELOPE_LIMIT`].
fn envelope_range_ok(range: [f32; 2]) -> bool {
    let [low, high] = range;
    -ENVELOPE_LIMIT <= low && low <= high && high <= ENVELOPE_LIMIT
}

/// The estimator runs its pressure loops over the full size, so modes past `rank` must be zero
/// rows and columns of `A`, `B`, `C` and `K`.
fn modes_beyond_rank_are_zero(model: &PressureModel) -> bool {
    let rank = usize::from(model.rank);
    let unused = |row: &[f32]| row.get(rank..).unwrap_or(&[]).iter().all(|&value| value == 0.0);
    model.a.iter().all(|row| unused(row))
        && model.a.iter().skip(rank).all(|row| row.iter().all(|&value| value == 0.0))
        && model.b.iter().skip(rank).all(|row| row.iter().all(|&value| value == 0.0))
        && model.c.iter().all(|row| unused(row))
        && model.gain.iter().skip(rank).all(|row| row.iter().all(|&value| value == 0.0))
}

/// Every factor of every term (used or not) is a variable or the padding
/// [`crate::sparse::ONE_FACTOR`], in the canonical ascending order: the estimator's factor
/// table has no other entries, and equal monomials must compare equal.
fn factors_in_table(model: &SparseModel) -> bool {
    model.terms.iter().all(|term| term.monomial.is_canonical(MAX_VARS))
}

/// `Ok` when `ok`, else [`BlobError::Invalid`] with `what`.
fn ensure(ok: bool, what: &'static str) -> Result<(), BlobError> {
    if ok { Ok(()) } else { Err(BlobError::Invalid(what)) }
}

/// [`BlobError::Invalid`] with `what` unless every value is finite.
fn all_finite(values: &[f32], what: &'static str) -> Result<(), BlobError> {
    ensure(values.iter().all(|value| value.is_finite()), what)
}

/// Walks every f32 of the set. The destructuring is exhaustive on purpose: a new field does not
/// compile until it is checked here (and described in [`SCHEMA`]).
fn check_all_finite(set: &CoefficientSet) -> Result<(), BlobError> {
    let CoefficientSet {
        schema_version: _,
        dt_s,
        rate_filter,
        alpha_schedule_deg,
        n_alpha: _,
        egk,
        pressure,
        fusion,
        plant,
        coupling,
        controller,
        actuator,
        envelope,
    } = set;
    all_finite(&[*dt_s], "dt_s is not finite")?;

    let RateFilter { rate_pole, accel_pole } = rate_filter;
    all_finite(&[*rate_pole], "rate_filter.rate_pole is not finite")?;
    all_finite(&[*accel_pole], "rate_filter.accel_pole is not finite")?;

    all_finite(alpha_schedule_deg, "alpha_schedule_deg is not finite")?;

    for params in egk {
        let EgkParams {
            tau1_s,
            tau2_s,
            breakdown_deg,
            steepness_per_deg,
            sideslip_gain,
            clbeta_per_rad,
            clp,
            clpdot,
            clpp,
            vortex_gain,
            bias,
            half_span_time_s,
        } = params;
        all_finite(&[*tau1_s], "egk.tau1_s is not finite")?;
        all_finite(&[*tau2_s], "egk.tau2_s is not finite")?;
        all_finite(&[*breakdown_deg], "egk.breakdown_deg is not finite")?;
        all_finite(&[*steepness_per_deg], "egk.steepness_per_deg is not finite")?;
        all_finite(&[*sideslip_gain], "egk.sideslip_gain is not finite")?;
        all_finite(&[*clbeta_per_rad], "egk.clbeta_per_rad is not finite")?;
        all_finite(&[*clp], "egk.clp is not finite")?;
        all_finite(&[*clpdot], "egk.clpdot is not finite")?;
        all_finite(&[*clpp], "egk.clpp is not finite")?;
        all_finite(&[*vortex_gain], "egk.vortex_gain is not finite")?;
        all_finite(&[*bias], "egk.bias is not finite")?;
        all_finite(&[*half_span_time_s], "egk.half_span_time_s is not finite")?;
    }

    let PressureModel {
        rank: _,
        a,
        b,
        c,
        cp_mean,
        gain,
        innovation_std,
        gate_sigma,
        isolate_after: _,
        settle_steps: _,
        cl_weights,
        cl_offset,
    } = pressure;
    all_finite(a.as_flattened(), "pressure.a is not finite")?;
    all_finite(b.as_flattened(), "pressure.b is not finite")?;
    all_finite(c.as_flattened(), "pressure.c is not finite")?;
    all_finite(cp_mean, "pressure.cp_mean is not finite")?;
    all_finite(gain.as_flattened(), "pressure.gain is not finite")?;
    all_finite(innovation_std, "pressure.innovation_std is not finite")?;
    all_finite(&[*gate_sigma], "pressure.gate_sigma is not finite")?;
    all_finite(cl_weights.as_flattened(), "pressure.cl_weights is not finite")?;
    all_finite(cl_offset, "pressure.cl_offset is not finite")?;

    let FusionParams { rho, gain } = fusion;
    all_finite(&[*rho], "fusion.rho is not finite")?;
    all_finite(&[*gain], "fusion.gain is not finite")?;

    let [port, starboard] = plant;
    let PlantParams { slow_pole: port_pole, cmu_max: port_cmu_max, model: port } = port;
    let PlantParams { slow_pole: starboard_pole, cmu_max: starboard_cmu_max, model: starboard } = starboard;
    all_finite(&[*port_pole], "plant[0].slow_pole is not finite")?;
    all_finite(&[*starboard_pole], "plant[1].slow_pole is not finite")?;
    all_finite(&[*port_cmu_max], "plant[0].cmu_max is not finite")?;
    all_finite(&[*starboard_cmu_max], "plant[1].cmu_max is not finite")?;
    sparse_finite(port, "plant[0].terms.coeff is not finite", "plant[0].gate_threshold is not finite")?;
    sparse_finite(starboard, "plant[1].terms.coeff is not finite", "plant[1].gate_threshold is not finite")?;
    sparse_finite(coupling, "coupling.terms.coeff is not finite", "coupling.gate_threshold is not finite")?;

    let ControllerParams { causality_pole, feedback_kp, feedback_ki, cmu_max, inversion_iterations: _ } = controller;
    all_finite(&[*causality_pole], "controller.causality_pole is not finite")?;
    all_finite(&[*feedback_kp], "controller.feedback_kp is not finite")?;
    all_finite(&[*feedback_ki], "controller.feedback_ki is not finite")?;
    all_finite(&[*cmu_max], "controller.cmu_max is not finite")?;

    for response in actuator {
        let ActuatorResponse { delay_steps: _, pole, gain } = response;
        all_finite(&[*pole], "actuator.pole is not finite")?;
        all_finite(&[*gain], "actuator.gain is not finite")?;
    }
    let Envelope { cl_roll, cl } = envelope;
    all_finite(cl_roll, "envelope.cl_roll is not finite")?;
    all_finite(cl, "envelope.cl is not finite")
}

/// Every f32 of a sparse model: all term coefficients (used or not) and the gate thresholds.
fn sparse_finite(model: &SparseModel, coeff_what: &'static str, threshold_what: &'static str) -> Result<(), BlobError> {
    let SparseModel { terms, n_terms: _, gate_threshold } = model;
    for term in terms {
        let Term { coeff, monomial } = term;
        let Monomial { factors: _, gate_mask: _ } = monomial;
        all_finite(&[*coeff], coeff_what)?;
    }
    all_finite(gate_threshold, threshold_what)
}

/// A short, static description of a postcard decoding error.
fn postcard_reason(error: &postcard::Error) -> &'static str {
    match error {
        postcard::Error::DeserializeUnexpectedEnd => "unexpected end of payload",
        postcard::Error::DeserializeBadVarint => "bad varint",
        postcard::Error::DeserializeBadBool => "bad bool",
        postcard::Error::DeserializeBadChar => "bad char",
        postcard::Error::DeserializeBadUtf8 => "bad utf-8",
        postcard::Error::DeserializeBadOption => "bad option tag",
        postcard::Error::DeserializeBadEnum => "bad enum tag",
        postcard::Error::DeserializeBadEncoding => "bad encoding",
        postcard::Error::SerdeDeCustom => "serde error",
        _ => "postcard error",
    }
}

/// FNV-1a, 32-bit (offset basis 0x811c9dc5, prime 0x01000193).
const fn fnv1a_32(bytes: &[u8]) -> u32 {
    let mut hash: u32 = 0x811c_9dc5;
    let mut rest = bytes;
    while let [byte, tail @ ..] = rest {
        hash ^= *byte as u32;
        hash = hash.wrapping_mul(0x0100_0193);
        rest = tail;
    }
    hash
}

#[cfg(test)]
mod tests {
    use core::array;

    use proptest::prelude::*;

    use super::*;
    use crate::coeffs::{N_COUPLING_VARS, N_PLANT_VARS};
    use crate::sparse::{Factor, ONE_FACTOR};

    /// Distinct, non-zero, exactly representable f32 values in ascending order.
    struct Seq {
        count: u16,
    }

    impl Seq {
        fn next(&mut self) -> f32 {
            self.count += 1;
            0.125 + f32::from(self.count) * 0.0625
        }

        fn arr<const N: usize>(&mut self) -> [f32; N] {
            array::from_fn(|_| self.next())
        }

        fn mat<const R: usize, const C: usize>(&mut self) -> [[f32; C]; R] {
            array::from_fn(|_| self.arr())
        }

        fn sparse(&mut self, n_terms: u8) -> SparseModel {
            let terms = array::from_fn(|term_idx| Term {
                coeff: if term_idx % 2 == 0 { self.next() } else { -self.next() },
                monomial: Monomial {
                    factors: [
                        Factor::var(term_idx % 3).unwrap_or(ONE_FACTOR),
                        Factor::var(term_idx % 3 + term_idx % 4).unwrap_or(ONE_FACTOR),
                        ONE_FACTOR,
                    ],
                    gate_mask: (term_idx % 64) as u8,
                },
            });
            SparseModel { terms, n_terms, gate_threshold: self.arr() }
        }

        fn egk(&mut self) -> EgkParams {
            EgkParams {
                tau1_s: self.next(),
                tau2_s: self.next(),
                breakdown_deg: self.next(),
                steepness_per_deg: self.next(),
                sideslip_gain: self.next(),
                clbeta_per_rad: -self.next(),
                clp: -self.next(),
                clpdot: -self.next(),
                clpp: -self.next(),
                vortex_gain: self.next(),
                bias: -self.next(),
                half_span_time_s: self.next(),
            }
        }
    }

    /// A valid set with every field set to a distinct non-zero value.
    fn valid_set() -> CoefficientSet {
        let mut seq = Seq { count: 0 };
        CoefficientSet {
            schema_version: SCHEMA_VERSION,
            dt_s: 0.001,
            rate_filter: RateFilter { rate_pole: seq.next(), accel_pole: seq.next() },
            alpha_schedule_deg: seq.arr(),
            n_alpha: 3,
            egk: array::from_fn(|_| seq.egk()),
            pressure: PressureModel {
                rank: PRESSURE_RANK as u8,
                a: seq.mat(),
                b: seq.mat(),
                c: seq.mat(),
                cp_mean: seq.arr().map(|value: f32| -value),
                gain: seq.mat(),
                innovation_std: seq.arr(),
                gate_sigma: seq.next(),
                isolate_after: 300,
                settle_steps: 150,
                cl_weights: seq.mat(),
                cl_offset: seq.arr(),
            },
            fusion: FusionParams { rho: seq.next(), gain: seq.next() },
            plant: [
                PlantParams { slow_pole: 0.9, cmu_max: 0.009, model: seq.sparse(5) },
                PlantParams { slow_pole: 0.95, cmu_max: 0.012, model: seq.sparse(5) },
            ],
            coupling: seq.sparse(7),
            controller: ControllerParams {
                causality_pole: 0.95,
                feedback_kp: seq.next(),
                feedback_ki: seq.next(),
                cmu_max: seq.next(),
                inversion_iterations: 24,
            },
            actuator: [
                ActuatorResponse { delay_steps: 5, pole: 0.7, gain: 0.98 },
                ActuatorResponse { delay_steps: 6, pole: 0.75, gain: 1.02 },
            ],
            envelope: Envelope { cl_roll: [-0.05, 0.0625], cl: [-0.0625, 0.075] },
        }
    }

    /// A set whose every field has its largest value (largest encoding, not valid).
    fn large_set() -> CoefficientSet {
        let big = f32::MAX;
        let sparse = SparseModel {
            terms: [Term { coeff: big, monomial: Monomial { factors: [ONE_FACTOR; MAX_DEGREE], gate_mask: u8::MAX } };
                MAX_TERMS],
            n_terms: u8::MAX,
            gate_threshold: [big; MAX_VARS],
        };
        let egk = EgkParams {
            tau1_s: big,
            tau2_s: big,
            breakdown_deg: big,
            steepness_per_deg: big,
            sideslip_gain: big,
            clbeta_per_rad: big,
            clp: big,
            clpdot: big,
            clpp: big,
            vortex_gain: big,
            bias: big,
            half_span_time_s: big,
        };
        CoefficientSet {
            schema_version: u16::MAX,
            dt_s: big,
            rate_filter: RateFilter { rate_pole: big, accel_pole: big },
            alpha_schedule_deg: [big; N_ALPHA],
            n_alpha: u8::MAX,
            egk: [egk; N_ALPHA],
            pressure: PressureModel {
                rank: u8::MAX,
                a: [[big; PRESSURE_RANK]; PRESSURE_RANK],
                b: [[big; N_PRESSURE_INPUTS]; PRESSURE_RANK],
                c: [[big; PRESSURE_RANK]; N_TAPS],
                cp_mean: [big; N_TAPS],
                gain: [[big; N_TAPS]; PRESSURE_RANK],
                innovation_std: [big; N_TAPS],
                gate_sigma: big,
                isolate_after: u16::MAX,
                settle_steps: u16::MAX,
                cl_weights: [[big; N_TAPS]; N_ALPHA],
                cl_offset: [big; N_ALPHA],
            },
            fusion: FusionParams { rho: big, gain: big },
            plant: [PlantParams { slow_pole: big, cmu_max: big, model: sparse }; 2],
            coupling: sparse,
            controller: ControllerParams {
                causality_pole: big,
                feedback_kp: big,
                feedback_ki: big,
                cmu_max: big,
                inversion_iterations: u8::MAX,
            },
            actuator: [ActuatorResponse { delay_steps: u8::MAX, pole: big, gain: big }; 2],
            envelope: Envelope { cl_roll: [big; 2], cl: [big; 2] },
        }
    }

    fn encode_vec(set: &CoefficientSet) -> Vec<u8> {
        let mut buf = vec![0u8; MAX_BLOB_LEN];
        let len = encode(set, &mut buf).expect("encode into MAX_BLOB_LEN");
        buf.truncate(len);
        buf
    }

    /// A blob with a correct header around an arbitrary payload.
    fn seal(payload: &[u8]) -> Vec<u8> {
        let mut blob = Header::for_payload(payload).expect("payload length fits u32").to_bytes().to_vec();
        blob.extend_from_slice(payload);
        blob
    }

    fn valid_blob() -> Vec<u8> {
        encode_vec(&valid_set())
    }

    #[test]
    fn blob_schema_mentions_current_constants() {
        for (name, value) in [
            ("schema_version", usize::from(SCHEMA_VERSION)),
            ("N_TAPS", N_TAPS),
            ("PRESSURE_RANK", PRESSURE_RANK),
            ("N_PRESSURE_INPUTS", N_PRESSURE_INPUTS),
            ("N_ALPHA", N_ALPHA),
            ("MAX_TERMS", MAX_TERMS),
            ("MAX_VARS", MAX_VARS),
            ("N_PLANT_VARS", N_PLANT_VARS),
            ("N_COUPLING_VARS", N_COUPLING_VARS),
            ("DEMAND_SLOTS", DEMAND_SLOTS),
        ] {
            let entry = format!("; {name}={value};");
            assert!(SCHEMA.contains(&entry), "SCHEMA lacks `{entry}`: update it (and the layout) for the new size");
        }
    }

    #[test]
    fn blob_schema_hash_is_fnv1a_of_schema() {
        // Reference vectors of FNV-1a 32.
        assert_eq!(fnv1a_32(b""), 0x811c_9dc5);
        assert_eq!(fnv1a_32(b"a"), 0xe40c_292c);
        assert_eq!(fnv1a_32(b"foobar"), 0xbf9c_f968);
        assert_eq!(SCHEMA_HASH, fnv1a_32(SCHEMA.as_bytes()));
        // The check value of CRC-32/ISO-HDLC.
        assert_eq!(PAYLOAD_CRC.checksum(b"123456789"), 0xcbf4_3926);
    }

    /// The payload written field by field in the order of [`SCHEMA`]: catches a reordering of
    /// fields in coeffs.rs (which the schema hash alone would not see).
    #[test]
    fn blob_payload_follows_schema_field_order() {
        struct Writer(Vec<u8>);
        impl Writer {
            fn f32s(&mut self, values: &[f32]) {
                for value in values {
                    self.0.extend_from_slice(&value.to_le_bytes());
                }
            }
            fn u8(&mut self, value: u8) {
                self.0.push(value);
            }
            fn u16(&mut self, mut value: u16) {
                while value >= 0x80 {
                    self.0.push((value & 0x7f) as u8 | 0x80);
                    value >>= 7;
                }
                self.0.push(value as u8);
            }
            fn sparse(&mut self, model: &SparseModel) {
                for term in &model.terms {
                    self.f32s(&[term.coeff]);
                    // A factor is written as the one byte of its index, as the `u8` it was.
                    for factor in term.monomial.factors {
                        self.u8(factor.index() as u8);
                    }
                    self.u8(term.monomial.gate_mask);
                }
                self.u8(model.n_terms);
                self.f32s(&model.gate_threshold);
            }
        }
        let set = valid_set();
        let mut w = Writer(Vec::new());
        w.u16(set.schema_version);
        w.f32s(&[set.dt_s, set.rate_filter.rate_pole, set.rate_filter.accel_pole]);
        w.f32s(&set.alpha_schedule_deg);
        w.u8(set.n_alpha);
        for e in &set.egk {
            w.f32s(&[
                e.tau1_s,
                e.tau2_s,
                e.breakdown_deg,
                e.steepness_per_deg,
                e.sideslip_gain,
                e.clbeta_per_rad,
                e.clp,
                e.clpdot,
                e.clpp,
                e.vortex_gain,
                e.bias,
                e.half_span_time_s,
            ]);
        }
        let p = &set.pressure;
        w.u8(p.rank);
        w.f32s(p.a.as_flattened());
        w.f32s(p.b.as_flattened());
        w.f32s(p.c.as_flattened());
        w.f32s(&p.cp_mean);
        w.f32s(p.gain.as_flattened());
        w.f32s(&p.innovation_std);
        w.f32s(&[p.gate_sigma]);
        w.u16(p.isolate_after);
        w.u16(p.settle_steps);
        w.f32s(p.cl_weights.as_flattened());
        w.f32s(&p.cl_offset);
        w.f32s(&[set.fusion.rho, set.fusion.gain]);
        w.f32s(&[set.plant[0].slow_pole, set.plant[0].cmu_max]);
        w.sparse(&set.plant[0].model);
        w.f32s(&[set.plant[1].slow_pole, set.plant[1].cmu_max]);
        w.sparse(&set.plant[1].model);
        w.sparse(&set.coupling);
        let c = &set.controller;
        w.f32s(&[c.causality_pole, c.feedback_kp, c.feedback_ki, c.cmu_max]);
        w.u8(c.inversion_iterations);
        for response in &set.actuator {
            w.u8(response.delay_steps);
            w.f32s(&[response.pole, response.gain]);
        }
        w.f32s(&set.envelope.cl_roll);
        w.f32s(&set.envelope.cl);

        let blob = valid_blob();
        assert_eq!(&blob[HEADER_LEN..], w.0.as_slice());
    }

    /// A factor is one byte, its index; a byte that names no factor does not decode.
    #[test]
    fn blob_factor_is_its_index_byte() {
        let mut buffer = [0u8; 4];
        for var_idx in 0..=MAX_VARS {
            let factor = Factor::var(var_idx).unwrap_or(ONE_FACTOR);
            assert_eq!(postcard::to_slice(&factor, &mut buffer).map(|bytes| bytes.to_vec()), Ok(vec![var_idx as u8]));
            assert_eq!(postcard::from_bytes::<Factor>(&[var_idx as u8]), Ok(factor));
        }
        assert!(postcard::from_bytes::<Factor>(&[MAX_VARS as u8 + 1]).is_err());
        assert!(postcard::from_bytes::<Factor>(&[u8::MAX]).is_err());
    }

    #[test]
    fn blob_round_trip() {
        let set = valid_set();
        assert_eq!(validate(&set), Ok(()));
        let blob = valid_blob();
        assert_eq!(blob.len(), encoded_len(&set));
        println!("encoded test set: {} bytes (MAX_BLOB_LEN = {MAX_BLOB_LEN})", blob.len());
        assert_eq!(&blob[0..4], b"RLCS");
        assert_eq!(u16::from_le_bytes([blob[4], blob[5]]), BLOB_FORMAT_VERSION);
        assert_eq!(u32::from_le_bytes(blob[6..10].try_into().unwrap()), SCHEMA_HASH);
        assert_eq!(u32::from_le_bytes(blob[10..14].try_into().unwrap()) as usize, blob.len() - HEADER_LEN);
        assert_eq!(u32::from_le_bytes(blob[14..18].try_into().unwrap()), PAYLOAD_CRC.checksum(&blob[HEADER_LEN..]));
        assert_eq!(&blob[18..20], &[0, 0]);
        assert_eq!(decode(&blob), Ok(set));
    }

    #[test]
    fn blob_max_len_bounds_the_largest_set() {
        let set = large_set();
        let mut buf = vec![0u8; MAX_BLOB_LEN];
        let len = encode(&set, &mut buf).expect("the largest set fits MAX_BLOB_LEN");
        println!("largest set: {len} bytes, MAX_BLOB_LEN = {MAX_BLOB_LEN}");
        // The bound is exact: a larger encoding means a field was added without updating it.
        assert_eq!(len, MAX_BLOB_LEN);
        assert_eq!(encoded_len(&set), MAX_BLOB_LEN);
    }

    #[test]
    fn blob_encode_reports_small_buffers() {
        let set = valid_set();
        let needed = encoded_len(&set);
        for available in [0, 10, HEADER_LEN - 1, HEADER_LEN, HEADER_LEN + 1, needed - 1] {
            let mut buf = vec![0u8; available];
            assert_eq!(encode(&set, &mut buf), Err(BlobError::BufferTooSmall { needed, available }), "{available}");
        }
        let mut buf = vec![0u8; needed];
        assert_eq!(encode(&set, &mut buf), Ok(needed));
    }

    #[test]
    fn blob_rejects_short_input() {
        let blob = valid_blob();
        assert_eq!(decode(&[]), Err(BlobError::TooShort { len: 0 }));
        assert_eq!(decode(&blob[..HEADER_LEN - 1]), Err(BlobError::TooShort { len: HEADER_LEN - 1 }));
        let payload_len = (blob.len() - HEADER_LEN) as u32;
        assert_eq!(decode(&blob[..HEADER_LEN]), Err(BlobError::LengthMismatch { declared: payload_len, actual: 0 }));
    }

    #[test]
    fn blob_rejects_truncation_and_trailing_bytes() {
        let blob = valid_blob();
        let payload_len = blob.len() - HEADER_LEN;
        assert_eq!(
            decode(&blob[..blob.len() - 1]),
            Err(BlobError::LengthMismatch { declared: payload_len as u32, actual: payload_len - 1 })
        );
        let mut longer = blob.clone();
        longer.push(0);
        assert_eq!(
            decode(&longer),
            Err(BlobError::LengthMismatch { declared: payload_len as u32, actual: payload_len + 1 })
        );
    }

    #[test]
    fn blob_rejects_bad_header_fields() {
        let blob = valid_blob();

        let mut bad = blob.clone();
        bad[0] = b'X';
        assert_eq!(decode(&bad), Err(BlobError::BadMagic { found: *b"XLCS" }));

        let mut bad = blob.clone();
        bad[4..6].copy_from_slice(&2u16.to_le_bytes());
        assert_eq!(decode(&bad), Err(BlobError::UnsupportedVersion { found: 2 }));

        let mut bad = blob.clone();
        bad[6..10].copy_from_slice(&0xdead_beef_u32.to_le_bytes());
        assert_eq!(decode(&bad), Err(BlobError::SchemaMismatch { expected: SCHEMA_HASH, found: 0xdead_beef }));

        let mut bad = blob.clone();
        bad[19] = 1;
        assert_eq!(decode(&bad), Err(BlobError::ReservedNonZero { found: 0x0100 }));
    }

    #[test]
    fn blob_rejects_crc_mismatch() {
        let mut bad = valid_blob();
        let stored = u32::from_le_bytes(bad[14..18].try_into().unwrap());
        bad[HEADER_LEN + 100] ^= 0x01;
        let found = PAYLOAD_CRC.checksum(&bad[HEADER_LEN..]);
        assert_ne!(stored, found);
        assert_eq!(decode(&bad), Err(BlobError::CrcMismatch { expected: stored, found }));
    }

    #[test]
    fn blob_rejects_undecodable_and_overlong_payloads() {
        let blob = valid_blob();
        let payload = &blob[HEADER_LEN..];
        assert_eq!(decode(&seal(&payload[..payload.len() - 4])), Err(BlobError::Decode("unexpected end of payload")));
        assert_eq!(decode(&seal(&[])), Err(BlobError::Decode("unexpected end of payload")));
        // schema_version as a varint that never terminates within a u16.
        assert_eq!(decode(&seal(&[0xff, 0xff, 0xff, 0xff])), Err(BlobError::Decode("bad varint")));
        let mut longer = payload.to_vec();
        longer.extend_from_slice(&[1, 2, 3]);
        assert_eq!(decode(&seal(&longer)), Err(BlobError::TrailingPayload { unused: 3 }));
    }

    #[test]
    fn blob_rejects_invalid_set_after_decoding() {
        let mut set = valid_set();
        set.pressure.gain[3][7] = f32::NAN;
        let blob = encode_vec(&set);
        assert_eq!(decode(&blob), Err(BlobError::Invalid("pressure.gain is not finite")));
    }

    /// Issue 8 (reliability; the fuzzer of `cargo xtask fuzz --target blob` found it): finite
    /// pressure tables whose product overflows passed validation, and the step then returned a
    /// NaN `cl_pressure`.
    #[test]
    fn issue_8_pressure_tables_that_overflow_are_rejected_and_never_reach_the_output() {
        let mut set = crate::coeffs::DEFAULT;
        set.pressure.cl_weights[0][1] = 1e30;
        set.pressure.c[1][0] = 1e23;
        assert!(
            matches!(validate(&set), Err(BlobError::Invalid(what)) if what.starts_with("pressure tables overflow"))
        );
        let mut estimator = crate::Estimator::new(&set);
        let input = crate::Input { phi_deg: 5.0, alpha_deg: 10.0, cmu_port: 0.0, cmu_stbd: 0.0, cp: [-0.4; N_TAPS] };
        for _ in 0..10 {
            assert!(estimator.step(&input).estimates().iter().all(|value| value.is_finite()));
        }
    }

    #[test]
    fn blob_every_single_bit_flip_is_rejected() {
        let blob = valid_blob();
        let mut flipped = blob.clone();
        for byte_idx in 0..blob.len() {
            for bit in 0..8 {
                flipped[byte_idx] ^= 1 << bit;
                let result = decode(&flipped);
                let expected_kind = match byte_idx {
                    0..4 => matches!(result, Err(BlobError::BadMagic { .. })),
                    4..6 => matches!(result, Err(BlobError::UnsupportedVersion { .. })),
                    6..10 => matches!(result, Err(BlobError::SchemaMismatch { .. })),
                    10..14 => matches!(result, Err(BlobError::LengthMismatch { .. })),
                    18..20 => matches!(result, Err(BlobError::ReservedNonZero { .. })),
                    _ => matches!(result, Err(BlobError::CrcMismatch { .. })),
                };
                assert!(expected_kind, "flip of byte {byte_idx} bit {bit} gave {result:?}");
                flipped[byte_idx] ^= 1 << bit;
            }
        }
        assert_eq!(flipped, blob);
    }

    #[test]
    fn blob_validate_rejects_bad_values() {
        type Corruption = (fn(&mut CoefficientSet), &'static str);
        let cases: [Corruption; 33] = [
            (|s| s.schema_version = SCHEMA_VERSION + 1, "schema_version differs from this build's SCHEMA_VERSION"),
            (|s| s.pressure.gain[9][11] = f32::NAN, "pressure.gain is not finite"),
            (|s| s.pressure.a[0][0] = f32::INFINITY, "pressure.a is not finite"),
            (|s| s.egk[3].bias = f32::NEG_INFINITY, "egk.bias is not finite"),
            (|s| s.plant[1].model.terms[15].coeff = f32::NAN, "plant[1].terms.coeff is not finite"),
            (|s| s.coupling.gate_threshold[5] = f32::INFINITY, "coupling.gate_threshold is not finite"),
            (|s| s.controller.feedback_ki = f32::NAN, "controller.feedback_ki is not finite"),
            (|s| s.dt_s = 0.0, "dt_s must be > 0"),
            (|s| s.dt_s = -0.001, "dt_s must be > 0"),
            (|s| s.n_alpha = 0, "n_alpha must be in 1..=N_ALPHA"),
            (|s| s.n_alpha = N_ALPHA as u8 + 1, "n_alpha must be in 1..=N_ALPHA"),
            (
                |s| s.alpha_schedule_deg[2] = s.alpha_schedule_deg[1],
                "alpha_schedule_deg must be strictly ascending over the n_alpha used breakpoints",
            ),
            (
                |s| s.alpha_schedule_deg.swap(0, 1),
                "alpha_schedule_deg must be strictly ascending over the n_alpha used breakpoints",
            ),
            (|s| s.egk[2].tau1_s = 0.0, "egk.tau1_s must be > 0"),
            (|s| s.egk[0].tau2_s = -0.01, "egk.tau2_s must be >= 0"),
            (|s| s.pressure.rank = PRESSURE_RANK as u8 + 1, "pressure.rank must be <= PRESSURE_RANK"),
            (|s| s.pressure.gate_sigma = 0.0, "pressure.gate_sigma must be > 0"),
            (|s| s.plant[0].model.n_terms = MAX_TERMS as u8 + 1, "plant[0].n_terms must be <= MAX_TERMS"),
            (|s| s.coupling.n_terms = u8::MAX, "coupling.n_terms must be <= MAX_TERMS"),
            (|s| s.controller.cmu_max = 0.0, "controller.cmu_max must be > 0"),
            (|s| s.pressure.rank = 4, "pressure modes beyond rank must be zero"),
            (
                |s| s.coupling.terms[15].monomial.factors = [ONE_FACTOR, Factor::Var0, ONE_FACTOR],
                "coupling factors must be variables or ONE_FACTOR, ascending",
            ),
            (
                |s| s.plant[1].model.terms[0].monomial.factors = [Factor::Var2, Factor::Var1, ONE_FACTOR],
                "plant[1] factors must be variables or ONE_FACTOR, ascending",
            ),
            (|s| s.actuator[0].pole = f32::NAN, "actuator.pole is not finite"),
            (|s| s.actuator[1].gain = f32::INFINITY, "actuator.gain is not finite"),
            (|s| s.actuator[0].delay_steps = DEMAND_SLOTS as u8, "actuator[0].delay_steps must be < DEMAND_SLOTS"),
            (|s| s.actuator[1].pole = 1.0, "actuator[1].pole must be in [0, 1)"),
            (|s| s.actuator[0].pole = -0.1, "actuator[0].pole must be in [0, 1)"),
            (|s| s.actuator[1].gain = 0.0, "actuator[1].gain must be in (0, 10]"),
            (|s| s.actuator[0].gain = 10.5, "actuator[0].gain must be in (0, 10]"),
            (|s| s.envelope.cl[1] = f32::NAN, "envelope.cl is not finite"),
            (|s| s.envelope.cl_roll = [0.01, -0.01], "envelope.cl_roll must be ordered within +-ENVELOPE_LIMIT"),
            (|s| s.envelope.cl = [-2.0, 0.1], "envelope.cl must be ordered within +-ENVELOPE_LIMIT"),
        ];
        for (corrupt, what) in cases {
            let mut set = valid_set();
            corrupt(&mut set);
            assert_eq!(validate(&set), Err(BlobError::Invalid(what)));
        }
    }

    #[test]
    fn blob_validate_accepts_edge_values() {
        // Unused breakpoints and eGK entries may be anything finite; tau2 = 0 and rank = 0 are fine.
        let mut set = valid_set();
        set.alpha_schedule_deg[3] = -90.0;
        set.egk[3].tau1_s = 0.0;
        set.egk[0].tau2_s = 0.0;
        set.pressure = PressureModel { rank: 0, ..crate::prior::PRIOR.pressure };
        set.plant[0].model.n_terms = MAX_TERMS as u8;
        assert_eq!(validate(&set), Ok(()));
        set.n_alpha = 1;
        set.alpha_schedule_deg[1] = -90.0;
        assert_eq!(validate(&set), Ok(()));
        // The longest dead time, no lag, the largest gain, a range of one value, the limits.
        set.actuator[0] = ActuatorResponse { delay_steps: (DEMAND_SLOTS - 1) as u8, pole: 0.0, gain: 10.0 };
        set.envelope = Envelope { cl_roll: [0.02, 0.02], cl: [-ENVELOPE_LIMIT, ENVELOPE_LIMIT] };
        assert_eq!(validate(&set), Ok(()));
    }

    #[test]
    fn blob_error_messages() {
        assert_eq!(BlobError::TooShort { len: 12 }.to_string(), "blob too short: 12 bytes, a header needs 20");
        let all = [
            BlobError::BufferTooSmall { needed: 2000, available: 10 },
            BlobError::Encode,
            BlobError::TooShort { len: 3 },
            BlobError::BadMagic { found: *b"XLCS" },
            BlobError::UnsupportedVersion { found: 2 },
            BlobError::SchemaMismatch { expected: SCHEMA_HASH, found: 0 },
            BlobError::ReservedNonZero { found: 1 },
            BlobError::LengthMismatch { declared: 10, actual: 9 },
            BlobError::CrcMismatch { expected: 1, found: 2 },
            BlobError::Decode("bad varint"),
            BlobError::TrailingPayload { unused: 3 },
            BlobError::Invalid("dt_s must be > 0"),
        ];
        for error in all {
            let message = error.to_string();
            assert!(message.starts_with(|c: char| c.is_ascii_lowercase()), "{message}");
            assert!(!message.ends_with('.'), "{message}");
            let _: &dyn core::error::Error = &error;
        }
    }

    proptest! {
        #[test]
        fn blob_decode_never_panics_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = decode(&bytes);
        }

        #[test]
        fn blob_decode_never_panics_on_sealed_arbitrary_payloads(
            payload in proptest::collection::vec(any::<u8>(), 0..(MAX_PAYLOAD_LEN + 8)),
        ) {
            let _ = decode(&seal(&payload));
        }

        #[test]
        fn blob_decode_of_resealed_mutations_is_valid_or_err(
            edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        ) {
            let blob = valid_blob();
            let mut payload = blob[HEADER_LEN..].to_vec();
            for (index, value) in edits {
                let idx = index.index(payload.len());
                payload[idx] = value;
            }
            if let Ok(set) = decode(&seal(&payload)) {
                prop_assert_eq!(validate(&set), Ok(()));
            }
        }
    }
}
