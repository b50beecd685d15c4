//! MCAP input read whole: our recorder's episodes and any ros2-profile MCAP (rosbag2's mcap
//! storage too), through the same bounded streaming reader a batch job uses
//! ([`crate::mcap_stream`]). (The `mcap` crate's own reader allocates whatever a chunk header
//! claims: a corrupt uncompressed size aborts the process.)

use std::collections::BTreeMap;
use std::path::Path;

use crate::error::{Error, Result};
use crate::source::{RawMessage, Recording, Serialization, TopicInfo};

/// Reads an MCAP file: its ros2 topics (with their message counts), the messages of the topics
/// `want` accepts (sorted by log time), and its metadata records. Rejects other profiles,
/// non-`cdr` channels of the message types the converter reads, and files that are truncated
/// or corrupt (with the reason, naming the file).
pub fn read_mcap(path: &Path, want: &dyn Fn(&TopicInfo) -> bool) -> Result<Recording> {
    let mut messages = Vec::new();
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let (topics, metadata) =
        crate::mcap_stream::stream(path, &mut |t, log_time_ns, payload, _| {
            *counts.entry(t.topic.clone()).or_default() += 1;
            if want(t) {
                let data = payload
                    .share()
                    .with(<[u8]>::to_vec)
                    .map_err(|e| Error::input(path, format!("corrupt MCAP chunk: {e}")))?;
                messages.push(RawMessage {
                    topic: t.topic.clone(),
                    message_type: t.message_type.clone(),
                    log_time_ns,
                    data,
                    serialization: Serialization::Cdr,
                });
            }
            Ok(true)
        })?;
    messages.sort_by_key(|m| m.log_time_ns);
    let topics = topics
        .into_iter()
        .map(|t| TopicInfo {
            count: Some(counts.get(&t.topic).copied().unwrap_or(0)),
            ..t
        })
        .collect();
    Ok(Recording {
        topics,
        messages,
        metadata,
    })
}
