//! The reader behind [`super::stream`] and its siblings: chunk buffers reused once no frame
//! refers to them, the records of a chunk, and what each message is handed out as.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

use mcap::records::{op, Record};

use crate::error::{Error, Result};
use crate::lz4::{crc_mismatch, Decoder, Tail};
use crate::source::{ros2_type_name, TopicInfo};

/// A chunk's last message is left compressed when it is at least this large.
const DEFER_MIN: usize = 1 << 20;
/// Largest chunk accepted (uncompressed).
pub(super) const MAX_CHUNK: usize = 1 << 30;
/// Bytes of a deferred message decoded for its header.
const PREFIX: usize = 4 << 10;

/// Metadata records by name.
pub type Metadata = BTreeMap<String, BTreeMap<String, String>>;

/// A message payload kept beyond the read: a range of a shared decompressed chunk, or the
/// compressed end of a chunk.
#[derive(Debug, Clone)]
pub enum FrameBytes {
    /// Decompressed.
    Ready(Arc<Vec<u8>>, Range<usize>),
    /// Decoded when asked for.
    Deferred(Arc<Tail>),
}

impl FrameBytes {
    /// Calls `f` with the bytes, decompressing them first if they were left compressed.
    pub fn with<T>(&self, f: impl FnOnce(&[u8]) -> T) -> std::result::Result<T, String> {
        match self {
            Self::Ready(buf, range) => Ok(f(buf.get(range.clone()).unwrap_or_default())),
            Self::Deferred(tail) => tail.with(f),
        }
    }
}

/// A message payload during the read.
pub enum Payload<'a> {
    /// Decompressed: `chunk[range]`.
    Ready(&'a Arc<Vec<u8>>, Range<usize>),
    /// The compressed end of a chunk.
    Deferred(&'a Arc<Tail>),
}

impl Payload<'_> {
    /// The bytes, or for a payload left compressed the first of them (its first 4 KiB at least,
    /// ample for a header).
    pub fn prefix(&self) -> &[u8] {
        match self {
            Self::Ready(buf, range) => buf.get(range.clone()).unwrap_or_default(),
            Self::Deferred(tail) => tail.prefix(),
        }
    }
    /// A handle that outlives the read (no copy).
    pub fn share(&self) -> FrameBytes {
        match self {
            Self::Ready(buf, range) => FrameBytes::Ready(Arc::clone(buf), range.clone()),
            Self::Deferred(tail) => FrameBytes::Deferred(Arc::clone(tail)),
        }
    }
}

/// Called per message with (topic, log time in ns, payload, metadata records seen so far);
/// returns whether to go on reading.
pub type OnMessage<'a> = dyn FnMut(&TopicInfo, u64, Payload<'_>, &Metadata) -> Result<bool> + 'a;

/// Decompressed chunk buffers, reused once no frame refers to them any more.
#[derive(Default)]
pub(super) struct Buffers(Vec<Arc<Vec<u8>>>);

impl Buffers {
    /// Buffers kept for reuse; more than this are dropped when their frames are done.
    const KEEP: usize = 16;

    /// A buffer of at least `n` bytes that nobody else holds.
    pub(super) fn take(&mut self, n: usize) -> Arc<Vec<u8>> {
        let free = self.0.iter().position(|b| Arc::strong_count(b) == 1);
        let mut buf = match free {
            Some(i) => self.0.swap_remove(i),
            None => Arc::new(Vec::new()),
        };
        if Arc::get_mut(&mut buf).is_none() {
            buf = Arc::new(Vec::new());
        }
        if let Some(v) = Arc::get_mut(&mut buf) {
            if v.len() < n {
                v.resize(n, 0);
            }
        }
        buf
    }

    pub(super) fn give_back(&mut self, buf: &Arc<Vec<u8>>) {
        if self.0.len() >= Self::KEEP {
            if let Some(i) = self.0.iter().position(|b| Arc::strong_count(b) > 1) {
                self.0.swap_remove(i);
            }
        }
        if self.0.len() < Self::KEEP {
            self.0.push(Arc::clone(buf));
        }
    }
}

pub(super) struct Reader<'p> {
    pub(super) path: &'p Path,
    pub(super) schemas: BTreeMap<u16, String>,
    pub(super) channels: BTreeMap<u16, TopicInfo>,
    pub(super) metadata: Metadata,
    pub(super) first: bool,
    pub(super) buffers: Buffers,
}

impl Reader<'_> {
    fn bad(&self, reason: impl std::fmt::Display) -> Error {
        Error::input(self.path, reason)
    }

    /// A file-level record (`at` None), or one inside `chunk` at `at`. Returns whether to go on.
    pub(super) fn record(
        &mut self,
        opcode: u8,
        bytes: &[u8],
        at: Option<(&Arc<Vec<u8>>, usize)>,
        on_message: &mut OnMessage<'_>,
    ) -> Result<bool> {
        let first = std::mem::replace(&mut self.first, false);
        if opcode == op::CHUNK && at.is_some() {
            // Chunks hold messages, schemas and channels only; nesting would recurse.
            return Err(self.bad("corrupt MCAP chunk: a chunk record inside a chunk"));
        }
        if opcode == op::MESSAGE {
            // channel id u16, sequence u32, log time u64, publish time u64, then the payload.
            if bytes.len() < 22 {
                return Err(self.bad("corrupt MCAP record: message shorter than its header"));
            }
            let channel = u16::from_le_bytes([bytes[0], bytes[1]]);
            let mut log = [0u8; 8];
            log.copy_from_slice(&bytes[6..14]);
            let info = self
                .channels
                .get(&channel)
                .ok_or_else(|| self.bad(format!("message on unknown channel {channel}")))?;
            // A message outside chunks (unchunked files) is copied to be shareable.
            let owned;
            let (chunk, start) = match at {
                Some(a) => a,
                None => {
                    owned = Arc::new(bytes.to_vec());
                    (&owned, 0)
                }
            };
            let payload = Payload::Ready(chunk, start + 22..start + bytes.len());
            return on_message(info, u64::from_le_bytes(log), payload, &self.metadata);
        }
        if !matches!(
            opcode,
            op::HEADER | op::SCHEMA | op::CHANNEL | op::METADATA | op::CHUNK
        ) {
            return Ok(true);
        }
        let record = mcap::parse_record(opcode, bytes)
            .map_err(|e| self.bad(format!("corrupt MCAP record: {e}")))?;
        match record {
            Record::Header(h) if first && h.profile != "ros2" => {
                return Err(self.bad(format!("MCAP profile is '{}', expected 'ros2'", h.profile)));
            }
            Record::Schema { header, .. } => {
                self.schemas.insert(header.id, ros2_type_name(&header.name));
            }
            Record::Channel(c) => {
                let message_type = self.schemas.get(&c.schema_id).cloned().unwrap_or_default();
                if c.message_encoding != "cdr" && crate::source::is_read(&message_type) {
                    return Err(self.bad(format!(
                        "channel {} has message encoding '{}', expected 'cdr'",
                        c.topic, c.message_encoding
                    )));
                }
                let info = TopicInfo {
                    topic: c.topic,
                    message_type,
                    count: None,
                };
                self.channels.insert(c.id, info);
            }
            Record::Metadata(m) => {
                self.metadata.insert(m.name, m.metadata);
            }
            Record::Chunk { header, data } => {
                let n = usize::try_from(header.uncompressed_size)
                    .map_err(|_| self.bad("corrupt MCAP chunk: too large"))?;
                let crc = header.uncompressed_crc;
                return self.chunk(&header.compression, crc, &data, n, on_message);
            }
            _ => {}
        }
        Ok(true)
    }

    /// A chunk of `n` bytes of records, compressed as `compression` in `data`, whose records
    /// have CRC-32 `crc` (0: none recorded).
    fn chunk(
        &mut self,
        compression: &str,
        crc: u32,
        data: &[u8],
        n: usize,
        on_message: &mut OnMessage<'_>,
    ) -> Result<bool> {
        // LZ4 expands at most 255×; a larger claim (or any beyond 1 GiB) is corrupt, and is
        // refused before allocating for it.
        let limit = match compression {
            "lz4" => data.len().saturating_mul(255),
            "" => data.len(),
            _ => MAX_CHUNK,
        };
        if n > limit.min(MAX_CHUNK) {
            return Err(self.bad(format!(
                "corrupt MCAP chunk: {n} bytes of records claimed from {} compressed bytes",
                data.len()
            )));
        }
        let mut chunk = self.buffers.take(n);
        let out = Arc::get_mut(&mut chunk)
            .and_then(|v| v.get_mut(..n))
            .ok_or_else(|| self.bad("chunk buffer unavailable"))?;
        let path = self.path;
        let corrupt = |e: String| Error::input(path, format!("corrupt MCAP chunk: {e}"));
        let (wrote, tail) = match compression {
            "" => {
                let k = data.len().min(n);
                out[..k].copy_from_slice(&data[..k]);
                (data.len(), None)
            }
            "lz4" => lz4_records(data, out).map_err(corrupt)?,
            "zstd" => (
                zstd::bulk::decompress_to_buffer(data, out)
                    .map_err(|e| corrupt(format!("zstd: {e}")))?,
                None,
            ),
            other => return Err(self.bad(format!("unsupported chunk compression '{other}'"))),
        };
        let end = tail.as_ref().map_or(n, |(at, _)| *at);
        if wrote < end || (tail.is_none() && wrote != n) {
            return Err(corrupt(format!(
                "{wrote} bytes of records, its header says {n}"
            )));
        }
        self.buffers.give_back(&chunk);
        // The CRC covers all `n` bytes: checked now, or for a chunk whose last message is left
        // compressed, over the bytes decoded so far now and the rest when (if) it is decoded.
        let mut crc_state = None;
        if crc != 0 {
            let mut hasher = crc32fast::Hasher::new();
            hasher.update(chunk.get(..wrote.min(n)).unwrap_or_default());
            if tail.is_some() {
                crc_state = Some(hasher);
            } else {
                let computed = hasher.finalize();
                if computed != crc {
                    return Err(corrupt(crc_mismatch(computed, crc)));
                }
            }
        }
        if !self.chunk_records(&chunk, end, on_message)? {
            return Ok(false);
        }
        let Some((at, mut tail)) = tail else {
            return Ok(true);
        };
        if let Some(hasher) = crc_state {
            tail.check_crc(hasher, crc);
        }
        // The deferred message: its record header and message header are in the prefix.
        let Some(head) = chunk.get(at..at + 9 + 22) else {
            return Err(corrupt("truncated record".into()));
        };
        let (opcode, channel) = (head[0], u16::from_le_bytes([head[9], head[10]]));
        let mut log = [0u8; 8];
        log.copy_from_slice(&head[15..23]);
        let info = self
            .channels
            .get(&channel)
            .ok_or_else(|| self.bad(format!("message on unknown channel {channel}")))?;
        debug_assert_eq!(opcode, op::MESSAGE);
        let tail = Arc::new(tail);
        on_message(
            info,
            u64::from_le_bytes(log),
            Payload::Deferred(&tail),
            &self.metadata,
        )
    }

    /// The records of a decompressed chunk (its first `n` bytes).
    fn chunk_records(
        &mut self,
        chunk: &Arc<Vec<u8>>,
        n: usize,
        on_message: &mut OnMessage<'_>,
    ) -> Result<bool> {
        let mut at = 0;
        while at < n {
            let (opcode, end) = record_at(chunk, at, n)
                .ok_or_else(|| self.bad("corrupt MCAP chunk: record runs past the chunk"))?;
            let body = chunk.get(at + 9..end).unwrap_or_default();
            if !self.record(opcode, body, Some((chunk, at + 9)), on_message)? {
                return Ok(false);
            }
            at = end;
        }
        Ok(true)
    }
}

/// (opcode, end) of the record at `at` of `buf[..n]`.
pub(super) fn record_at(buf: &[u8], at: usize, n: usize) -> Option<(u8, usize)> {
    let head = buf.get(at..at + 9).filter(|_| at + 9 <= n)?;
    let mut len = [0u8; 8];
    len.copy_from_slice(&head[1..9]);
    let end = usize::try_from(u64::from_le_bytes(len))
        .ok()
        .and_then(|l| (at + 9).checked_add(l))
        .filter(|&e| e <= n)?;
    Some((head[0], end))
}

/// Decodes an LZ4 chunk's records into `out`, except a large last message, which is left
/// compressed once its first [`PREFIX`] bytes are out. Returns the bytes decoded and, for a
/// deferred message, where its record starts and the rest of it.
fn lz4_records(
    src: &[u8],
    out: &mut [u8],
) -> std::result::Result<(usize, Option<(usize, Tail)>), String> {
    let n = out.len();
    let mut decoder = Decoder::default();
    let (mut pos, mut at) = (0, 0);
    while at < n {
        pos = decoder.decode(src, out, pos, (at + 9).min(n))?;
        // Short input or a bad record length: the caller reports too few bytes.
        let Some((opcode, end)) = record_at(out, at, n).filter(|_| pos >= at + 9) else {
            break;
        };
        if end == n && opcode == op::MESSAGE && end - at >= DEFER_MIN && pos < end {
            let payload = at + 9 + 22;
            pos = decoder.decode(src, out, pos, payload + PREFIX)?;
            // Deferred only once the prefix is out: input that ends before it is truncated
            // (and is reported as too few bytes below).
            if pos >= payload + PREFIX && pos < end {
                let tail = Tail::defer(&decoder, src, out, pos, payload..end);
                return Ok((pos, Some((at, tail))));
            }
        }
        pos = decoder.decode(src, out, pos, end)?;
        if pos < end {
            break;
        }
        at = end;
    }
    Ok((pos.min(at), None))
}
