//! What a session reports: live figures per topic, and what happened to each episode.

use std::path::PathBuf;
use std::time::Instant;

use crate::control::Label;
use crate::episode::EpisodeSummary;

/// Live figures for one topic, counted since the session opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicStatus {
    /// ROS 2 topic.
    pub topic: String,
    /// Messages received (recording or not).
    pub received: u64,
    /// Payload bytes received.
    pub bytes: u64,
    /// Messages dropped because the writer queue was full.
    pub dropped: u64,
    /// Messages a publisher sent that never arrived (rmw_zenoh sequence gaps).
    pub upstream_gaps: u64,
}

/// A snapshot of the session.
#[derive(Debug, Clone)]
pub struct Status {
    /// The open episode's index and when it started.
    pub episode: Option<(u64, Instant)>,
    /// Per-topic figures: the rig's topics in rig order, then those `--topic` patterns found.
    pub topics: Vec<TopicStatus>,
    /// Payload bytes waiting for the writer.
    pub queued_bytes: usize,
}

/// What happened to an episode.
#[derive(Debug, Clone)]
pub enum Event {
    /// A new episode file was opened.
    Started {
        /// Episode index.
        index: u64,
        /// The `.partial` file.
        path: PathBuf,
    },
    /// An episode was closed and renamed into place.
    Finished(EpisodeReport),
    /// Writing an episode failed; its `.partial` file is left for `scaledp recover`.
    Failed {
        /// Episode index.
        index: u64,
        /// What went wrong.
        error: String,
    },
}

/// A finished episode.
#[derive(Debug, Clone)]
pub struct EpisodeReport {
    /// Episode index.
    pub index: u64,
    /// How it ended.
    pub outcome: Label,
    /// Duration from start to stop (s).
    pub duration_s: f64,
    /// Files, messages and bytes.
    pub summary: EpisodeSummary,
    /// Per topic: messages dropped by the queue during the episode, sorted by topic.
    pub dropped: std::collections::BTreeMap<String, u64>,
    /// Per topic: upstream sequence gaps during the episode, sorted by topic.
    pub upstream_gaps: std::collections::BTreeMap<String, u64>,
    /// Per latched topic: the messages kept from before the episode, written at its start.
    pub latched_at_start: std::collections::BTreeMap<String, u64>,
    /// Times every Zenoh link was lost during the episode (a bridge or peer restarting).
    pub link_outages: u64,
    /// Seconds without any link during the episode.
    pub link_outage_s: f64,
    /// What the recorder noticed, one line each, naming the topic (depth in an undeclared
    /// encoding, a `camera_info` of another size, a latched topic with nothing to write).
    pub warnings: Vec<String>,
}
