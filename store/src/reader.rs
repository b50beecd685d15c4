//! An object read front to back as a [`std::io::Read`], through ranged GETs of fixed-size blocks
//! kept a few ahead of the reader: a single GET stream is limited by one connection's window
//! (and a dropped one restarts from the start), while blocks in flight overlap the network with
//! the caller's work, a failed block is retried alone, and memory stays at `depth` blocks.

use std::collections::VecDeque;
use std::sync::Arc;

use bytes::{Buf, Bytes};
use tokio::task::JoinHandle;

use crate::bucket::Bucket;
use crate::error::{Error, Result};
use crate::location::ObjectInfo;
use crate::runtime::{block, spawn};

/// Bytes of one block.
pub const BLOCK_BYTES: u64 = 8 << 20;
/// Blocks in flight ahead of the reader.
pub const BLOCKS_AHEAD: usize = 4;

/// A front-to-back reader of one object version (see the module docs).
pub struct ObjectReader {
    bucket: Arc<Bucket>,
    info: ObjectInfo,
    key: object_store::path::Path,
    /// Where the next block to request starts.
    next: u64,
    inflight: VecDeque<JoinHandle<Result<Bytes>>>,
    current: Bytes,
    /// Bytes handed out so far.
    read: u64,
}

impl ObjectReader {
    /// A reader of the object `info` (pinned to its ETag, when it has one) of `bucket`.
    pub fn new(bucket: Arc<Bucket>, info: ObjectInfo) -> Result<Self> {
        let key = bucket.key_of(&info)?;
        Ok(Self {
            bucket,
            info,
            key,
            next: 0,
            inflight: VecDeque::new(),
            current: Bytes::new(),
            read: 0,
        })
    }

    /// The object read.
    pub fn info(&self) -> &ObjectInfo {
        &self.info
    }

    /// Bytes handed to the caller so far.
    pub fn bytes_read(&self) -> u64 {
        self.read
    }

    /// Requests blocks until `BLOCKS_AHEAD` are in flight or the object is covered.
    fn fill(&mut self) -> Result<()> {
        while self.inflight.len() < BLOCKS_AHEAD && self.next < self.info.size {
            let end = (self.next + BLOCK_BYTES).min(self.info.size);
            let fetch = self.bucket.fetch(&self.key, &self.info, self.next..end);
            let handle = spawn(fetch)?;
            self.inflight.push_back(handle);
            self.next = end;
        }
        Ok(())
    }

    /// The next block, waiting for it.
    fn next_block(&mut self) -> Result<Option<Bytes>> {
        self.fill()?;
        let Some(handle) = self.inflight.pop_front() else {
            return Ok(None);
        };
        let got = block(handle)?.map_err(|e| Error::Other {
            url: self.info.url.to_string(),
            reason: format!("read task failed: {e}"),
        })??;
        self.fill()?;
        Ok(Some(got))
    }
}

impl std::io::Read for ObjectReader {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        while self.current.is_empty() {
            match self.next_block() {
                Ok(Some(b)) => self.current = b,
                Ok(None) => return Ok(0),
                // The caller names the object; the message says what happened to it.
                Err(e) => return Err(std::io::Error::other(e.reason())),
            }
        }
        let n = out.len().min(self.current.len());
        out[..n].copy_from_slice(&self.current[..n]);
        self.current.advance(n);
        self.read += n as u64;
        Ok(n)
    }
}

impl Drop for ObjectReader {
    fn drop(&mut self) {
        for h in &self.inflight {
            h.abort();
        }
    }
}
