//! Where bytes live (DESIGN §8): content-addressed blobs behind one trait,
//! apart from the metadata in [`crate::store`]. A blob's name is the
//! lower-case hex sha256 of its bytes; `put` verifies that before the blob
//! becomes visible, so a reader never sees a blob that does not match its
//! name.
//!
//! [`LocalBlobs`] keeps them on local disk, [`ObjectBlobs`] in an
//! S3-compatible object store (chosen with `aobake serve --blobs URL`,
//! [`open`]). The same suite ([`suite`]) runs on both.

mod local;
mod object;
#[cfg(test)]
mod suite;

pub use local::LocalBlobs;
pub use object::{MULTIPART_BYTES, ObjectBlobs, redacted};

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
    /// The object store failed.
    #[error("blob store: {0}")]
    Store(#[from] object_store::Error),
    /// The blob store's settings cannot be used.
    #[error("{0}")]
    Config(String),
    /// The bucket is not there (deleted, or an S3 server started again
    /// without its data): an outage until it is made again, not a request
    /// gone wrong.
    #[error("blob store: its bucket does not exist (create it again, or restore it): {0}")]
    NoBucket(String),
}

impl BlobError {
    /// Whether the store cannot serve now, for a while ([`Self::unreachable`]
    /// or a bucket that is not there): a client may try again later, and
    /// the server answers 503.
    pub fn outage(&self) -> bool {
        self.unreachable() || matches!(self, Self::NoBucket(_))
    }

    /// Whether the store could not be reached (down, refusing, timing
    /// out, cut off), not that the request was wrong: a client may try
    /// again later.
    pub fn unreachable(&self) -> bool {
        use object_store::client::{HttpError, HttpErrorKind};
        let Self::Store(e) = self else {
            return false;
        };
        let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
        while let Some(err) = source {
            if let Some(http) = err.downcast_ref::<HttpError>() {
                return matches!(
                    http.kind(),
                    HttpErrorKind::Connect | HttpErrorKind::Timeout | HttpErrorKind::Interrupted
                );
            }
            source = err.source();
        }
        false
    }
}

/// The blob store `url` names: `s3://…` ([`ObjectBlobs::from_url`]), or a
/// directory (`file:///path`, or a plain path) for [`LocalBlobs`].
pub fn open(url: &str) -> Result<std::sync::Arc<dyn Blobs>, BlobError> {
    if url.starts_with("s3://") {
        return Ok(std::sync::Arc::new(ObjectBlobs::from_url(url)?));
    }
    if let Some((scheme, _)) = url.split_once("://")
        && scheme != "file"
    {
        return Err(BlobError::Config(format!(
            "--blobs {:?}: use s3://BUCKET[/PREFIX][?endpoint=…] or a directory",
            redacted(url)
        )));
    }
    let dir = url.strip_prefix("file://").unwrap_or(url);
    Ok(std::sync::Arc::new(LocalBlobs::open(
        std::path::Path::new(dir),
    )?))
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

/// Checks that `bytes` hash to `digest`, what every backend does before
/// it stores anything.
pub fn verify(digest: &str, bytes: &[u8]) -> Result<(), BlobError> {
    check_digest(digest)?;
    let actual = aobake_core::digest::sha256_hex(bytes);
    if actual != digest {
        return Err(BlobError::DigestMismatch {
            expected: digest.to_owned(),
            actual,
        });
    }
    Ok(())
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
    /// Removes the blob (an operator's repair of one whose bytes no longer
    /// match its name, so that the next `put` stores it again); `false`
    /// when it was not there.
    async fn delete(&self, digest: &str) -> Result<bool, BlobError>;
    /// Whether the store can be used at all (a bucket that exists and
    /// answers): what `serve` checks at its start and `/readyz` at each
    /// probe. The default asks for a blob no one stores.
    async fn probe(&self) -> Result<(), BlobError> {
        self.len(&"0".repeat(64)).await.map(|_| ())
    }
}

/// A blob store whose outages end in the server's log: each request it
/// fails logs a 503, and the first answer after them says so, with how
/// long the store was away (as the reaper does for the database).
#[derive(Debug)]
pub struct Watched {
    inner: std::sync::Arc<dyn Blobs>,
    /// Since the store first failed to answer, while it does.
    down_since: std::sync::Mutex<Option<std::time::Instant>>,
}

impl Watched {
    /// `inner`, watched.
    pub fn over(inner: std::sync::Arc<dyn Blobs>) -> std::sync::Arc<dyn Blobs> {
        std::sync::Arc::new(Self {
            inner,
            down_since: std::sync::Mutex::default(),
        })
    }

    /// `result`, after noting whether the store answered.
    fn heard<T>(&self, result: Result<T, BlobError>) -> Result<T, BlobError> {
        let mut down = self
            .down_since
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        match &result {
            Err(e) if e.outage() => {
                // (Each request it fails logs its own line, as a 503.)
                down.get_or_insert_with(std::time::Instant::now);
            }
            // Errors found here before any request (a digest that does
            // not match, a local file) say nothing of the store.
            Err(
                BlobError::DigestMismatch { .. } | BlobError::BadDigest(_) | BlobError::Config(_),
            ) => {}
            // An answer, a refusal included, means it is back.
            _ => {
                if let Some(since) = down.take() {
                    log_line!(
                        "the blob store answers again, after {:.0} s",
                        since.elapsed().as_secs_f64()
                    );
                }
            }
        }
        result
    }
}

#[async_trait::async_trait]
impl Blobs for Watched {
    async fn put(&self, digest: &str, bytes: &[u8]) -> Result<(), BlobError> {
        self.heard(self.inner.put(digest, bytes).await)
    }

    async fn get(&self, digest: &str) -> Result<Option<Vec<u8>>, BlobError> {
        self.heard(self.inner.get(digest).await)
    }

    async fn get_range(
        &self,
        digest: &str,
        start: u64,
        end: u64,
    ) -> Result<Option<Vec<u8>>, BlobError> {
        self.heard(self.inner.get_range(digest, start, end).await)
    }

    async fn len(&self, digest: &str) -> Result<Option<u64>, BlobError> {
        self.heard(self.inner.len(digest).await)
    }

    async fn delete(&self, digest: &str) -> Result<bool, BlobError> {
        self.heard(self.inner.delete(digest).await)
    }

    async fn probe(&self) -> Result<(), BlobError> {
        self.heard(self.inner.probe().await)
    }
}
