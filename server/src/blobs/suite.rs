//! The blob stores' behaviour, written once and run against every backend:
//! local disk, and a real S3-compatible server that the tests start
//! (`aobake_e2e::TestS3`, moto's server).

use aobake_core::digest::sha256_hex;

use super::{BlobError, Blobs, MULTIPART_BYTES};

/// What every blob store must do.
pub(crate) async fn run_all(blobs: &dyn Blobs) {
    let bytes = b"hello blobs".to_vec();
    let d = sha256_hex(&bytes);
    assert!(blobs.get(&d).await.unwrap().is_none());
    assert!(blobs.len(&d).await.unwrap().is_none());
    assert!(blobs.get_range(&d, 0, 4).await.unwrap().is_none());
    // The digest is checked before anything is stored.
    let wrong = sha256_hex(b"other");
    assert!(matches!(
        blobs.put(&wrong, &bytes).await,
        Err(BlobError::DigestMismatch { .. })
    ));
    assert!(
        blobs.get(&wrong).await.unwrap().is_none(),
        "nothing published"
    );
    // A second put of the same blob, even at once, changes nothing.
    let (a, b) = tokio::join!(blobs.put(&d, &bytes), blobs.put(&d, &bytes));
    a.unwrap();
    b.unwrap();
    blobs.put(&d, &bytes).await.unwrap();
    assert_eq!(blobs.get(&d).await.unwrap().unwrap(), bytes);
    assert_eq!(blobs.len(&d).await.unwrap(), Some(11));
    // A deleted blob is gone, and a put stores it again.
    assert!(blobs.delete(&d).await.unwrap());
    assert!(blobs.len(&d).await.unwrap().is_none());
    assert!(!blobs.delete(&d).await.unwrap(), "not there");
    blobs.put(&d, &bytes).await.unwrap();
    assert_eq!(blobs.len(&d).await.unwrap(), Some(11));
    // Ranges are clamped to the blob.
    let range = |s, e| blobs.get_range(&d, s, e);
    assert_eq!(range(6, 100).await.unwrap().unwrap(), b"blobs");
    assert_eq!(range(0, 5).await.unwrap().unwrap(), b"hello");
    assert_eq!(range(20, 30).await.unwrap().unwrap(), b"");
    assert_eq!(range(5, 5).await.unwrap().unwrap(), b"");
    // Names that could leave the store's prefix are refused.
    for bad in ["../../etc/passwd", "AB", &d.to_uppercase()] {
        assert!(matches!(blobs.get(bad).await, Err(BlobError::BadDigest(_))));
        assert!(matches!(
            blobs.put(bad, &bytes).await,
            Err(BlobError::BadDigest(_))
        ));
    }
    // A blob larger than a part: whole, and ranges across the parts.
    let large: Vec<u8> = (0..MULTIPART_BYTES + 300_000)
        .map(|i| (i * 7 % 251) as u8)
        .collect();
    let big = sha256_hex(&large);
    let (a, b) = tokio::join!(blobs.put(&big, &large), blobs.put(&big, &large));
    a.unwrap();
    b.unwrap();
    assert_eq!(blobs.len(&big).await.unwrap(), Some(large.len() as u64));
    assert!(blobs.get(&big).await.unwrap().unwrap() == large);
    let (s, e) = (MULTIPART_BYTES - 10, MULTIPART_BYTES + 10);
    assert_eq!(
        blobs
            .get_range(&big, s as u64, e as u64)
            .await
            .unwrap()
            .unwrap(),
        large[s..e]
    );
}
