//! Blobs as files under a directory, two hex digits of fan-out:
//! `DIR/ab/abcdef…`. A put writes a temporary file in `DIR/tmp`, fsyncs
//! it, renames it into place and fsyncs the directory, so a crash leaves
//! either the whole blob or none.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use super::{BlobError, Blobs, check_digest, verify};

/// Blobs on local disk.
#[derive(Debug, Clone)]
pub struct LocalBlobs {
    root: PathBuf,
}

impl LocalBlobs {
    /// Blobs under `root` (created if needed).
    pub fn open(root: &Path) -> Result<Self, BlobError> {
        std::fs::create_dir_all(root.join("tmp"))?;
        Ok(Self {
            root: root.to_owned(),
        })
    }

    fn path(&self, digest: &str) -> Result<PathBuf, BlobError> {
        check_digest(digest)?;
        Ok(self.root.join(&digest[..2]).join(digest))
    }

    fn put_sync(&self, digest: &str, bytes: &[u8]) -> Result<(), BlobError> {
        let path = self.path(digest)?;
        verify(digest, bytes)?;
        if path.exists() {
            return Ok(());
        }
        let dir = path.parent().expect("fan-out directory");
        std::fs::create_dir_all(dir)?;
        let mut tmp = tempfile::NamedTempFile::new_in(self.root.join("tmp"))?;
        tmp.write_all(bytes)?;
        tmp.as_file().sync_all()?;
        tmp.persist(&path).map_err(|e| e.error)?;
        std::fs::File::open(dir)?.sync_all()?;
        Ok(())
    }
}

fn missing_is_none<T>(r: std::io::Result<T>) -> Result<Option<T>, BlobError> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e.into()),
    }
}

#[async_trait::async_trait]
impl Blobs for LocalBlobs {
    async fn put(&self, digest: &str, bytes: &[u8]) -> Result<(), BlobError> {
        let this = self.clone();
        let (digest, bytes) = (digest.to_owned(), bytes.to_vec());
        tokio::task::spawn_blocking(move || this.put_sync(&digest, &bytes))
            .await
            .map_err(|e| BlobError::Io(std::io::Error::other(e)))?
    }

    async fn get(&self, digest: &str) -> Result<Option<Vec<u8>>, BlobError> {
        missing_is_none(tokio::fs::read(self.path(digest)?).await)
    }

    async fn get_range(
        &self,
        digest: &str,
        start: u64,
        end: u64,
    ) -> Result<Option<Vec<u8>>, BlobError> {
        use tokio::io::{AsyncReadExt as _, AsyncSeekExt as _};
        let Some(mut file) = missing_is_none(tokio::fs::File::open(self.path(digest)?).await)?
        else {
            return Ok(None);
        };
        let len = file.metadata().await?.len();
        let (start, end) = (start.min(len), end.min(len));
        file.seek(std::io::SeekFrom::Start(start)).await?;
        let mut out = vec![0; (end.saturating_sub(start)) as usize];
        file.read_exact(&mut out).await?;
        Ok(Some(out))
    }

    async fn len(&self, digest: &str) -> Result<Option<u64>, BlobError> {
        Ok(missing_is_none(tokio::fs::metadata(self.path(digest)?).await)?.map(|m| m.len()))
    }

    async fn delete(&self, digest: &str) -> Result<bool, BlobError> {
        Ok(missing_is_none(tokio::fs::remove_file(self.path(digest)?).await)?.is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn blobs_on_disk_pass_the_suite_and_leave_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = LocalBlobs::open(dir.path()).unwrap();
        super::super::suite::run_all(&blobs).await;
        let tmp: Vec<_> = std::fs::read_dir(dir.path().join("tmp")).unwrap().collect();
        assert!(tmp.is_empty(), "no temporary file left behind");
    }
}
