//! What a session reports: live figures per topic, and what happened to each episode.

use std::path::PathBuf;
use std::time::Instant;

use crate::control::Label;
use crate::disk::DiskStatus;
use crate::episode::EpisodeSummary;
use crate::verdict::Verdict;

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
    /// The episode that ended and waits for a label, keep, discard or re-record.
    pub held: Option<u64>,
    /// The task of the episodes started from now on.
    pub task: String,
    /// The output disk as the guard last saw it (None with the guard off).
    pub disk: Option<DiskStatus>,
}

/// What happened to an episode.
// A few events per episode: their size does not matter, and a boxed report would only make
// every reader dereference it.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum Event {
    /// A new episode file was opened.
    Started {
        /// Episode index.
        index: u64,
        /// The `.partial` file.
        path: PathBuf,
    },
    /// An episode stopped recording and is held for a decision (see `Command::End`): its
    /// verdict.
    Ended {
        /// Episode index.
        index: u64,
        /// Whether convert would take it.
        verdict: Verdict,
    },
    /// An episode was closed and renamed into place.
    Finished(EpisodeReport),
    /// An episode finished earlier was moved to `discarded/` (a discard or re-record after it
    /// was labelled).
    Discarded {
        /// Episode index.
        index: u64,
        /// Where it is now.
        path: PathBuf,
    },
    /// A start was refused.
    Refused {
        /// The line saying why.
        reason: String,
        /// The topics missing or slow, one line each (empty for a refusal of the disk guard).
        problems: Vec<String>,
        /// Whether `Command::ForceStart` would start it (topics missing, not a full disk).
        force: bool,
    },
    /// The task of the episodes started from now on changed.
    Task(String),
    /// Less than the warning's minutes of recording are left on the output disk.
    DiskLow(String),
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
    /// Whether convert would take it, and the figures behind it.
    pub verdict: Verdict,
    /// Why the recorder ended it itself (the disk about to be full), if it did.
    pub cut: Option<String>,
    /// Topics missing or slow when it started (it was started anyway).
    pub started_with_missing_topics: Vec<String>,
    /// Bytes of the file.
    pub file_bytes: u64,
}
