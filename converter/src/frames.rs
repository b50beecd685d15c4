//! Where camera frames come from during a conversion. Alignment needs every frame's stamp but
//! only the frames it picks are decoded. An MCAP recording is read once: its small messages and
//! every frame's stamp are kept, and the frames the conversion will pick (see
//! [`crate::prefetch`]) are decoded, resized and encoded in parallel as they stream past, so a
//! multi-GB raw-image episode never sits in memory; a frame that guess missed is fetched by a
//! second read. Bags are read into memory once and served from there.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use crate::encode_pool::{encode_while, Encodings, FrameJob};
use crate::error::{Error, Result};
use crate::images::{encode_message, EncodeSpec, EncodedFrame};
use crate::mcap_remote::RemoteMcap;
use crate::mcap_stream::{stream, stream_hashed, Payload};
use crate::options::ConvertOptions;
use crate::prefetch::Selector;
use crate::source::{RawMessage, Recording, Serialization, TopicInfo};
use crate::video::{is_video, Transcoder, IMAGE};

pub use crate::encode_pool::FrameKey;

/// Stamps of a camera topic's frames and access to the frames themselves.
pub trait FrameStore: Sync {
    /// (header stamp in ns or 0 when unreadable, log time in ns) of every frame of `topic`, in
    /// stored order; a frame's position in this list is its ordinal.
    fn stamps(&self, topic: &str) -> Vec<(u64, u64)>;
    /// The `wanted` frames (stored ordinals per topic) of the input `path`, each decoded, resized
    /// and JPEG-encoded per `spec`, in parallel.
    fn encode(
        &self,
        path: &Path,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        spec: &EncodeSpec,
    ) -> Result<HashMap<FrameKey, EncodedFrame>>;
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

/// Whether a message type is a camera frame.
pub(crate) fn is_image(message_type: &str) -> bool {
    matches!(
        message_type,
        "sensor_msgs/msg/Image" | "sensor_msgs/msg/CompressedImage"
    )
}

/// A message after [`transcode`].
enum Transcoded {
    /// Not a video frame: read as it is.
    Pass,
    /// A video frame that gives no picture: not one of its topic's frames.
    Dropped,
    /// A video frame's picture: the topic as a raw image topic, and the image message (CDR).
    Picture(TopicInfo, Arc<Vec<u8>>),
}

/// Decodes a video topic's frame to a raw image message (see [`crate::video`]).
fn transcode(
    path: &Path,
    video: &mut Transcoder,
    topic: &TopicInfo,
    log_time_ns: u64,
    payload: &Payload<'_>,
) -> Result<Transcoded> {
    if !is_video(&topic.message_type) {
        return Ok(Transcoded::Pass);
    }
    let decoded = payload
        .share()
        .with(|data| video.frame(path, &topic.topic, log_time_ns, data))
        .map_err(|e| Error::input(path, format!("corrupt MCAP chunk: {e}")))??;
    Ok(match decoded {
        Some(cdr) => Transcoded::Picture(
            TopicInfo {
                message_type: IMAGE.into(),
                ..topic.clone()
            },
            Arc::new(cdr),
        ),
        None => Transcoded::Dropped,
    })
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
    fn encode(
        &self,
        path: &Path,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        spec: &EncodeSpec,
    ) -> Result<HashMap<FrameKey, EncodedFrame>> {
        let mut ordinal: BTreeMap<&str, usize> = BTreeMap::new();
        let mut jobs = Vec::new();
        for m in &self.0.messages {
            let Some(set) = wanted.get(&m.topic) else {
                continue;
            };
            let o = ordinal.entry(&m.topic).or_default();
            if set.contains(o) {
                jobs.push((*o, m));
            }
            *o += 1;
        }
        // Collected in order before the first error is taken, so a recording with several
        // bad frames always names the earliest.
        let each: Vec<Result<(FrameKey, EncodedFrame)>> = jobs
            .into_par_iter()
            .map(|(o, m)| {
                let e = encode_message(
                    path,
                    &m.topic,
                    &m.message_type,
                    m.log_time_ns,
                    m.serialization,
                    &m.data,
                    spec,
                )?;
                Ok(((m.topic.clone(), o), e))
            })
            .collect();
        each.into_iter().collect()
    }
}

/// Where an MCAP recording is read from.
pub(crate) enum McapSource {
    /// A local file.
    File(PathBuf),
    /// An object, read by range (see [`crate::mcap_remote`]).
    Object(Arc<RemoteMcap>),
}

/// An MCAP file's frame stamps, the frames encoded during the first read, and the file to read
/// the others from.
pub struct McapFrames {
    source: McapSource,
    stamps: BTreeMap<String, Vec<(u64, u64)>>,
    /// Per topic, the message types counted as its frames on the first read (wanted images):
    /// a second read counts the same messages, so ordinals agree.
    frame_types: BTreeMap<String, BTreeSet<String>>,
    /// Camera topics recorded as video (decoded from their start on every read).
    video_topics: BTreeSet<String>,
    /// Frames encoded during the first read, per `spec`.
    ready: Mutex<Encodings>,
    spec: Option<EncodeSpec>,
    /// Frames fetched by a second read so far (a diagnostic).
    read_again: std::sync::atomic::AtomicUsize,
}

impl McapFrames {
    /// Whether a message of `topic` is one of the frames [`FrameStore::stamps`] lists.
    fn is_frame(&self, topic: &TopicInfo) -> bool {
        self.frame_types
            .get(&topic.topic)
            .is_some_and(|types| types.contains(&topic.message_type))
    }

    /// Frames encoded during the first read and not taken yet (a diagnostic).
    pub fn prefetched(&self) -> usize {
        self.ready.lock().map_or(0, |r| r.len())
    }

    /// Frames the first read missed, fetched by reading the file again (a diagnostic).
    pub fn read_again(&self) -> usize {
        self.read_again.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl FrameStore for McapFrames {
    fn stamps(&self, topic: &str) -> Vec<(u64, u64)> {
        self.stamps.get(topic).cloned().unwrap_or_default()
    }
    fn encode(
        &self,
        path: &Path,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        spec: &EncodeSpec,
    ) -> Result<HashMap<FrameKey, EncodedFrame>> {
        let mut out = HashMap::new();
        let mut missing: BTreeMap<String, BTreeSet<usize>> = BTreeMap::new();
        {
            let mut ready = self.ready.lock().unwrap_or_else(|p| p.into_inner());
            tracing::debug!(
                "{}: {} frames encoded on the first read",
                path.display(),
                ready.len()
            );
            let usable = self.spec.as_ref() == Some(spec);
            for (topic, set) in wanted {
                for &o in set {
                    let key = (topic.clone(), o);
                    match ready.remove(&key).filter(|_| usable) {
                        Some(r) => {
                            out.insert(key, r?);
                        }
                        None => {
                            missing.entry(topic.clone()).or_default().insert(o);
                        }
                    }
                }
            }
        }
        let mut left: usize = missing.values().map(BTreeSet::len).sum();
        tracing::debug!(
            "{}: {} frames used of those encoded on the first read, {left} to read again",
            path.display(),
            out.len()
        );
        if left == 0 {
            return Ok(out);
        }
        self.read_again
            .fetch_add(left, std::sync::atomic::Ordering::Relaxed);
        let mut ordinal: BTreeMap<String, usize> = BTreeMap::new();
        let video_missing = missing.keys().any(|t| self.video_topics.contains(t));
        let (read, done) = encode_while(path, spec, |submit| {
            if let (McapSource::Object(remote), false) = (&self.source, video_missing) {
                return self.read_remote_again(remote, &missing, left, submit);
            }
            let mut video = Transcoder::default();
            let mut again = |topic: &TopicInfo, log_time_ns, payload: Payload<'_>, _: &_| {
                if !missing.contains_key(&topic.topic) {
                    return Ok(true);
                }
                let picture;
                let (topic, payload) =
                    match transcode(path, &mut video, topic, log_time_ns, &payload)? {
                        Transcoded::Pass => (topic, payload),
                        Transcoded::Dropped => return Ok(true),
                        Transcoded::Picture(t, bytes) => {
                            picture = (t, bytes);
                            (&picture.0, Payload::Ready(&picture.1, 0..picture.1.len()))
                        }
                    };
                let Some(set) = missing.get(&topic.topic).filter(|_| self.is_frame(topic)) else {
                    return Ok(true);
                };
                let o = ordinal.entry(topic.topic.clone()).or_default();
                if set.contains(o) {
                    submit(FrameJob {
                        key: (topic.topic.clone(), *o),
                        message_type: topic.message_type.clone(),
                        log_time_ns,
                        bytes: payload.share(),
                    });
                    left -= 1;
                }
                *o += 1;
                Ok(left > 0)
            };
            match &self.source {
                McapSource::File(path) => stream(path, &mut again).map(drop),
                // Video frames decode from their topic's start: the whole object again.
                McapSource::Object(remote) => remote.stream(None, &mut again).map(drop),
            }
        });
        read?;
        for (key, r) in done {
            out.insert(key, r?);
        }
        Ok(out)
    }
}

impl McapFrames {
    /// The second read of an object: only the chunks holding the `missing` frames (`left` of
    /// them), each frame found by its topic, log time and place among that topic's frames
    /// logged at the same time (ordinals cannot be counted in a partial read).
    fn read_remote_again(
        &self,
        remote: &RemoteMcap,
        missing: &BTreeMap<String, BTreeSet<usize>>,
        mut left: usize,
        submit: &mut dyn FnMut(FrameJob),
    ) -> Result<()> {
        let mut by_log: HashMap<(String, u64, usize), usize> = HashMap::new();
        let mut logs: BTreeMap<String, BTreeSet<u64>> = BTreeMap::new();
        for (topic, set) in missing {
            let mut seen: HashMap<u64, usize> = HashMap::new();
            for (o, (_, log)) in self.stamps(topic).into_iter().enumerate() {
                let occurrence = seen.entry(log).or_default();
                if set.contains(&o) {
                    by_log.insert((topic.clone(), log, *occurrence), o);
                    logs.entry(topic.clone()).or_default().insert(log);
                }
                *occurrence += 1;
            }
        }
        let mut occurrences: HashMap<(String, u64), usize> = HashMap::new();
        remote.stream_again(&logs, &mut |topic, log_time_ns, payload, _| {
            let wanted = logs
                .get(&topic.topic)
                .is_some_and(|l| l.contains(&log_time_ns));
            if !wanted || !self.is_frame(topic) {
                return Ok(true);
            }
            let k = occurrences
                .entry((topic.topic.clone(), log_time_ns))
                .or_default();
            if let Some(&o) = by_log.get(&(topic.topic.clone(), log_time_ns, *k)) {
                submit(FrameJob {
                    key: (topic.topic.clone(), o),
                    message_type: topic.message_type.clone(),
                    log_time_ns,
                    bytes: payload.share(),
                });
                left = left.saturating_sub(1);
            }
            *k += 1;
            Ok(left > 0)
        })
    }
}

/// Reads an MCAP file once: every wanted non-image message in full, the first message of each
/// image topic in full (for rig detection), and the stamps of all image messages. With
/// `prefetch`, the frames a conversion with those options will pick are encoded on the way.
pub fn read_mcap_light(
    path: &Path,
    want: &(dyn Fn(&TopicInfo) -> bool + Sync),
    prefetch: Option<&ConvertOptions>,
) -> Result<(Recording, McapFrames)> {
    read_mcap_hashed(path, want, prefetch, None)
}

/// [`read_mcap_light`], feeding the file's bytes to `hasher` on the way.
pub(crate) fn read_mcap_hashed(
    path: &Path,
    want: &(dyn Fn(&TopicInfo) -> bool + Sync),
    prefetch: Option<&ConvertOptions>,
    hasher: Option<&mut blake3::Hasher>,
) -> Result<(Recording, McapFrames)> {
    let source = McapSource::File(path.into());
    read_mcap_from(path, source, want, prefetch, hasher)
}

/// [`read_mcap_hashed`] of a recording in a local file or in object storage (named `path`).
pub(crate) fn read_mcap_from(
    path: &Path,
    source: McapSource,
    want: &(dyn Fn(&TopicInfo) -> bool + Sync),
    prefetch: Option<&ConvertOptions>,
    hasher: Option<&mut blake3::Hasher>,
) -> Result<(Recording, McapFrames)> {
    let spec = prefetch.map(ConvertOptions::encode_spec);
    let mut selector = prefetch.map(Selector::new);
    let mut messages = Vec::new();
    let mut stamps: BTreeMap<String, Vec<(u64, u64)>> = BTreeMap::new();
    let mut frame_types: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut video_topics = BTreeSet::new();
    let read = |submit: &mut dyn FnMut(FrameJob)| {
        let mut video = Transcoder::default();
        let mut on_message = |t: &TopicInfo, log_time_ns, payload: Payload<'_>, metadata: &_| {
            if !want(t) {
                return Ok(true);
            }
            let picture;
            let (t, payload) = match transcode(path, &mut video, t, log_time_ns, &payload)? {
                Transcoded::Pass => (t, payload),
                Transcoded::Dropped => return Ok(true),
                Transcoded::Picture(topic, bytes) => {
                    video_topics.insert(t.topic.clone());
                    picture = (topic, bytes);
                    (&picture.0, Payload::Ready(&picture.1, 0..picture.1.len()))
                }
            };
            let header =
                scaledp_schema::msg::header_stamp(payload.prefix()).map_or(0, |s| s.as_ns());
            let data = || -> Result<Vec<u8>> {
                payload
                    .share()
                    .with(<[u8]>::to_vec)
                    .map_err(|e| Error::input(path, format!("corrupt MCAP chunk: {e}")))
            };
            let m = RawMessage {
                topic: t.topic.clone(),
                message_type: t.message_type.clone(),
                log_time_ns,
                data: Vec::new(),
                serialization: Serialization::Cdr,
            };
            let mut ordinal = None;
            if is_image(&t.message_type) {
                if !frame_types
                    .get(&t.topic)
                    .is_some_and(|s| s.contains(&t.message_type))
                {
                    let types = frame_types.entry(t.topic.clone()).or_default();
                    types.insert(t.message_type.clone());
                }
                let list = stamps.entry(t.topic.clone()).or_default();
                if list.is_empty() {
                    messages.push(RawMessage { data: data()?, ..m });
                }
                ordinal = Some(list.len());
                list.push((header, log_time_ns));
            } else {
                messages.push(RawMessage { data: data()?, ..m });
            }
            if let Some(s) = &mut selector {
                s.message(
                    path,
                    t,
                    ordinal,
                    header,
                    log_time_ns,
                    &payload,
                    metadata,
                    submit,
                );
            }
            Ok(true)
        };
        let r = match &source {
            McapSource::File(file) => stream_hashed(file, hasher, &mut on_message),
            McapSource::Object(remote) => remote.stream(hasher, &mut on_message),
        };
        if let (Ok(_), Some(s)) = (&r, &mut selector) {
            s.finish(submit);
        }
        video.warn_dropped(path);
        r
    };
    let (read, ready) = match &spec {
        Some(spec) => encode_while(path, spec, read),
        None => (read(&mut |_| {}), HashMap::new()),
    };
    let (topics, metadata) = read?;
    messages.sort_by_key(|m| m.log_time_ns);
    let topics = topics.into_iter().filter(|t| want(t)).collect();
    Ok((
        Recording {
            topics,
            messages,
            metadata,
        },
        McapFrames {
            source,
            stamps,
            frame_types,
            video_topics,
            ready: Mutex::new(ready),
            spec,
            read_again: Default::default(),
        },
    ))
}
