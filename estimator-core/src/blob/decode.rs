//! Reading a blob: the header field by field, the CRC, the `postcard` payload (every byte of
//! it) and the values ([`validate`]).

use core::fmt;

use super::validate::{InvalidSet, validate};
use super::{BLOB_FORMAT_VERSION, HEADER_LEN, Header, MAGIC, PAYLOAD_CRC, SCHEMA_HASH};
use crate::coeffs::CoefficientSet;

/// Why a blob could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
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
    /// The set decodes but a value is out of range.
    Invalid(InvalidSet),
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
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
            Self::Invalid(invalid) => invalid.fmt(f),
        }
    }
}

impl core::error::Error for DecodeError {}

/// Reads a blob: checks the header, the payload length and CRC, decodes the payload and
/// [`validate`]s the set.
///
/// # Errors
///
/// The first failed check, in the order of the [`DecodeError`] variants from
/// [`DecodeError::TooShort`] to [`DecodeError::Invalid`].
pub fn decode(bytes: &[u8]) -> Result<CoefficientSet, DecodeError> {
    let Some((header, payload)) = bytes.split_first_chunk::<HEADER_LEN>() else {
        return Err(DecodeError::TooShort { len: bytes.len() });
    };
    let header = Header::from_bytes(header);
    if header.magic != MAGIC {
        return Err(DecodeError::BadMagic { found: header.magic });
    }
    if header.version != BLOB_FORMAT_VERSION {
        return Err(DecodeError::UnsupportedVersion { found: header.version });
    }
    if header.schema_hash != SCHEMA_HASH {
        return Err(DecodeError::SchemaMismatch { expected: SCHEMA_HASH, found: header.schema_hash });
    }
    if header.reserved != 0 {
        return Err(DecodeError::ReservedNonZero { found: header.reserved });
    }
    if usize::try_from(header.payload_len).ok() != Some(payload.len()) {
        return Err(DecodeError::LengthMismatch { declared: header.payload_len, actual: payload.len() });
    }
    let crc = PAYLOAD_CRC.checksum(payload);
    if crc != header.crc {
        return Err(DecodeError::CrcMismatch { expected: header.crc, found: crc });
    }
    let (set, unused) = postcard::take_from_bytes::<CoefficientSet>(payload)
        .map_err(|error| DecodeError::Decode(postcard_reason(&error)))?;
    if !unused.is_empty() {
        return Err(DecodeError::TrailingPayload { unused: unused.len() });
    }
    validate(&set).map_err(DecodeError::Invalid)?;
    Ok(set)
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
