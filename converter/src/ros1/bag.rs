//! The ROS 1 bag format 2.0 container, read through its index one chunk at a time.
//!
//! The record parser is hand-written on purpose. The one Rust crate for the format, `rosbag`
//! (0.6.3, last release May 2024), memory-maps the whole file (`unsafe`; a bag truncated while
//! mapped is a SIGBUS), links the C lz4 library and bzip2 0.4's C backend, and decompresses
//! chunks without a cap (`Vec::with_capacity` of the header's `size`, an unbounded `io::copy` for
//! lz4), so a hostile bag can make it allocate gigabytes. The format is small (seven record types
//! of `name=value` header fields), so a few hundred bounded lines are the safer dependency.
//!
//! Every length is checked against what remains (of the file, the record or the decompressed
//! chunk) before anything is allocated or read; a malformed or truncated bag is an
//! [`Error::Input`] naming the file, the offset and the problem.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use super::record::{self, ChunkInfo, Connection, Fields};
use super::record::{OP_BAG_HEADER, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION};
use crate::error::{Error, Result};
use crate::source::{RawMessage, Recording, Serialization, TopicInfo};

const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
/// Record headers are a handful of short fields (connection data, which carries the message
/// definition, is record data). Anything larger is corruption.
const MAX_HEADER_LEN: u32 = 1 << 20;
/// Initial capacity cap of a decompressed chunk (the buffer grows with the data produced).
const PREALLOC_CAP: usize = 64 << 20;

/// Reads a ROS 1 bag (format 2.0): its topics (types rewritten to ROS 2 form, counts from the
/// index) and the messages of the topics `want` accepts, sorted by log time (the record's
/// `time`), with [`Serialization::Ros1`] payloads.
///
/// Only chunks that hold a wanted topic are read and decompressed (none, bz2 or lz4), one at a
/// time. The bag must be indexed: an unfinished recording (index position 0) or a truncated file
/// is an error that suggests `rosbag reindex`, never a silently shorter recording; the messages
/// per connection of every chunk read are checked against the index.
pub fn read_ros1_bag(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    let file = File::open(path).map_err(Error::io(path))?;
    let len = file.metadata().map_err(Error::io(path))?.len();
    let mut bag = BagFile {
        path,
        file: BufReader::new(file),
        len,
        pos: 0,
    };
    bag.check_magic()?;
    let (at, header, data_len) = bag
        .next_record()?
        .ok_or_else(|| bag.bad(13, "no bag header"))?;
    let (index_pos, conn_count, chunk_count) = bag_header(&header).map_err(|e| bag.bad(at, e))?;
    bag.skip(data_len)?;
    let chunks_start = bag.pos;
    if index_pos == 0 {
        return Err(bag.bad(
            at,
            "bag has no index (recording not closed?); run `rosbag reindex`",
        ));
    }
    if index_pos < chunks_start || index_pos > len {
        let msg = format!("index position {index_pos} is outside the file ({len} bytes)");
        return Err(bag.bad(at, format!("{msg}: truncated? run `rosbag reindex`")));
    }
    let (connections, chunk_infos) = bag.read_index(index_pos)?;
    if connections.len() != conn_count as usize || chunk_infos.len() != chunk_count as usize {
        return Err(bag.bad(
            index_pos,
            format!(
                "index has {} connections and {} chunk infos, the bag header says {conn_count} \
                 and {chunk_count}: truncated?",
                connections.len(),
                chunk_infos.len()
            ),
        ));
    }

    // Topics: a topic may have several connections (publishers); its type is the first one's.
    let mut totals: BTreeMap<u32, u64> = BTreeMap::new();
    for (conn, n) in chunk_infos.iter().flat_map(|c| &c.counts) {
        *totals.entry(*conn).or_default() += u64::from(*n);
    }
    let mut topics: BTreeMap<&str, TopicInfo> = BTreeMap::new();
    for (id, c) in &connections {
        let n = totals.get(id).copied().unwrap_or(0);
        let info = topics.entry(&c.topic).or_insert_with(|| TopicInfo {
            topic: c.topic.clone(),
            message_type: c.message_type.clone(),
            count: Some(0),
        });
        info.count = info.count.map(|total| total + n);
    }
    let wanted_topics: BTreeSet<&str> = topics
        .values()
        .filter(|t| want(t))
        .map(|t| t.topic.as_str())
        .collect();
    let wanted: BTreeSet<u32> = connections
        .iter()
        .filter(|(_, c)| wanted_topics.contains(c.topic.as_str()))
        .map(|(id, _)| *id)
        .collect();

    let mut chunks: Vec<&ChunkInfo> = chunk_infos
        .iter()
        .filter(|c| c.counts.keys().any(|k| wanted.contains(k)))
        .collect();
    chunks.sort_by_key(|c| c.chunk_pos);
    let mut messages = Vec::new();
    for info in chunks {
        if info.chunk_pos < chunks_start || info.chunk_pos >= index_pos {
            let msg = format!(
                "chunk position {} is outside the chunk section",
                info.chunk_pos
            );
            return Err(bag.bad(info.at, msg));
        }
        let data = bag.read_chunk(info.chunk_pos, index_pos)?;
        let mut seen: BTreeMap<u32, u32> = BTreeMap::new();
        record::parse_chunk(&data, |conn, log_time_ns, payload| {
            let c = connections
                .get(&conn)
                .ok_or(format!("message of unknown connection {conn}"))?;
            *seen.entry(conn).or_default() += 1;
            if wanted.contains(&conn) {
                messages.push(RawMessage {
                    topic: c.topic.clone(),
                    message_type: c.message_type.clone(),
                    log_time_ns,
                    data: payload.to_vec(),
                    serialization: Serialization::Ros1,
                });
            }
            Ok(())
        })
        .map_err(|e| bag.bad(info.chunk_pos, e))?;
        if seen != info.counts {
            let msg = format!(
                "messages per connection {seen:?}, the index says {:?}",
                info.counts
            );
            return Err(bag.bad(info.chunk_pos, msg));
        }
    }
    messages.sort_by_key(|m| m.log_time_ns);
    let topics = topics.into_values().collect();
    Ok(Recording {
        topics,
        messages,
        metadata: BTreeMap::new(),
    })
}

/// The bag header record's `index_pos`, `conn_count` and `chunk_count`.
fn bag_header(header: &[u8]) -> std::result::Result<(u64, u32, u32), String> {
    let f = Fields::parse(header)?;
    if f.op()? != OP_BAG_HEADER {
        return Err("first record is not a bag header".into());
    }
    Ok((
        f.u64("index_pos")?,
        f.u32("conn_count")?,
        f.u32("chunk_count")?,
    ))
}

/// The bag file with the read position tracked; every length is checked against the file size.
struct BagFile<'p> {
    path: &'p Path,
    file: BufReader<File>,
    len: u64,
    pos: u64,
}

impl BagFile<'_> {
    fn bad(&self, offset: u64, reason: impl std::fmt::Display) -> Error {
        Error::input(self.path, format!("ROS 1 bag, offset {offset}: {reason}"))
    }

    fn check_magic(&mut self) -> Result<()> {
        let mut magic = [0u8; 13];
        let n = self.len.min(13) as usize;
        self.read_exact(&mut magic[..n])?;
        if magic[..n] == *MAGIC {
            return Ok(());
        }
        let reason = if magic.starts_with(b"#ROSBAG V") {
            let line = magic.split(|&b| b == b'\n').next().unwrap_or_default();
            let line = String::from_utf8_lossy(line);
            format!("unsupported bag version '{line}' (only 2.0 is read)")
        } else if n < 13 && magic[..n] == MAGIC[..n] {
            format!("file is only {n} bytes: truncated")
        } else {
            "not a ROS 1 bag (no '#ROSBAG V2.0' magic)".into()
        };
        Err(Error::input(self.path, reason))
    }

    fn read_exact(&mut self, buf: &mut [u8]) -> Result<()> {
        self.file.read_exact(buf).map_err(Error::io(self.path))?;
        self.pos += buf.len() as u64;
        Ok(())
    }

    fn seek(&mut self, pos: u64) -> Result<()> {
        self.file
            .seek(SeekFrom::Start(pos))
            .map_err(Error::io(self.path))?;
        self.pos = pos;
        Ok(())
    }

    fn skip(&mut self, n: u32) -> Result<()> {
        self.file
            .seek_relative(i64::from(n))
            .map_err(Error::io(self.path))?;
        self.pos += u64::from(n);
        Ok(())
    }

    /// A `u32` length of `what` at the current position, checked against the bytes left after it.
    fn read_len(&mut self, record_at: u64, what: &str) -> Result<u32> {
        let left = self.len - self.pos;
        if left < 4 {
            let msg = format!("file ends inside the {what} length ({left} bytes left): truncated");
            return Err(self.bad(record_at, msg));
        }
        let mut b = [0u8; 4];
        self.read_exact(&mut b)?;
        let n = u32::from_le_bytes(b);
        let left = self.len - self.pos;
        if u64::from(n) > left {
            let msg = format!("{what} length {n} exceeds the {left} bytes left: truncated?");
            return Err(self.bad(record_at, msg));
        }
        Ok(n)
    }

    /// The record at the current position: its offset, its header, and the length of its data
    /// (next in the file, for the caller to read or skip). `None` at the end of the file.
    fn next_record(&mut self) -> Result<Option<(u64, Vec<u8>, u32)>> {
        let at = self.pos;
        if at == self.len {
            return Ok(None);
        }
        let header_len = self.read_len(at, "record header")?;
        if header_len > MAX_HEADER_LEN {
            return Err(self.bad(at, format!("record header length {header_len} is absurd")));
        }
        let header = self.read_data(header_len)?;
        let data_len = self.read_len(at, "record data")?;
        Ok(Some((at, header, data_len)))
    }

    /// `n` bytes, which `read_len` checked are in the file.
    fn read_data(&mut self, n: u32) -> Result<Vec<u8>> {
        let mut data = vec![0u8; n as usize];
        self.read_exact(&mut data)?;
        Ok(data)
    }

    /// The index section: connection and chunk info records up to the end of the file.
    fn read_index(
        &mut self,
        index_pos: u64,
    ) -> Result<(BTreeMap<u32, Connection>, Vec<ChunkInfo>)> {
        self.seek(index_pos)?;
        let (mut connections, mut chunks) = (BTreeMap::new(), Vec::new());
        while let Some((at, header, data_len)) = self.next_record()? {
            let data = self.read_data(data_len)?;
            let step = Fields::parse(&header).and_then(|f| match f.op()? {
                OP_CONNECTION => record::connection(&f, &data).map(|(id, c)| {
                    connections.insert(id, c);
                }),
                OP_CHUNK_INFO => record::chunk_info(at, &f, &data).map(|c| chunks.push(c)),
                op => Err(format!(
                    "unexpected record op {op:#04x} in the index section"
                )),
            });
            step.map_err(|e| self.bad(at, e))?;
        }
        Ok((connections, chunks))
    }

    /// The chunk record at `pos` (which must end by `end`), decompressed: exactly the `size`
    /// bytes its header announces, never more.
    fn read_chunk(&mut self, pos: u64, end: u64) -> Result<Vec<u8>> {
        self.seek(pos)?;
        let (at, header, data_len) = self
            .next_record()?
            .ok_or_else(|| self.bad(pos, "no chunk"))?;
        let fields = Fields::parse(&header).map_err(|e| self.bad(at, e))?;
        let chunk = |f: &Fields<'_>| -> std::result::Result<(u32, String), String> {
            match f.op()? {
                OP_CHUNK => Ok((f.u32("size")?, f.string("compression")?)),
                _ => Err("chunk info points at a record that is not a chunk".into()),
            }
        };
        let (size, compression) = chunk(&fields).map_err(|e| self.bad(at, e))?;
        if self.pos + u64::from(data_len) > end {
            return Err(self.bad(at, "chunk runs into the index section"));
        }
        let raw = self.read_data(data_len)?;
        let out = match compression.as_str() {
            "none" => Ok(raw),
            "bz2" => decompress(bzip2::read::BzDecoder::new(&raw[..]), size),
            "lz4" => decompress(lz4_flex::frame::FrameDecoder::new(&raw[..]), size),
            other => return Err(self.bad(at, format!("unsupported chunk compression '{other}'"))),
        }
        .map_err(|e| self.bad(at, format!("{compression} chunk: {e}")))?;
        if out.len() != size as usize {
            let msg = format!(
                "{compression} chunk holds {} bytes, its header says {size}",
                out.len()
            );
            return Err(self.bad(at, msg));
        }
        Ok(out)
    }
}

/// Decompresses at most `size + 1` bytes (one more to notice a chunk longer than announced); the
/// buffer grows with the data actually produced, so a lying `size` cannot allocate much.
fn decompress(r: impl Read, size: u32) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::with_capacity((size as usize).min(PREALLOC_CAP));
    r.take(u64::from(size) + 1).read_to_end(&mut out)?;
    Ok(out)
}
