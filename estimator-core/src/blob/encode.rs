//! Writing a blob: the header, then the set's `postcard` payload, into a caller's buffer.

use core::fmt;

use super::{HEADER_LEN, Header, encoded_len};
use crate::coeffs::CoefficientSet;

/// Why a blob could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The output buffer cannot hold the blob.
    BufferTooSmall {
        /// Bytes the blob needs.
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// `postcard` failed to serialize the set for a reason other than a full buffer.
    Encode,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooSmall { needed, available } => {
                write!(f, "output buffer too small: {available} bytes, the blob needs {needed}")
            }
            Self::Encode => f.write_str("coefficient set does not serialize"),
        }
    }
}

impl core::error::Error for EncodeError {}

/// Writes the blob of `set` (header, then payload) to the start of `out` and returns its length.
///
/// The set is written as it is, without [`validate`](super::validate): check it first if the blob must load.
///
/// # Errors
///
/// [`EncodeError::BufferTooSmall`] when `out` cannot hold the blob (a buffer of
/// [`MAX_BLOB_LEN`](super::MAX_BLOB_LEN) bytes always can); [`EncodeError::Encode`] if `postcard` fails otherwise.
pub fn encode(set: &CoefficientSet, out: &mut [u8]) -> Result<usize, EncodeError> {
    let available = out.len();
    let too_small = || EncodeError::BufferTooSmall { needed: encoded_len(set), available };
    let Some((header, rest)) = out.split_first_chunk_mut::<HEADER_LEN>() else {
        return Err(too_small());
    };
    let payload = match postcard::to_slice(set, rest) {
        Ok(payload) => payload,
        Err(postcard::Error::SerializeBufferFull) => return Err(too_small()),
        Err(_) => return Err(EncodeError::Encode),
    };
    *header = Header::for_payload(payload)?.to_bytes();
    HEADER_LEN.checked_add(payload.len()).ok_or(EncodeError::Encode)
}
