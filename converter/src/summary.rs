//! A local MCAP file's summary, read alone (the footer, the summary section, and the records it
//! indexes: a few kilobytes of a file of any size): its metadata records, for reading an
//! episode's label ahead of converting it, and its per-topic message counts, for checking a
//! recording without reading its chunks (`scaledp bench record`).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

use mcap::records::{op, Record};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};

use crate::error::{Error, Result};
use crate::mcap_stream::Metadata;

/// Largest summary section or metadata record read.
const MAX_RECORD_BYTES: usize = 64 << 20;

/// The summary of the MCAP file open as `file`; None without one (unindexed, cut short).
fn read_summary(file: &mut File) -> std::io::Result<Option<mcap::Summary>> {
    let size = file.metadata()?.len();
    let mut reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(size)
            .with_record_length_limit(MAX_RECORD_BYTES),
    );
    while let Some(event) = reader.next_event() {
        let Ok(event) = event else {
            return Ok(None);
        };
        match event {
            SummaryReadEvent::SeekRequest(to) => {
                let pos = file.seek(to)?;
                reader.notify_seeked(pos);
            }
            SummaryReadEvent::ReadRequest(n) => {
                let got = file.read(reader.insert(n))?;
                reader.notify_read(got);
            }
        }
    }
    Ok(reader.finish())
}

/// The metadata records of the MCAP file `path`, through its summary; None without one.
pub(crate) fn local_metadata(path: &Path) -> std::io::Result<Option<Metadata>> {
    let mut file = File::open(path)?;
    let Some(summary) = read_summary(&mut file)? else {
        return Ok(None);
    };
    let mut out = Metadata::new();
    for index in &summary.metadata_indexes {
        let length = usize::try_from(index.length)
            .ok()
            .filter(|&l| l <= MAX_RECORD_BYTES && l > 9);
        let Some(length) = length else {
            return Ok(None);
        };
        let mut bytes = vec![0u8; length];
        file.seek(SeekFrom::Start(index.offset))?;
        file.read_exact(&mut bytes)?;
        if bytes[0] != op::METADATA {
            return Ok(None);
        }
        match mcap::parse_record(op::METADATA, &bytes[9..]) {
            Ok(Record::Metadata(m)) => {
                out.insert(m.name, m.metadata);
            }
            _ => return Ok(None),
        }
    }
    Ok(Some(out))
}

/// What the summary of a finished MCAP file says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct McapSummary {
    /// Messages per topic (from the statistics record), topics without messages included.
    pub messages: BTreeMap<String, u64>,
    /// Chunks the chunk index lists.
    pub chunks: usize,
    /// Names of the metadata records.
    pub metadata: Vec<String>,
}

/// The summary of the finished MCAP file `path` (its statistics, chunk index and metadata
/// index), read without its chunks; an error naming the file when it has none or no
/// statistics.
pub fn mcap_summary(path: &Path) -> Result<McapSummary> {
    let mut file = File::open(path).map_err(Error::io(path))?;
    let summary = read_summary(&mut file)
        .map_err(Error::io(path))?
        .ok_or_else(|| Error::input(path, "no MCAP summary (cut short, or unindexed)"))?;
    let stats = summary
        .stats
        .as_ref()
        .ok_or_else(|| Error::input(path, "no statistics record in the MCAP summary"))?;
    let mut messages: BTreeMap<String, u64> = summary
        .channels
        .values()
        .map(|c| (c.topic.clone(), 0))
        .collect();
    for (id, n) in &stats.channel_message_counts {
        let channel = summary.channels.get(id).ok_or_else(|| {
            Error::input(
                path,
                format!("statistics count channel {id}, which is not in the summary"),
            )
        })?;
        *messages.entry(channel.topic.clone()).or_default() += n;
    }
    Ok(McapSummary {
        messages,
        chunks: summary.chunk_indexes.len(),
        metadata: summary
            .metadata_indexes
            .iter()
            .map(|m| m.name.clone())
            .collect(),
    })
}
