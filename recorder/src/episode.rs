//! One episode as one ROS 2-profile MCAP file, written as `*.partial` and renamed when finished.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use scaledp_schema::rig::TopicSpec;

use crate::error::{Error, Result};

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// No compression: the least CPU, the largest files.
    None,
    /// LZ4: fast, the default.
    #[default]
    Lz4,
    /// Zstandard (level 1): smaller files, more CPU.
    Zstd,
}

impl std::str::FromStr for Compression {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "none" => Ok(Self::None),
            "lz4" => Ok(Self::Lz4),
            "zstd" => Ok(Self::Zstd),
            _ => Err(format!("unknown compression '{s}' (none, lz4, zstd)")),
        }
    }
}

/// QoS rosbag2 records for a reliable, volatile, keep-last subscriber (what camera and joint
/// state publishers offer); readers such as `ros2 bag play` use it to re-publish.
pub const OFFERED_QOS_YAML: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n  avoid_ros_namespace_conventions: false\n";

/// QoS rosbag2 records for a transient-local ("latched") publisher such as tf2's
/// `/tf_static`: reliable, transient local, so `ros2 bag play` re-publishes it latched.
pub const OFFERED_QOS_LATCHED_YAML: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n  avoid_ros_namespace_conventions: false\n";

/// One channel of an episode file: a topic, its type and the `ros2msg` schema text written for
/// it.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelSpec {
    /// ROS 2 topic.
    pub topic: String,
    /// Full ROS 2 type; `None` when nobody could tell (a schemaless channel).
    pub message_type: Option<String>,
    /// The schema text; empty when the type's definition was found nowhere (readers that need
    /// it cannot decode the channel, the bytes are kept all the same).
    pub definition: String,
    /// Transient-local: its `offered_qos_profiles` say so.
    pub latched: bool,
}

impl ChannelSpec {
    /// A rig topic whose type scaledp knows; [`Error::UnknownType`] otherwise.
    pub fn known(t: &TopicSpec) -> Result<Self> {
        let definition =
            scaledp_schema::msg::definition(&t.message_type).ok_or_else(|| Error::UnknownType {
                topic: t.topic.clone(),
                message_type: t.message_type.clone(),
            })?;
        Ok(Self {
            topic: t.topic.clone(),
            message_type: Some(t.message_type.clone()),
            definition,
            latched: t.latched,
        })
    }
}

/// Options of an episode file. Defaults: LZ4 chunks of 8 MiB.
#[derive(Debug, Clone)]
pub struct EpisodeOptions {
    compression: Compression,
    chunk_size: u64,
}

impl Default for EpisodeOptions {
    fn default() -> Self {
        Self {
            compression: Compression::Lz4,
            chunk_size: 8 << 20,
        }
    }
}

impl EpisodeOptions {
    /// Default options.
    pub fn new() -> Self {
        Self::default()
    }
    /// Chunk compression.
    pub fn compression(mut self, c: Compression) -> Self {
        self.compression = c;
        self
    }
    /// Target uncompressed chunk size (bytes); a chunk is also closed by every flush.
    pub fn chunk_size(mut self, bytes: u64) -> Self {
        self.chunk_size = bytes.max(1 << 10);
        self
    }

    /// Creates `<path>.partial` with the header, schemas, channels and `start_metadata`
    /// (written as the `scaledp.episode.start` metadata record, so a crashed episode keeps it).
    /// Every topic's type must be one scaledp knows ([`Error::UnknownType`] names the first
    /// that is not); [`Self::create_channels`] takes schemas found elsewhere.
    pub fn create(
        &self,
        path: &Path,
        topics: &[TopicSpec],
        start_metadata: BTreeMap<String, String>,
    ) -> Result<EpisodeWriter> {
        let channels = topics
            .iter()
            .map(ChannelSpec::known)
            .collect::<Result<Vec<_>>>()?;
        self.create_channels(path, &channels, start_metadata)
    }

    /// [`Self::create`] with each channel's schema given.
    pub fn create_channels(
        &self,
        path: &Path,
        topics: &[ChannelSpec],
        start_metadata: BTreeMap<String, String>,
    ) -> Result<EpisodeWriter> {
        let partial = partial_path(path);
        let file = File::create(&partial).map_err(Error::io(&partial))?;
        self.start_file(path, partial.clone(), file, topics, start_metadata)
            .inspect_err(|_| {
                // Not one chunk of it is readable (a full disk refuses even the header): no
                // `.partial` is left for `recover` to trip over.
                let _ = std::fs::remove_file(&partial);
            })
    }

    fn start_file(
        &self,
        path: &Path,
        partial: PathBuf,
        file: File,
        topics: &[ChannelSpec],
        start_metadata: BTreeMap<String, String>,
    ) -> Result<EpisodeWriter> {
        let compression = match self.compression {
            Compression::None => None,
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::Zstd => Some(mcap::Compression::Zstd),
        };
        let mut writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("scaledp-recorder ", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .compression_level(1)
            .chunk_size(Some(self.chunk_size))
            .create(BufWriter::with_capacity(1 << 20, file))
            .map_err(Error::mcap(&partial))?;
        let mut channel_ids = Vec::with_capacity(topics.len());
        for t in topics {
            channel_ids.push(add_channel(&mut writer, t, &partial)?);
        }
        writer
            .write_metadata(&mcap::records::Metadata {
                name: scaledp_schema::episode::START_RECORD.into(),
                metadata: start_metadata,
            })
            .map_err(Error::mcap(&partial))?;
        writer.flush().map_err(Error::mcap(&partial))?;
        Ok(EpisodeWriter {
            path: path.to_path_buf(),
            partial,
            writer: Some(writer),
            channel_ids,
            messages: vec![0; topics.len()],
            bytes: vec![0; topics.len()],
            topics: topics.iter().map(|t| t.topic.clone()).collect(),
        })
    }
}

/// Adds `t`'s schema (none when its type is unknown) and channel.
fn add_channel(
    writer: &mut mcap::Writer<BufWriter<File>>,
    t: &ChannelSpec,
    partial: &Path,
) -> Result<u16> {
    let schema = match &t.message_type {
        Some(ty) => writer
            .add_schema(ty, "ros2msg", t.definition.as_bytes())
            .map_err(Error::mcap(partial))?,
        None => 0,
    };
    let qos = if t.latched {
        OFFERED_QOS_LATCHED_YAML
    } else {
        OFFERED_QOS_YAML
    };
    let meta = BTreeMap::from([("offered_qos_profiles".to_string(), qos.to_string())]);
    writer
        .add_channel(schema, &t.topic, "cdr", &meta)
        .map_err(Error::mcap(partial))
}

/// `episode_000001.mcap` → `episode_000001.mcap.partial`.
pub fn partial_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".partial");
    PathBuf::from(s)
}

/// An open episode file.
pub struct EpisodeWriter {
    path: PathBuf,
    partial: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channel_ids: Vec<u16>,
    messages: Vec<u64>,
    bytes: Vec<u64>,
    topics: Vec<String>,
}

/// What one finished episode file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeSummary {
    /// The finished file.
    pub path: PathBuf,
    /// Messages per topic, sorted by topic.
    pub messages: BTreeMap<String, u64>,
    /// Payload bytes per topic, sorted by topic.
    pub bytes: BTreeMap<String, u64>,
}

impl EpisodeWriter {
    /// The `.partial` file being written.
    pub fn partial_path(&self) -> &Path {
        &self.partial
    }

    /// Adds a channel to the open file (a topic first seen mid-episode); returns its topic
    /// number for [`Self::write`].
    pub fn add_channel(&mut self, t: &ChannelSpec) -> Result<usize> {
        let w = self.writer.as_mut().ok_or(Error::Stopped)?;
        let id = add_channel(w, t, &self.partial)?;
        self.channel_ids.push(id);
        self.messages.push(0);
        self.bytes.push(0);
        self.topics.push(t.topic.clone());
        Ok(self.channel_ids.len() - 1)
    }

    /// Appends one message of topic number `topic` (index into the `topics` given to `create`).
    pub fn write(
        &mut self,
        topic: usize,
        log_time_ns: u64,
        publish_time_ns: u64,
        data: &[u8],
    ) -> Result<()> {
        let w = self.writer.as_mut().ok_or(Error::Stopped)?;
        let header = mcap::records::MessageHeader {
            channel_id: self.channel_ids[topic],
            sequence: (self.messages[topic] + 1) as u32,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
        };
        w.write_to_known_channel(&header, data)
            .map_err(Error::mcap(&self.partial))?;
        self.messages[topic] += 1;
        self.bytes[topic] += data.len() as u64;
        Ok(())
    }

    /// Messages written so far per topic index.
    pub fn message_counts(&self) -> &[u64] {
        &self.messages
    }

    /// Closes the open chunk and hands it to the OS: a crash after this loses nothing before it.
    /// Fails when the file was removed meanwhile (its directory deleted): writes would go on
    /// into a file no one can open.
    pub fn flush(&mut self) -> Result<()> {
        let w = self.writer.as_mut().ok_or(Error::Stopped)?;
        w.flush().map_err(Error::mcap(&self.partial))?;
        match std::fs::metadata(&self.partial) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(Error::Io {
                path: self.partial.clone(),
                source: std::io::Error::new(
                    e.kind(),
                    format!("removed while being written (is its directory gone?): {e}"),
                ),
            }),
            _ => Ok(()),
        }
    }

    /// Writes a metadata record (e.g. the episode's verdict) before the end record.
    pub fn write_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<()> {
        let w = self.writer.as_mut().ok_or(Error::Stopped)?;
        w.write_metadata(&mcap::records::Metadata {
            name: name.into(),
            metadata,
        })
        .map_err(Error::mcap(&self.partial))
    }

    /// Writes `metadata` as the `scaledp.episode` record, the summary section and the end magic,
    /// syncs, and renames the file to `dest` (normally the path given to `create`).
    pub fn finish(
        mut self,
        metadata: BTreeMap<String, String>,
        dest: Option<&Path>,
    ) -> Result<EpisodeSummary> {
        let mut w = self.writer.take().ok_or(Error::Stopped)?;
        let partial = self.partial.clone();
        w.write_metadata(&mcap::records::Metadata {
            name: scaledp_schema::episode::END_RECORD.into(),
            metadata,
        })
        .map_err(Error::mcap(&partial))?;
        w.finish().map_err(Error::mcap(&partial))?;
        let file = w.into_inner().into_inner().map_err(|e| Error::Io {
            path: partial.clone(),
            source: e.into_error(),
        })?;
        file.sync_all().map_err(Error::io(&partial))?;
        let dest = dest.unwrap_or(&self.path).to_path_buf();
        if let Some(dir) = dest.parent() {
            std::fs::create_dir_all(dir).map_err(Error::io(dir))?;
        }
        std::fs::rename(&partial, &dest).map_err(Error::io(&dest))?;
        if let Some(dir) = dest.parent().and_then(|d| File::open(d).ok()) {
            // Make the rename itself durable; failure here loses nothing already written.
            let _ = dir.sync_all();
        }
        let by_topic = |v: &[u64]| self.topics.iter().cloned().zip(v.iter().copied()).collect();
        Ok(EpisodeSummary {
            path: dest,
            messages: by_topic(&self.messages),
            bytes: by_topic(&self.bytes),
        })
    }
}

impl Drop for EpisodeWriter {
    fn drop(&mut self) {
        // An unfinished episode stays a `.partial` file: flush what we have so `recover` finds it.
        if let Some(w) = self.writer.as_mut() {
            let _ = w.flush();
        }
    }
}
