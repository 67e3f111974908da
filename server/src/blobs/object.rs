//! Blobs in an S3-compatible object store, through the `object_store`
//! crate: `PREFIX/ab/abcdef…`, as on local disk. A put checks the digest
//! before anything is sent, so no object ever holds bytes that do not
//! match its name; it creates the object conditionally (`If-None-Match:
//! *`), so a second writer of the same digest changes nothing. Blobs over
//! [`MULTIPART_BYTES`] go up in parts, which the store makes visible whole
//! when the upload completes (after a `HEAD` that skips a blob already
//! there; two writers racing on one large blob write the same bytes).

use std::sync::Arc;
use std::time::Duration;

use object_store::{
    ClientConfigKey, ObjectStore, ObjectStoreExt as _, PutMode, PutOptions, PutPayload,
    RetryConfig, WriteMultipart,
    aws::{AmazonS3Builder, AmazonS3ConfigKey},
    path::Path,
};

use super::{BlobError, Blobs, check_digest, verify};

/// Blobs larger than this are uploaded in parts of this size.
pub const MULTIPART_BYTES: usize = 8 << 20;

/// Blobs in an object store.
#[derive(Debug, Clone)]
pub struct ObjectBlobs {
    store: Arc<dyn ObjectStore>,
    prefix: Path,
}

impl ObjectBlobs {
    /// Blobs under `prefix` of `store`.
    pub fn new(store: Arc<dyn ObjectStore>, prefix: Path) -> Self {
        Self { store, prefix }
    }

    /// Blobs at `s3://BUCKET[/PREFIX][?KEY=VALUE&…]`: each query pair is
    /// one of `object_store`'s S3 settings (`endpoint`, `region`,
    /// `allow_http`, …); credentials and the rest come from the usual
    /// `AWS_*` environment variables.
    pub fn from_url(url: &str) -> Result<Self, BlobError> {
        let shown = redacted(url);
        let bad = |why: String| BlobError::Config(format!("--blobs {shown:?}: {why}"));
        let rest = url
            .strip_prefix("s3://")
            .ok_or_else(|| bad("only s3:// URLs name an object store".into()))?;
        let (location, query) = rest.split_once('?').unwrap_or((rest, ""));
        let (bucket, prefix) = location.split_once('/').unwrap_or((location, ""));
        if bucket.is_empty() {
            return Err(bad("no bucket".into()));
        }
        // A store that does not answer fails a request soon (the API
        // answers 503 then): it connects within 3 s, and retries start
        // within 10 s of the first try, not over object_store's three
        // minutes. `AWS_*` variables and query pairs may say otherwise.
        let mut builder = AmazonS3Builder::from_env()
            .with_bucket_name(bucket)
            .with_retry(RetryConfig {
                max_retries: 3,
                retry_timeout: Duration::from_secs(10),
                ..RetryConfig::default()
            });
        let connect = AmazonS3ConfigKey::Client(ClientConfigKey::ConnectTimeout);
        if builder.get_config_value(&connect).is_none() {
            builder = builder.with_config(connect, "3s");
        }
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| bad(format!("{pair:?} is not KEY=VALUE")))?;
            let key: AmazonS3ConfigKey = key
                .parse()
                .map_err(|_| bad(format!("{key:?} is not an S3 setting")))?;
            builder = builder.with_config(key, value);
        }
        // An http:// endpoint without allow_http builds, then fails every
        // request with "builder error": say so now.
        let endpoint = builder.get_config_value(&AmazonS3ConfigKey::Endpoint);
        let allow_http = AmazonS3ConfigKey::Client(ClientConfigKey::AllowHttp);
        // (Truthy as object_store reads it.)
        let allowed = builder
            .get_config_value(&allow_http)
            .is_some_and(|v| ["true", "1", "yes", "on"].contains(&v.to_ascii_lowercase().as_str()));
        if endpoint
            .as_deref()
            .is_some_and(|e| e.starts_with("http://"))
            && !allowed
        {
            return Err(bad(
                "the endpoint is http://: add allow_http=true (or use https://)".into(),
            ));
        }
        // TLS to the store is reqwest's rustls on ring, the process's
        // provider (reqwest asks for it when it builds its client); an
        // error says one is installed already.
        let _ = rustls::crypto::ring::default_provider().install_default();
        let store = builder.build().map_err(|e| bad(e.to_string()))?;
        let prefix = Path::parse(prefix).map_err(|e| bad(e.to_string()))?;
        Ok(Self::new(Arc::new(store), prefix))
    }

    fn path(&self, digest: &str) -> Result<Path, BlobError> {
        check_digest(digest)?;
        Ok(self.prefix.clone().join(&digest[..2]).join(digest))
    }

    /// The object's length, or `None` when there is none.
    async fn head(&self, path: &Path) -> Result<Option<u64>, BlobError> {
        missing_is_none(self.store.head(path).await).map(|m| m.map(|m| m.size))
    }
}

fn missing_is_none<T>(r: object_store::Result<T>) -> Result<Option<T>, BlobError> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(e) if no_bucket(&e) => Err(BlobError::NoBucket(e.to_string())),
        Err(object_store::Error::NotFound { .. }) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// Whether the store said the bucket is not there (S3's `NoSuchBucket`,
/// somewhere in the error's chain). A HEAD has no body to say it in: a
/// missing bucket then reads as a missing object.
fn no_bucket(e: &object_store::Error) -> bool {
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(err) = source {
        if err.to_string().contains("NoSuchBucket") {
            return true;
        }
        source = err.source();
    }
    false
}

/// An object store error as a [`BlobError`]; a write's "not found" can
/// only be the bucket's (`write`).
fn store_error(e: object_store::Error, write: bool) -> BlobError {
    if no_bucket(&e) || (write && matches!(e, object_store::Error::NotFound { .. })) {
        BlobError::NoBucket(e.to_string())
    } else {
        e.into()
    }
}

/// `url` with the values of its secret settings (a secret key, a session
/// token, a password) replaced by `…`, fit to be shown or logged.
pub fn redacted(url: &str) -> String {
    let Some((location, query)) = url.split_once('?') else {
        return url.to_owned();
    };
    let pairs: Vec<String> = query
        .split('&')
        .map(|pair| match pair.split_once('=') {
            Some((key, _))
                if ["secret", "token", "password"]
                    .iter()
                    .any(|s| key.to_ascii_lowercase().contains(s)) =>
            {
                format!("{key}=…")
            }
            _ => pair.to_owned(),
        })
        .collect();
    format!("{location}?{}", pairs.join("&"))
}

#[async_trait::async_trait]
impl Blobs for ObjectBlobs {
    async fn put(&self, digest: &str, bytes: &[u8]) -> Result<(), BlobError> {
        let path = self.path(digest)?;
        verify(digest, bytes)?;
        if bytes.len() > MULTIPART_BYTES {
            if self.head(&path).await?.is_some() {
                return Ok(());
            }
            let upload = self
                .store
                .put_multipart(&path)
                .await
                .map_err(|e| store_error(e, true))?;
            let mut writer = WriteMultipart::new_with_chunk_size(upload, MULTIPART_BYTES);
            writer.write(bytes);
            // A failed finish aborts the upload itself: no parts are left.
            writer.finish().await.map_err(|e| store_error(e, true))?;
            return Ok(());
        }
        let create = PutOptions {
            mode: PutMode::Create,
            ..PutOptions::default()
        };
        let payload = PutPayload::from(bytes.to_vec());
        match self.store.put_opts(&path, payload, create).await {
            Ok(_) | Err(object_store::Error::AlreadyExists { .. }) => Ok(()),
            Err(e) => Err(store_error(e, true)),
        }
    }

    async fn get(&self, digest: &str) -> Result<Option<Vec<u8>>, BlobError> {
        let path = self.path(digest)?;
        let Some(got) = missing_is_none(self.store.get(&path).await)? else {
            return Ok(None);
        };
        Ok(Some(got.bytes().await?.to_vec()))
    }

    async fn get_range(
        &self,
        digest: &str,
        start: u64,
        end: u64,
    ) -> Result<Option<Vec<u8>>, BlobError> {
        let path = self.path(digest)?;
        // One ranged GET (the store trims an end past the blob); only an
        // empty range, or a start the GET refuses (past the end), asks
        // with a HEAD whether the blob is there at all.
        if start < end {
            match self.store.get_range(&path, start..end).await {
                Ok(bytes) => return Ok(Some(bytes.to_vec())),
                Err(object_store::Error::NotFound { .. }) => return Ok(None),
                Err(_) if start > 0 => {}
                Err(e) => return Err(e.into()),
            }
        }
        Ok(self.head(&path).await?.map(|_| Vec::new()))
    }

    async fn len(&self, digest: &str) -> Result<Option<u64>, BlobError> {
        self.head(&self.path(digest)?).await
    }

    async fn delete(&self, digest: &str) -> Result<bool, BlobError> {
        let path = self.path(digest)?;
        // S3's DELETE answers alike whether the object was there.
        if self.head(&path).await?.is_none() {
            return Ok(false);
        }
        self.store
            .delete(&path)
            .await
            .map_err(|e| store_error(e, true))?;
        Ok(true)
    }

    /// A listing of the prefix's first level: a HEAD on an object that is
    /// not there answers 404 alike for a bucket that is not there, a list
    /// does not.
    async fn probe(&self) -> Result<(), BlobError> {
        let prefix = (!self.prefix.as_ref().is_empty()).then_some(&self.prefix);
        match self.store.list_with_delimiter(prefix).await {
            Ok(_) => Ok(()),
            // Said plainly, for `serve`'s start and the readiness log.
            Err(e) => Err(store_error(e, true)),
        }
    }
}

#[cfg(test)]
mod tests {
    use aobake_e2e::TestS3;

    use super::super::suite::run_all;

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn blobs_in_a_real_s3_server_pass_the_suite() {
        let s3 = TestS3::start();
        let blobs = super::super::open(&s3.url).unwrap();
        run_all(blobs.as_ref()).await;
        // The store refuses a second create of one name (what keeps a
        // racing writer from replacing a blob), and a put asks for that.
        use super::*;
        use aobake_core::digest::sha256_hex;
        let blobs = ObjectBlobs::from_url(&s3.url).unwrap();
        let bytes = b"hello blobs";
        let path = blobs.path(&sha256_hex(bytes)).unwrap();
        let create = || PutOptions {
            mode: PutMode::Create,
            ..PutOptions::default()
        };
        let again = blobs
            .store
            .put_opts(&path, PutPayload::from_static(bytes), create())
            .await;
        assert!(
            matches!(again, Err(object_store::Error::AlreadyExists { .. })),
            "{again:?}"
        );
        // The probe passes on the bucket, and fails on one that is not
        // there, whose HEAD on an object would answer a plain 404.
        blobs.probe().await.unwrap();
        let missing =
            ObjectBlobs::from_url(&s3.url.replace("aobake-test", "no-such-bucket")).unwrap();
        assert_eq!(missing.len(&"0".repeat(64)).await.unwrap(), None);
        let refused = missing.probe().await.unwrap_err();
        assert!(matches!(refused, BlobError::NoBucket(_)), "{refused:?}");
        assert!(
            refused.to_string().contains("its bucket does not exist"),
            "{refused}"
        );
        // Writing to it is an outage (a 503 over HTTP), not a failure:
        // the bucket may be made again.
        let put = missing.put(&sha256_hex(bytes), bytes).await.unwrap_err();
        assert!(
            put.outage() && matches!(put, BlobError::NoBucket(_)),
            "{put:?}"
        );
        let big = vec![7u8; MULTIPART_BYTES + 1];
        let put = missing.put(&sha256_hex(&big), &big).await.unwrap_err();
        assert!(matches!(put, BlobError::NoBucket(_)), "{put:?}");
    }

    /// An `https://` endpoint is spoken to in TLS (rustls on ring, the
    /// provider this module installs): what reaches the endpoint opens
    /// with a TLS handshake record, and the store's error is the broken
    /// connection's, not a missing crypto provider's.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn an_https_endpoint_is_spoken_to_in_tls() {
        use super::super::Blobs as _;
        use std::io::Read as _;
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let first = std::thread::spawn(move || {
            let (mut stream, _) = listener.accept().unwrap();
            let mut head = [0u8; 3];
            stream.read_exact(&mut head).unwrap();
            head
        });
        let blobs = super::ObjectBlobs::from_url(&format!(
            "s3://bucket?endpoint=https://127.0.0.1:{port}&region=us-east-1&access_key_id=a&secret_access_key=b"
        ))
        .unwrap();
        let failed = blobs.get(&"0".repeat(64)).await.unwrap_err().to_string();
        // A TLS record: handshake (22), protocol 3.x.
        assert_eq!(first.join().unwrap()[..2], [22, 3], "{failed}");
        assert!(!failed.contains("CryptoProvider"), "{failed}");
    }

    #[test]
    fn urls_name_what_is_wrong() {
        let err = |url: &str| super::super::open(url).unwrap_err().to_string();
        assert!(err("s3://").contains("no bucket"), "{}", err("s3://"));
        assert!(err("s3://b?color=red").contains("\"color\" is not an S3 setting"));
        assert!(err("s3://b?endpoint").contains("is not KEY=VALUE"));
        assert!(err("gs://b").contains("use s3://"));
        let http = err("s3://b?endpoint=http://127.0.0.1:9000");
        assert!(http.contains("add allow_http=true"), "{http}");
        // A secret given as a setting is not echoed.
        let said = err("s3://b?aws_secret_access_key=SECRETXYZ&bogus=1");
        assert!(
            said.contains("\"bogus\" is not an S3 setting") && !said.contains("SECRETXYZ"),
            "{said}"
        );
    }
}
