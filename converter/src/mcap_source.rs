//! MCAP input: our recorder's episodes and any ros2-profile MCAP (rosbag2's mcap storage too).

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Error, Result};
use crate::source::{ros2_type_name, RawMessage, Recording, Serialization, TopicInfo};

/// Reads an MCAP file: its ros2 topics, the messages of the topics `want` accepts (sorted by log
/// time), and its metadata records. Rejects other profiles, non-`cdr` channels of wanted topics,
/// and files that are truncated or corrupt (with the reason, naming the file).
pub fn read_mcap(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    let bytes = std::fs::read(path).map_err(Error::io(path))?;
    let bad = |reason: String| Error::input(path, reason);
    let header = mcap_header(&bytes).map_err(|e| bad(format!("not an MCAP file: {e}")))?;
    if header != "ros2" {
        return Err(bad(format!("MCAP profile is '{header}', expected 'ros2'")));
    }
    let summary = mcap::Summary::read(&bytes)
        .map_err(|e| {
            bad(format!(
                "truncated or corrupt MCAP ({e}); try `scaledp recover`"
            ))
        })?
        .ok_or_else(|| {
            bad("MCAP has no summary section (unfinished?); try `scaledp recover`".into())
        })?;
    let mut topics: BTreeMap<u16, TopicInfo> = BTreeMap::new();
    for (id, ch) in &summary.channels {
        let message_type = ch
            .schema
            .as_ref()
            .map(|s| ros2_type_name(&s.name))
            .unwrap_or_default();
        let count = summary
            .stats
            .as_ref()
            .and_then(|s| s.channel_message_counts.get(id).copied());
        let info = TopicInfo {
            topic: ch.topic.clone(),
            message_type,
            count,
        };
        if want(&info) && ch.message_encoding != "cdr" {
            return Err(bad(format!(
                "channel {} has message encoding '{}', expected 'cdr'",
                ch.topic, ch.message_encoding
            )));
        }
        topics.insert(*id, info);
    }
    let mut messages = Vec::new();
    for m in mcap::MessageStream::new(&bytes).map_err(|e| bad(e.to_string()))? {
        let m = m.map_err(|e| bad(format!("corrupt MCAP data: {e}")))?;
        let Some(info) = topics.get(&m.channel.id) else {
            continue;
        };
        if !want(info) {
            continue;
        }
        messages.push(RawMessage {
            topic: info.topic.clone(),
            message_type: info.message_type.clone(),
            log_time_ns: m.log_time,
            data: m.data.into_owned(),
            serialization: Serialization::Cdr,
        });
    }
    messages.sort_by_key(|m| m.log_time_ns);
    let mut metadata = BTreeMap::new();
    for idx in &summary.metadata_indexes {
        let md = mcap::read::metadata(&bytes, idx)
            .map_err(|e| bad(format!("metadata '{}': {e}", idx.name)))?;
        metadata.insert(md.name, md.metadata);
    }
    let mut topics: Vec<TopicInfo> = topics.into_values().collect();
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    topics.dedup_by(|a, b| a.topic == b.topic);
    Ok(Recording {
        topics,
        messages,
        metadata,
    })
}

/// The profile in the MCAP header record.
fn mcap_header(bytes: &[u8]) -> std::result::Result<String, String> {
    let mut r =
        mcap::read::LinearReader::sans_magic(bytes.get(8..).ok_or("shorter than the magic")?);
    if bytes.get(..8) != Some(mcap::MAGIC) {
        return Err("no MCAP magic".into());
    }
    match r.next() {
        Some(Ok(mcap::records::Record::Header(h))) => Ok(h.profile),
        Some(Ok(_)) => Err("first record is not a header".into()),
        Some(Err(e)) => Err(e.to_string()),
        None => Err("empty".into()),
    }
}
