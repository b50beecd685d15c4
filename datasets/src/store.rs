//! Where a dataset lives: a local directory (plain `std::fs`, positioned reads) or a prefix in
//! S3-compatible object storage (`object_store`, configured from the standard `AWS_*`
//! environment variables, e.g. `AWS_ENDPOINT_URL` and `AWS_ALLOW_HTTP=true` for a local server).
//! Data files are exposed to the parquet reader as [`DataFile`]s that count the bytes they read.

use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use bytes::Bytes;
use object_store::ObjectStore;
use parquet::file::reader::{ChunkReader, Length};

use crate::error::{Error, Result};

/// Retries of a failed object store request.
const STORE_RETRIES: usize = 3;
/// Longest time a request is retried for.
const STORE_RETRY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(30);

/// A dataset root.
#[derive(Clone)]
pub(crate) enum Store {
    Local(PathBuf),
    Remote(Arc<Remote>),
}

pub(crate) struct Remote {
    store: Box<dyn ObjectStore>,
    prefix: String,
    url: String,
    rt: tokio::runtime::Runtime,
}

impl Remote {
    fn key(&self, rel: &str) -> object_store::path::Path {
        object_store::path::Path::from(format!("{}{rel}", self.prefix))
    }

    /// A missing object reads as a missing file (`stats.json` is optional); other failures keep
    /// the store's reason on one line (servers answer with multi-line XML).
    fn err(&self, rel: &str, e: object_store::Error) -> Error {
        let path = format!("{}/{rel}", self.url.trim_end_matches('/'));
        match e {
            object_store::Error::NotFound { .. } => Error::Io {
                path: path.into(),
                source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such object"),
            },
            e => Error::Store {
                path,
                reason: e
                    .to_string()
                    .split_whitespace()
                    .collect::<Vec<_>>()
                    .join(" "),
            },
        }
    }
}

impl Store {
    /// `s3://bucket/prefix` or a local directory.
    pub fn open(location: &str) -> Result<Self> {
        let Some(rest) = location.strip_prefix("s3://") else {
            let root = PathBuf::from(location);
            if !root.is_dir() {
                return Err(Error::Io {
                    path: root,
                    source: std::io::Error::new(
                        std::io::ErrorKind::NotFound,
                        "no such dataset directory",
                    ),
                });
            }
            return Ok(Store::Local(root));
        };
        let (bucket, prefix) = rest.split_once('/').unwrap_or((rest, ""));
        // Bounded: a connection that drops is retried a few times, then the read fails with the
        // store's reason instead of stalling a training run (object_store's own default retries
        // for up to three minutes). A request times out after 30 s, a connect after 5 s
        // (object_store's defaults; `AWS_TIMEOUT`-style settings from the environment apply).
        let retry = object_store::RetryConfig {
            max_retries: STORE_RETRIES,
            retry_timeout: STORE_RETRY_TIMEOUT,
            ..Default::default()
        };
        let store = object_store::aws::AmazonS3Builder::from_env()
            .with_retry(retry)
            .with_bucket_name(bucket)
            .build()
            .map_err(|e| Error::Store {
                path: location.into(),
                reason: e.to_string(),
            })?;
        let prefix = prefix.trim_matches('/');
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("scaledp-s3")
            .enable_all()
            .build()
            .map_err(|e| Error::Io {
                path: location.into(),
                source: e,
            })?;
        Ok(Store::Remote(Arc::new(Remote {
            store: Box::new(store),
            prefix: if prefix.is_empty() {
                String::new()
            } else {
                format!("{prefix}/")
            },
            url: location.into(),
            rt,
        })))
    }

    /// A description for messages: the directory or URL.
    pub fn describe(&self, rel: &str) -> String {
        match self {
            Store::Local(root) => root.join(rel).display().to_string(),
            Store::Remote(r) => format!("{}/{rel}", r.url.trim_end_matches('/')),
        }
    }

    /// The whole object at `rel`.
    pub fn read(&self, rel: &str) -> Result<Bytes> {
        match self {
            Store::Local(root) => {
                let path = root.join(rel);
                std::fs::read(&path)
                    .map(Bytes::from)
                    .map_err(|source| Error::Io { path, source })
            }
            Store::Remote(r) => r.rt.block_on(async {
                let got = r.store.get(&r.key(rel)).await.map_err(|e| r.err(rel, e))?;
                got.bytes().await.map_err(|e| r.err(rel, e))
            }),
        }
    }

    /// Paths (relative to the root, sorted) of the files under `dir` whose name ends in `ext`.
    pub fn list(&self, dir: &str, ext: &str) -> Result<Vec<String>> {
        let mut out = Vec::new();
        match self {
            Store::Local(root) => walk(root, Path::new(dir), ext, &mut out)?,
            Store::Remote(r) => {
                use futures::StreamExt;
                let listed: Vec<_> = r.rt.block_on(async {
                    let mut s = r.store.list(Some(&r.key(dir)));
                    let mut v = Vec::new();
                    while let Some(m) = s.next().await {
                        v.push(m.map_err(|e| r.err(dir, e))?);
                    }
                    Ok::<_, Error>(v)
                })?;
                for m in listed {
                    let key = m.location.to_string();
                    if let Some(rel) = key.strip_prefix(&r.prefix) {
                        if rel.ends_with(ext) {
                            out.push(rel.to_string());
                        }
                    }
                }
            }
        }
        out.sort();
        Ok(out)
    }

    /// A data file for the parquet reader; `counter` adds every byte read.
    pub fn file(&self, rel: &str, counter: Arc<AtomicU64>) -> Result<DataFile> {
        let backing = match self {
            Store::Local(root) => {
                let path = root.join(rel);
                let file = File::open(&path).map_err(|source| Error::Io {
                    path: path.clone(),
                    source,
                })?;
                let size = file
                    .metadata()
                    .map_err(|source| Error::Io { path, source })?
                    .len();
                Backing::Local { file, size }
            }
            Store::Remote(r) => {
                let key = r.key(rel);
                let size =
                    r.rt.block_on(r.store.head(&key))
                        .map_err(|e| r.err(rel, e))?
                        .size;
                Backing::Remote {
                    remote: r.clone(),
                    key,
                    size,
                }
            }
        };
        Ok(DataFile {
            backing: Arc::new(backing),
            name: self.describe(rel),
            counter,
        })
    }
}

fn walk(root: &Path, dir: &Path, ext: &str, out: &mut Vec<String>) -> Result<()> {
    let full = root.join(dir);
    let entries = match std::fs::read_dir(&full) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(source) => return Err(Error::Io { path: full, source }),
    };
    for entry in entries {
        let entry = entry.map_err(|source| Error::Io {
            path: full.clone(),
            source,
        })?;
        let rel = dir.join(entry.file_name());
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            walk(root, &rel, ext, out)?;
        } else if let Some(s) = rel.to_str().filter(|s| s.ends_with(ext)) {
            out.push(s.to_string());
        }
    }
    Ok(())
}

enum Backing {
    Local {
        file: File,
        size: u64,
    },
    Remote {
        remote: Arc<Remote>,
        key: object_store::path::Path,
        size: u64,
    },
}

/// One parquet data file, shareable between threads (positioned reads, no shared cursor).
#[derive(Clone)]
pub(crate) struct DataFile {
    backing: Arc<Backing>,
    /// The path or URL, for messages.
    pub name: String,
    counter: Arc<AtomicU64>,
}

impl Length for DataFile {
    fn len(&self) -> u64 {
        match &*self.backing {
            Backing::Local { size, .. } | Backing::Remote { size, .. } => *size,
        }
    }
}

/// A reader from an offset to the end of a [`DataFile`] that fetches on demand, in chunks that
/// start small (a page header is a few bytes) and double: the parquet reader asks for one when a
/// file has no offset index, to read a page header, and must not pull the rest of the file.
pub(crate) struct RangeRead {
    file: DataFile,
    pos: u64,
    end: u64,
    buf: Bytes,
    chunk: usize,
}

impl std::io::Read for RangeRead {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        if self.buf.is_empty() && self.pos < self.end {
            let n = (self.end - self.pos).min(self.chunk as u64) as usize;
            self.buf = self
                .file
                .get_bytes(self.pos, n)
                .map_err(std::io::Error::other)?;
            self.pos += n as u64;
            self.chunk = (self.chunk * 2).min(1 << 20);
        }
        let n = out.len().min(self.buf.len());
        out[..n].copy_from_slice(&self.buf[..n]);
        bytes::Buf::advance(&mut self.buf, n);
        Ok(n)
    }
}

impl ChunkReader for DataFile {
    type T = RangeRead;

    fn get_read(&self, start: u64) -> parquet::errors::Result<Self::T> {
        Ok(RangeRead {
            file: self.clone(),
            pos: start,
            end: self.len().max(start),
            buf: Bytes::new(),
            chunk: 512,
        })
    }

    fn get_bytes(&self, start: u64, length: usize) -> parquet::errors::Result<Bytes> {
        let ext = |e: String| {
            let e = e.split_whitespace().collect::<Vec<_>>().join(" ");
            parquet::errors::ParquetError::General(format!("{}: {e}", self.name))
        };
        // Offsets come from the file's own metadata: check them before allocating.
        if start
            .checked_add(length as u64)
            .is_none_or(|end| end > self.len())
        {
            return Err(ext(format!(
                "a read of {length} bytes at {start} goes past the end ({} bytes): corrupt footer or page index",
                self.len()
            )));
        }
        self.counter.fetch_add(length as u64, Ordering::Relaxed);
        match &*self.backing {
            Backing::Local { file, .. } => {
                let mut buf = vec![0u8; length];
                file.read_exact_at(&mut buf, start)
                    .map_err(|e| ext(e.to_string()))?;
                Ok(Bytes::from(buf))
            }
            Backing::Remote { remote, key, .. } => remote
                .rt
                .block_on(remote.store.get_range(key, start..start + length as u64))
                .map_err(|e| ext(e.to_string())),
        }
    }
}

/// A [`DataFile`] as `Read + Seek` for parsers that walk a file's boxes (the MP4 index):
/// reads of at most 64 KiB at a time, fetched where the cursor is, so seeking past a large box
/// reads none of it.
pub(crate) struct SeekRead {
    file: DataFile,
    pos: u64,
    buf: Bytes,
    /// File offset of `buf`'s first byte.
    buf_at: u64,
}

impl SeekRead {
    pub fn new(file: DataFile) -> Self {
        SeekRead {
            file,
            pos: 0,
            buf: Bytes::new(),
            buf_at: 0,
        }
    }
}

impl std::io::Read for SeekRead {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let len = self.file.len();
        if self.pos >= len || out.is_empty() {
            return Ok(0);
        }
        let inside = self.pos >= self.buf_at && self.pos < self.buf_at + self.buf.len() as u64;
        if !inside {
            let n = (len - self.pos).min(64 << 10) as usize;
            self.buf = self
                .file
                .get_bytes(self.pos, n)
                .map_err(std::io::Error::other)?;
            self.buf_at = self.pos;
        }
        let from = (self.pos - self.buf_at) as usize;
        let n = out.len().min(self.buf.len() - from);
        out[..n].copy_from_slice(&self.buf[from..from + n]);
        self.pos += n as u64;
        Ok(n)
    }
}

impl std::io::Seek for SeekRead {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        let target = match to {
            std::io::SeekFrom::Start(p) => Some(p),
            std::io::SeekFrom::End(d) => self.file.len().checked_add_signed(d),
            std::io::SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = target.ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
        })?;
        Ok(self.pos)
    }
}
