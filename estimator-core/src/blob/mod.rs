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
//! own variant. Each operation has its own error type: [`EncodeError`] (the buffer),
//! [`DecodeError`] (the bytes) and [`InvalidSet`] (the values). Nothing here allocates or
//! panics.

mod decode;
mod encode;
#[cfg(test)]
mod tests;
mod validate;

pub use decode::{DecodeError, decode};
pub use encode::{EncodeError, encode};
pub use validate::{ENVELOPE_LIMIT, InvalidSet, validate};

use crate::coeffs::{
    CoefficientSet, MAX_DEGREE, MAX_TERMS, MAX_VARS, N_ALPHA, N_PRESSURE_INPUTS, N_TAPS, PRESSURE_RANK,
};

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
pub const SCHEMA: &str = "rlcs coefficient set; schema_version=8; \
    N_TAPS=12; PRESSURE_RANK=10; N_PRESSURE_INPUTS=5; N_ALPHA=8; MAX_TERMS=16; MAX_VARS=7; MAX_DEGREE=3; \
    N_PLANT_VARS=5; N_COUPLING_VARS=7; DEMAND_SLOTS=64; \
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
pub(super) const PAYLOAD_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

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

/// The fixed header of a blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Header {
    pub(super) magic: [u8; 4],
    pub(super) version: u16,
    pub(super) schema_hash: u32,
    pub(super) payload_len: u32,
    pub(super) crc: u32,
    pub(super) reserved: u16,
}

impl Header {
    /// The header this build writes for a payload.
    pub(super) fn for_payload(payload: &[u8]) -> Result<Self, EncodeError> {
        let payload_len = u32::try_from(payload.len()).map_err(|_| EncodeError::Encode)?;
        Ok(Self {
            magic: MAGIC,
            version: BLOB_FORMAT_VERSION,
            schema_hash: SCHEMA_HASH,
            payload_len,
            crc: PAYLOAD_CRC.checksum(payload),
            reserved: 0,
        })
    }

    pub(super) fn to_bytes(self) -> [u8; HEADER_LEN] {
        let [m0, m1, m2, m3] = self.magic;
        let [v0, v1] = self.version.to_le_bytes();
        let [h0, h1, h2, h3] = self.schema_hash.to_le_bytes();
        let [l0, l1, l2, l3] = self.payload_len.to_le_bytes();
        let [c0, c1, c2, c3] = self.crc.to_le_bytes();
        let [r0, r1] = self.reserved.to_le_bytes();
        [m0, m1, m2, m3, v0, v1, h0, h1, h2, h3, l0, l1, l2, l3, c0, c1, c2, c3, r0, r1]
    }

    pub(super) fn from_bytes(bytes: &[u8; HEADER_LEN]) -> Self {
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
