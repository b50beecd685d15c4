//! Settings of a recording session (`start`, in `session`, opens it).

use std::path::PathBuf;
use std::time::Duration;

use scaledp_schema::msg::MsgSearch;
use scaledp_schema::rig::Rig;

use crate::disk::{DiskOptions, FreeSpace};
use crate::episode::{Compression, EpisodeOptions};
use crate::patterns::TopicPattern;

/// Settings of a recording session; `start` opens it.
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    pub(crate) rig: Rig,
    pub(crate) out_dir: PathBuf,
    pub(crate) task: String,
    pub(crate) tasks: Vec<String>,
    pub(crate) operator: String,
    pub(crate) episode: EpisodeOptions,
    pub(crate) queue_bytes: usize,
    pub(crate) flush_interval: Duration,
    pub(crate) control_prefix: String,
    pub(crate) bridge_namespace: String,
    pub(crate) patterns: Vec<TopicPattern>,
    pub(crate) msg_search: MsgSearch,
    pub(crate) check_topics: bool,
    pub(crate) disk: DiskOptions,
}

impl RecorderOptions {
    /// Records every topic of `rig` into `out_dir`. Defaults: LZ4 chunks of 8 MiB, a 1 GiB
    /// queue, a flush every 500 ms, control on `scaledp/recorder/control`, no bridge namespace,
    /// no further topics, only scaledp's own message definitions, starts whatever the topics do
    /// (their state is noted in the episode), the disk guard on (statvfs, episodes assumed as
    /// long as the longest so far, a warning below 5 minutes of room).
    pub fn new(rig: Rig, out_dir: impl Into<PathBuf>) -> Self {
        Self {
            rig,
            out_dir: out_dir.into(),
            task: String::new(),
            tasks: Vec::new(),
            operator: String::new(),
            episode: EpisodeOptions::new(),
            queue_bytes: 1 << 30,
            flush_interval: Duration::from_millis(500),
            control_prefix: "scaledp/recorder".into(),
            bridge_namespace: String::new(),
            patterns: Vec::new(),
            msg_search: MsgSearch::new(),
            check_topics: false,
            disk: DiskOptions::default(),
        }
    }
    /// The task instruction stored with every episode, e.g. "put the cup on the plate".
    pub fn task(mut self, task: impl Into<String>) -> Self {
        self.task = task.into();
        self
    }
    /// Several tasks for the session: the first is recorded first, [`crate::Command::NextTask`]
    /// moves on to the next (after the last, the first again).
    pub fn tasks<S: Into<String>>(mut self, tasks: impl IntoIterator<Item = S>) -> Self {
        self.tasks = tasks.into_iter().map(Into::into).collect();
        if let Some(first) = self.tasks.first() {
            self.task.clone_from(first);
        }
        self
    }
    /// Who teleoperated.
    pub fn operator(mut self, operator: impl Into<String>) -> Self {
        self.operator = operator.into();
        self
    }
    /// Chunk compression.
    pub fn compression(mut self, c: Compression) -> Self {
        self.episode = self.episode.compression(c);
        self
    }
    /// Target chunk size (bytes).
    pub fn chunk_size(mut self, bytes: u64) -> Self {
        self.episode = self.episode.chunk_size(bytes);
        self
    }
    /// Most payload bytes waiting for the writer before new messages are dropped (and counted).
    pub fn queue_bytes(mut self, bytes: usize) -> Self {
        self.queue_bytes = bytes.max(1);
        self
    }
    /// How often the open chunk is closed and handed to the OS (at most 1 s).
    pub fn flush_interval(mut self, every: Duration) -> Self {
        self.flush_interval = every.clamp(Duration::from_millis(10), Duration::from_secs(1));
        self
    }
    /// Key prefix for `<prefix>/control` (commands in) and `<prefix>/status` (events out).
    pub fn control_prefix(mut self, prefix: impl Into<String>) -> Self {
        self.control_prefix = prefix.into().trim_matches('/').to_string();
        self
    }
    /// Namespace zenoh-bridge-ros2dds was started with (`-n`), if any.
    pub fn bridge_namespace(mut self, ns: impl Into<String>) -> Self {
        self.bridge_namespace = ns.into();
        self
    }
    /// Also records the topics `pattern` matches (a glob, or a name whose type comes from its
    /// rmw_zenoh key or the bridge's announcement), each as a channel of its own from its first
    /// message on. Rig topics are recorded once, as rig topics. (A concrete `NAME:TYPE` is
    /// better added to the rig's further topics: it is then part of the stored rig.)
    pub fn topic_pattern(mut self, pattern: TopicPattern) -> Self {
        self.patterns.push(pattern);
        self
    }
    /// Where definitions of types scaledp does not know are looked up (`AMENT_PREFIX_PATH`,
    /// `--msg-path`).
    pub fn msg_search(mut self, search: MsgSearch) -> Self {
        self.msg_search = search;
        self
    }
    /// Refuse a [`crate::Command::Start`] while a rig topic is missing or slow (see
    /// [`crate::Liveness`]); [`crate::Command::ForceStart`] starts anyway. Off by default:
    /// unattended sessions start and note what was missing in the episode.
    pub fn check_topics(mut self, yes: bool) -> Self {
        self.check_topics = yes;
        self
    }
    /// The disk guard (on by default): refuse to start an episode the output disk has no room
    /// for, and end one before the disk is full.
    pub fn disk_guard(mut self, on: bool) -> Self {
        self.disk.enabled = on;
        self
    }
    /// The length of the session's episodes (s), what the disk guard makes room for (default:
    /// the longest episode so far, 60 s before the first).
    pub fn episode_time(mut self, seconds: Option<f64>) -> Self {
        self.disk.episode_s = seconds.filter(|s| *s > 0.0);
        self
    }
    /// Warn when the output disk holds less than this many minutes of recording (default 5).
    pub fn disk_warn_minutes(mut self, minutes: f64) -> Self {
        self.disk.warn_minutes = minutes.max(0.0);
        self
    }
    /// Where the disk guard gets the free space from (a test's full disk).
    pub fn free_space(mut self, free: FreeSpace) -> Self {
        self.disk.free_space = free;
        self
    }
}
