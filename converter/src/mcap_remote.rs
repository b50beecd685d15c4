//! A recording in object storage, read through ranged GETs instead of a download. Its summary
//! (footer, then the summary section: schemas, channels, chunk and metadata indexes) comes
//! first, in one GET of the object's tail in nearly every file; with it the episode's metadata
//! records are fetched alone (so an episode recorded as `failure` or `discarded` is skipped
//! without reading its chunks), and the frames a first read did not encode are fetched by
//! reading only the chunks the chunk index says hold them. The first read itself streams every
//! byte front to back through prefetched ranged GETs ([`scaledp_store::ObjectReader`]): the
//! conversion uses nearly every chunk of an interleaved recording, and the content hash that
//! resuming relies on covers every byte. A file without a summary (unindexed, or cut short) is
//! read front to back both times.

use std::collections::{BTreeMap, BTreeSet};
use std::io::SeekFrom;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::{op, Record};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use scaledp_store::{Bucket, ObjectInfo, ObjectReader};

use crate::error::{Error, Result};
use crate::mcap_stream::{stream_chunks, stream_from, Metadata, OnMessage, Payload};
use crate::source::{ros2_type_name, TopicInfo};

/// Bytes of the object's tail fetched first: the footer and the summary of a recording of a few
/// minutes (a longer one's summary is one more GET).
const TAIL_BYTES: u64 = 64 << 10;
/// Largest summary section or metadata record accepted (a corrupt length is refused before
/// anything is allocated for it).
const MAX_SUMMARY_BYTES: usize = 256 << 20;
/// Largest chunk record fetched by range (1 GiB of records, compressed, plus its header).
const MAX_CHUNK_RECORD: u64 = (1 << 30) + (1 << 24);
/// Chunks fetched at once by a second read.
const CHUNKS_AT_ONCE: usize = 8;

/// An MCAP object and, when it has one, its summary.
pub(crate) struct RemoteMcap {
    name: PathBuf,
    bucket: Arc<Bucket>,
    info: ObjectInfo,
    summary: Option<mcap::Summary>,
}

impl RemoteMcap {
    /// Opens the object `info` of `bucket` and reads its summary.
    pub fn open(bucket: Arc<Bucket>, info: ObjectInfo) -> Result<Self> {
        let name = info.url.as_path();
        let summary = read_summary(&name, &bucket, &info)?;
        Ok(Self {
            name,
            bucket,
            info,
            summary,
        })
    }

    /// Its metadata records, fetched alone through the metadata index; None without a summary.
    pub fn metadata(&self) -> Result<Option<Metadata>> {
        let Some(summary) = &self.summary else {
            return Ok(None);
        };
        let ranges = summary
            .metadata_indexes
            .iter()
            .map(|m| self.checked(m.offset, m.length, MAX_SUMMARY_BYTES as u64))
            .collect::<Result<Vec<_>>>()?;
        let records = self.fetch(&ranges)?;
        let mut out = Metadata::new();
        for bytes in records {
            let bad = || Error::input(&self.name, "corrupt MCAP metadata index");
            let body = (bytes.first() == Some(&op::METADATA))
                .then(|| bytes.get(9..))
                .flatten()
                .ok_or_else(bad)?;
            match mcap::parse_record(op::METADATA, body) {
                Ok(Record::Metadata(m)) => {
                    out.insert(m.name, m.metadata);
                }
                _ => return Err(bad()),
            }
        }
        Ok(Some(out))
    }

    /// Streams the whole object front to back (see [`crate::mcap_stream::stream`]), feeding
    /// every byte to `hasher`.
    pub fn stream(
        &self,
        hasher: Option<&mut blake3::Hasher>,
        on_message: &mut OnMessage<'_>,
    ) -> Result<(Vec<TopicInfo>, Metadata)> {
        let reader = ObjectReader::new(self.bucket.clone(), self.info.clone())
            .map_err(|e| Error::input(&self.name, e.reason()))?;
        stream_from(&self.name, reader, self.info.size, hasher, on_message)
    }

    /// Reads the messages of the chunks that may hold a message of a topic of `wanted` at one
    /// of its log times (ns), in file order, calling `on_message` until it returns false; the
    /// whole object again when there is no chunk index.
    pub fn stream_again(
        &self,
        wanted: &BTreeMap<String, BTreeSet<u64>>,
        on_message: &mut OnMessage<'_>,
    ) -> Result<()> {
        let Some(summary) = self
            .summary
            .as_ref()
            .filter(|s| !s.chunk_indexes.is_empty())
        else {
            return self.stream(None, on_message).map(drop);
        };
        let schemas: BTreeMap<u16, String> = summary
            .schemas
            .iter()
            .map(|(id, s)| (*id, ros2_type_name(&s.name)))
            .collect();
        let channels: BTreeMap<u16, TopicInfo> = summary
            .channels
            .iter()
            .map(|(id, c)| {
                let message_type = c
                    .schema
                    .as_ref()
                    .map_or(String::new(), |s| ros2_type_name(&s.name));
                let info = TopicInfo {
                    topic: c.topic.clone(),
                    message_type,
                    count: None,
                };
                (*id, info)
            })
            .collect();
        let holds = |channel: &u16, start: u64, end: u64| {
            channels
                .get(channel)
                .and_then(|c| wanted.get(&c.topic))
                .is_some_and(|logs| logs.range(start..=end).next().is_some())
        };
        let mut chunks: Vec<&mcap::records::ChunkIndex> = summary
            .chunk_indexes
            .iter()
            .filter(|c| {
                let (a, b) = (c.message_start_time, c.message_end_time);
                // A chunk written without message indexes may hold any channel.
                c.message_index_offsets.is_empty()
                    || c.message_index_offsets.keys().any(|ch| holds(ch, a, b))
            })
            .collect();
        chunks.sort_by_key(|c| c.chunk_start_offset);
        let ranges = chunks
            .iter()
            .map(|c| self.checked(c.chunk_start_offset, c.chunk_length, MAX_CHUNK_RECORD))
            .collect::<Result<Vec<_>>>()?;
        tracing::debug!(
            "{}: reading {} of {} chunks again",
            self.name.display(),
            ranges.len(),
            summary.chunk_indexes.len()
        );
        let go_on = std::cell::Cell::new(true);
        let mut guard = |t: &TopicInfo, log: u64, p: Payload<'_>, m: &Metadata| {
            go_on.set(on_message(t, log, p, m)?);
            Ok(go_on.get())
        };
        for group in ranges.chunks(CHUNKS_AT_ONCE) {
            let fetched = self.fetch(group)?;
            let mut it = fetched.into_iter().map(Ok);
            stream_chunks(
                &self.name,
                schemas.clone(),
                channels.clone(),
                &mut it,
                &mut guard,
            )?;
            if !go_on.get() {
                break;
            }
        }
        Ok(())
    }

    /// `offset..offset + length`, refused when it leaves the object or exceeds `max`.
    fn checked(&self, offset: u64, length: u64, max: u64) -> Result<std::ops::Range<u64>> {
        match offset.checked_add(length) {
            Some(end) if end <= self.info.size && length <= max && length >= 9 => Ok(offset..end),
            _ => Err(Error::input(
                &self.name,
                format!(
                    "corrupt MCAP index: {length} bytes at {offset} do not fit in the {} bytes \
                     of the file",
                    self.info.size
                ),
            )),
        }
    }

    fn fetch(&self, ranges: &[std::ops::Range<u64>]) -> Result<Vec<bytes::Bytes>> {
        self.bucket
            .get_ranges(&self.info, ranges)
            .map_err(|e| Error::input(&self.name, e.reason()))
    }
}

/// The summary of the object (None when it has none: unindexed, or cut short).
fn read_summary(name: &Path, bucket: &Bucket, info: &ObjectInfo) -> Result<Option<mcap::Summary>> {
    let size = info.size;
    let tail_start = size.saturating_sub(TAIL_BYTES);
    let tail = bucket
        .get_range(info, tail_start..size)
        .map_err(|e| Error::input(name, e.reason()))?;
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(size)
            .with_record_length_limit(MAX_SUMMARY_BYTES),
    );
    let mut pos = 0u64;
    while let Some(event) = reader.next_event() {
        let event = match event {
            Ok(e) => e,
            Err(e) => {
                // No usable summary: the linear read decides whether the file is good.
                tracing::debug!("{}: no summary ({e})", name.display());
                return Ok(None);
            }
        };
        match event {
            SummaryReadEvent::SeekRequest(to) => {
                pos = match to {
                    SeekFrom::Start(p) => p,
                    SeekFrom::End(d) => size.saturating_add_signed(d),
                    SeekFrom::Current(d) => pos.saturating_add_signed(d),
                }
                .min(size);
                reader.notify_seeked(pos);
            }
            SummaryReadEvent::ReadRequest(n) => {
                let end = (pos + n as u64).min(size);
                let got = if pos >= tail_start {
                    let at = (pos - tail_start) as usize;
                    tail.slice(at..(end - tail_start) as usize)
                } else {
                    bucket
                        .get_range(info, pos..end)
                        .map_err(|e| Error::input(name, e.reason()))?
                };
                let buf = reader.insert(n);
                buf[..got.len()].copy_from_slice(&got);
                reader.notify_read(got.len());
                pos = end;
            }
        }
    }
    Ok(reader.finish())
}
