//! Where camera frames come from during a conversion. Alignment needs every frame's stamp but
//! only the frames it picks are decoded: an MCAP recording is read twice (stamps first, then
//! only the chosen frames, streamed in bounded batches), so a multi-GB raw-image episode never
//! sits in memory. Bags are read into memory once and served from there.

use std::collections::{BTreeMap, BTreeSet};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::error::{Error, Result};
use crate::source::{ros2_type_name, RawMessage, Recording, Serialization, TopicInfo};

/// Stamps of a camera topic's frames and access to the frames themselves.
pub trait FrameStore: Sync {
    /// (header stamp in ns or 0 when unreadable, log time in ns) of every frame of `topic`, in
    /// stored order; a frame's position in this list is its ordinal.
    fn stamps(&self, topic: &str) -> Vec<(u64, u64)>;
    /// Calls `f(topic, ordinal, message)` for every wanted frame, in stored order.
    fn fetch(
        &self,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        f: &mut dyn FnMut(&str, usize, RawMessage) -> Result<()>,
    ) -> Result<()>;
}

/// Header stamp of an image message of either serialization (0 when unreadable).
fn header_ns(m: &RawMessage) -> u64 {
    match m.serialization {
        Serialization::Cdr => scaledp_schema::msg::header_stamp(&m.data).map_or(0, |t| t.as_ns()),
        // ROS 1 Header: seq (u32), then stamp sec, nsec (u32 each).
        Serialization::Ros1 => match (m.data.get(4..8), m.data.get(8..12)) {
            (Some(s), Some(n)) => {
                let sec = u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as u64;
                let nsec = u32::from_le_bytes([n[0], n[1], n[2], n[3]]) as u64;
                sec * 1_000_000_000 + nsec
            }
            _ => 0,
        },
    }
}

fn is_image(message_type: &str) -> bool {
    matches!(
        message_type,
        "sensor_msgs/msg/Image" | "sensor_msgs/msg/CompressedImage"
    )
}

/// Frames of a recording already in memory.
pub struct InMemory<'a>(pub &'a Recording);

impl FrameStore for InMemory<'_> {
    fn stamps(&self, topic: &str) -> Vec<(u64, u64)> {
        self.0
            .messages
            .iter()
            .filter(|m| m.topic == topic)
            .map(|m| (header_ns(m), m.log_time_ns))
            .collect()
    }
    fn fetch(
        &self,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        f: &mut dyn FnMut(&str, usize, RawMessage) -> Result<()>,
    ) -> Result<()> {
        let mut ordinal: BTreeMap<&str, usize> = BTreeMap::new();
        for m in &self.0.messages {
            let Some(set) = wanted.get(&m.topic) else {
                continue;
            };
            let o = ordinal.entry(&m.topic).or_default();
            if set.contains(o) {
                f(&m.topic, *o, m.clone())?;
            }
            *o += 1;
        }
        Ok(())
    }
}

/// An MCAP file's frames, read on demand.
pub struct McapFrames {
    path: PathBuf,
    stamps: BTreeMap<String, Vec<(u64, u64)>>,
}

impl FrameStore for McapFrames {
    fn stamps(&self, topic: &str) -> Vec<(u64, u64)> {
        self.stamps.get(topic).cloned().unwrap_or_default()
    }
    fn fetch(
        &self,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        f: &mut dyn FnMut(&str, usize, RawMessage) -> Result<()>,
    ) -> Result<()> {
        let mut ordinal: BTreeMap<String, usize> = BTreeMap::new();
        stream(
            &self.path,
            &mut |topic: &TopicInfo, log_time_ns, data: &[u8]| {
                let Some(set) = wanted.get(&topic.topic) else {
                    return Ok(());
                };
                let o = ordinal.entry(topic.topic.clone()).or_default();
                let r = if set.contains(o) {
                    let m = RawMessage {
                        topic: topic.topic.clone(),
                        message_type: topic.message_type.clone(),
                        log_time_ns,
                        data: data.to_vec(),
                        serialization: Serialization::Cdr,
                    };
                    f(&topic.topic, *o, m)
                } else {
                    Ok(())
                };
                *o += 1;
                r
            },
        )
        .map(drop)
    }
}

/// A callback taking (topic, log time in ns, payload).
type OnMessage<'a> = dyn FnMut(&TopicInfo, u64, &[u8]) -> Result<()> + 'a;
/// Metadata records by name.
type Metadata = BTreeMap<String, BTreeMap<String, String>>;

/// Streams an MCAP file record by record, calling `on_message` for each message; returns the
/// topics and metadata. Checks the `ros2` profile, `cdr` encodings and the end of the file.
fn stream(path: &Path, on_message: &mut OnMessage<'_>) -> Result<(Vec<TopicInfo>, Metadata)> {
    let bad = |reason: String| Error::input(path, reason);
    let mut src = BufReader::with_capacity(1 << 20, File::open(path).map_err(Error::io(path))?);
    let mut reader =
        LinearReader::new_with_options(LinearReaderOptions::default().with_emit_chunks(false));
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
    let mut channels: BTreeMap<u16, TopicInfo> = BTreeMap::new();
    let mut metadata = BTreeMap::new();
    let mut first = true;
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| {
            bad(format!(
                "truncated or corrupt MCAP ({e}); try `scaledp recover`"
            ))
        })? {
            LinearReadEvent::ReadRequest(n) => {
                let got = src.read(reader.insert(n)).map_err(Error::io(path))?;
                reader.notify_read(got);
            }
            LinearReadEvent::Record { data, opcode } => {
                let record = mcap::parse_record(opcode, data)
                    .map_err(|e| bad(format!("corrupt MCAP record: {e}")))?;
                match record {
                    Record::Header(h) if first && h.profile != "ros2" => {
                        return Err(bad(format!(
                            "MCAP profile is '{}', expected 'ros2'",
                            h.profile
                        )));
                    }
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, ros2_type_name(&header.name));
                    }
                    Record::Channel(c) => {
                        let message_type = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                        if c.message_encoding != "cdr" && is_image(&message_type) {
                            return Err(bad(format!(
                                "channel {} has message encoding '{}', expected 'cdr'",
                                c.topic, c.message_encoding
                            )));
                        }
                        channels.insert(
                            c.id,
                            TopicInfo {
                                topic: c.topic,
                                message_type,
                                count: None,
                            },
                        );
                    }
                    Record::Message { header, data } => {
                        let info = channels.get(&header.channel_id).ok_or_else(|| {
                            bad(format!("message on unknown channel {}", header.channel_id))
                        })?;
                        on_message(info, header.log_time, &data)?;
                    }
                    Record::Metadata(m) => {
                        metadata.insert(m.name, m.metadata);
                    }
                    _ => {}
                }
                first = false;
            }
        }
    }
    let mut topics: Vec<TopicInfo> = channels.into_values().collect();
    topics.sort_by(|a, b| a.topic.cmp(&b.topic));
    topics.dedup_by(|a, b| a.topic == b.topic);
    Ok((topics, metadata))
}

/// First pass over an MCAP file: every wanted non-image message in full, the first message of
/// each image topic in full (for rig detection), and the stamps of all image messages.
pub fn read_mcap_light(
    path: &Path,
    want: &dyn Fn(&TopicInfo) -> bool,
) -> Result<(Recording, McapFrames)> {
    let mut messages = Vec::new();
    let mut stamps: BTreeMap<String, Vec<(u64, u64)>> = BTreeMap::new();
    let (topics, metadata) = stream(path, &mut |t, log_time_ns, data| {
        if !want(t) {
            return Ok(());
        }
        let m = RawMessage {
            topic: t.topic.clone(),
            message_type: t.message_type.clone(),
            log_time_ns,
            data: Vec::new(),
            serialization: Serialization::Cdr,
        };
        if is_image(&t.message_type) {
            let list = stamps.entry(t.topic.clone()).or_default();
            let header = scaledp_schema::msg::header_stamp(data).map_or(0, |s| s.as_ns());
            if list.is_empty() {
                messages.push(RawMessage {
                    data: data.to_vec(),
                    ..m
                });
            }
            list.push((header, log_time_ns));
        } else {
            messages.push(RawMessage {
                data: data.to_vec(),
                ..m
            });
        }
        Ok(())
    })?;
    messages.sort_by_key(|m| m.log_time_ns);
    let topics = topics.into_iter().filter(|t| want(t)).collect();
    Ok((
        Recording {
            topics,
            messages,
            metadata,
        },
        McapFrames {
            path: path.into(),
            stamps,
        },
    ))
}
