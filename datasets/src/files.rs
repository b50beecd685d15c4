//! A dataset's files for readers other than the loader (the viewer reads one episode in frame
//! order): the same local-directory-or-S3 store the loader opens, with the same error messages.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use parquet::file::reader::ChunkReader;

use crate::error::Result;
use crate::store::Store;

/// The files of a dataset at a location: a directory or `s3://bucket/prefix` (configured from
/// the usual `AWS_*` variables, as [`crate::LoaderOptions::open`] does).
#[derive(Clone)]
pub struct DatasetFiles {
    store: Store,
    counter: Arc<AtomicU64>,
}

impl std::fmt::Debug for DatasetFiles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DatasetFiles")
            .field("root", &self.store.describe(""))
            .finish_non_exhaustive()
    }
}

impl DatasetFiles {
    /// Opens `location`; a local path must be a directory.
    pub fn open(location: &str) -> Result<Self> {
        Ok(Self {
            store: Store::open(location)?,
            counter: Arc::default(),
        })
    }

    /// The path or URL of `rel` (relative to the root), for messages.
    pub fn describe(&self, rel: &str) -> String {
        self.store.describe(rel)
    }

    /// The whole file at `rel`. A missing file is an [`crate::Error::Io`] of kind `NotFound`.
    pub fn read(&self, rel: &str) -> Result<Vec<u8>> {
        let bytes = self.store.read(rel)?;
        self.counter
            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(bytes.to_vec())
    }

    /// Paths (relative to the root, sorted) of the files under `dir` whose names end in `ext`.
    pub fn list(&self, dir: &str, ext: &str) -> Result<Vec<String>> {
        self.store.list(dir, ext)
    }

    /// A file for the parquet reader (positioned reads, fetched on demand; thread-safe).
    pub fn parquet(&self, rel: &str) -> Result<impl ChunkReader + Clone + 'static> {
        self.store.file(rel, self.counter.clone())
    }

    /// Bytes read so far through this handle and its clones.
    pub fn bytes_read(&self) -> u64 {
        self.counter.load(Ordering::Relaxed)
    }
}
