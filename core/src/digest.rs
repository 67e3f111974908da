//! Content digests: sha256 as lower-case hex, the form in which uploads,
//! bake keys and assets are named (DESIGN §1).

use sha2::{Digest as _, Sha256};

/// sha256 of bytes, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// Lower-case hex of a finished digest.
pub fn hex(digest: &[u8]) -> String {
    digest.iter().map(|b| format!("{b:02x}")).collect()
}
