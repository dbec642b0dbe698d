//! Content hashes: the seal of a blind campaign's truth and the provenance line of the
//! generated tables both name their bytes by SHA-256 (FIPS 180-4), so one definition serves both.

use sha2::{Digest, Sha256};

/// Hex SHA-256 of `bytes`, lower case.
#[must_use]
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The FIPS 180-2 test vectors of SHA-256: the seal of the truth must be the standard hash.
    #[test]
    fn sha256_matches_the_standard_test_vectors() {
        assert_eq!(sha256_hex(b""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }
}
