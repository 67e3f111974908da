//! Where bytes live (DESIGN §8): content-addressed blobs behind one trait,
//! apart from the metadata in [`crate::store`]. A blob's name is the
//! lower-case hex sha256 of its bytes; `put` verifies that before the blob
//! becomes visible, so a reader never sees a blob that does not match its
//! name.
//!
//! [`LocalBlobs`] keeps them on local disk. The trait takes and returns
//! whole byte buffers and a byte range, which is also what an
//! S3-compatible backend (the `object_store` crate: conditional put,
//! ranged get) offers, so one drops in beside it.

mod local;

pub use local::LocalBlobs;

/// A failed blob operation.
#[derive(Debug, thiserror::Error)]
pub enum BlobError {
    /// The bytes do not hash to the name they were put under.
    #[error("the bytes hash to {actual}, not {expected}")]
    DigestMismatch {
        /// The name given.
        expected: String,
        /// What the bytes hash to.
        actual: String,
    },
    /// Not a lower-case hex sha256.
    #[error("{0:?} is not a sha256 digest")]
    BadDigest(String),
    /// The backend failed.
    #[error("blob store: {0}")]
    Io(#[from] std::io::Error),
}

/// Checks that `digest` is 64 lower-case hex digits (so it is safe as a
/// file or object name).
pub fn check_digest(digest: &str) -> Result<(), BlobError> {
    let ok = digest.len() == 64
        && digest
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b));
    if ok {
        Ok(())
    } else {
        Err(BlobError::BadDigest(digest.chars().take(80).collect()))
    }
}

/// Content-addressed bytes.
#[async_trait::async_trait]
pub trait Blobs: Send + Sync + std::fmt::Debug + 'static {
    /// Stores `bytes` under `digest` after checking that they hash to it;
    /// storing the same blob twice is a no-op.
    async fn put(&self, digest: &str, bytes: &[u8]) -> Result<(), BlobError>;
    /// The whole blob, or `None`.
    async fn get(&self, digest: &str) -> Result<Option<Vec<u8>>, BlobError>;
    /// Bytes `start..end` of the blob (clamped to its length).
    async fn get_range(
        &self,
        digest: &str,
        start: u64,
        end: u64,
    ) -> Result<Option<Vec<u8>>, BlobError>;
    /// The blob's length, or `None`.
    async fn len(&self, digest: &str) -> Result<Option<u64>, BlobError>;
}
