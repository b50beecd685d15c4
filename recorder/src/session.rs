//! A recording session: Zenoh subscribers → a byte-bounded queue → one writer thread → files.
//!
//! Zenoh callbacks never block: they stamp the receive time, count, and hand the payload (a
//! reference-counted buffer, not a copy) to the queue, or count a drop when the queue already
//! holds `queue_bytes`. Commands travel through the same queue, so an episode holds exactly the
//! messages received between its start and stop. Latched topics are queued while no episode is
//! open too: the writer keeps their latest messages for the start of every episode.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, RwLock};
use std::thread::JoinHandle;
use std::time::Instant;

use crossbeam_channel::{Receiver, Sender};
use scaledp_schema::rig::TopicSpec;
use zenoh::bytes::ZBytes;
use zenoh::sample::Sample;
use zenoh::Wait;

use crate::channels::discovered;
use crate::control::{Command, Label};
use crate::episode::EpisodeSummary;
use crate::error::{Error, Result};
use crate::keys::RmwAttachment;
use crate::links::LinkWatch;
use crate::options::RecorderOptions;
use crate::subscribe::Sub;

#[derive(Default)]
pub(crate) struct Counters {
    pub received: AtomicU64,
    pub bytes: AtomicU64,
    pub dropped: AtomicU64,
    pub upstream_gaps: AtomicU64,
}

/// A topic of the session and its figures.
pub(crate) struct Entry {
    pub spec: TopicSpec,
    pub counters: Arc<Counters>,
}

pub(crate) struct Shared {
    /// Zenoh peers and routers linked to the session, as last counted.
    pub links: AtomicUsize,
    /// Times every link was lost, and for how long in all (ns; an outage still going on is
    /// not in it yet: it starts at `down_since_ns`, 0 while a link is up).
    pub outages: AtomicU64,
    pub outage_ns: AtomicU64,
    pub down_since_ns: AtomicU64,
    pub recording: AtomicBool,
    pub queued_bytes: AtomicUsize,
    max_queued_bytes: usize,
    /// The rig's topics, then the ones `--topic` patterns found, in the order they came.
    pub topics: RwLock<Vec<Entry>>,
    /// How many of `topics` are the rig's.
    rig_topics: usize,
    by_name: Mutex<HashMap<String, usize>>,
    /// Types zenoh-bridge-ros2dds announces for its keys (learned from its liveliness tokens).
    pub bridge_types: Mutex<HashMap<String, String>>,
    last_sequence: Mutex<HashMap<(usize, Vec<u8>), i64>>,
    pub active: Mutex<Option<(u64, Instant)>>,
}

impl Shared {
    pub(crate) fn new(topics: &[TopicSpec], opts: &RecorderOptions) -> Self {
        Self {
            links: AtomicUsize::new(0),
            outages: AtomicU64::new(0),
            outage_ns: AtomicU64::new(0),
            down_since_ns: AtomicU64::new(0),
            recording: AtomicBool::new(false),
            queued_bytes: AtomicUsize::new(0),
            max_queued_bytes: opts.queue_bytes,
            topics: RwLock::new(
                topics
                    .iter()
                    .map(|t| Entry {
                        spec: t.clone(),
                        counters: Arc::default(),
                    })
                    .collect(),
            ),
            rig_topics: topics.len(),
            by_name: Mutex::new(
                topics
                    .iter()
                    .enumerate()
                    .map(|(i, t)| (t.topic.clone(), i))
                    .collect(),
            ),
            bridge_types: Mutex::default(),
            last_sequence: Mutex::default(),
            active: Mutex::new(None),
        }
    }

    /// Per topic, one figure of its counters.
    pub(crate) fn counters(&self, pick: fn(&Counters) -> u64) -> Vec<u64> {
        self.topics
            .read()
            .map(|t| t.iter().map(|e| pick(&e.counters)).collect())
            .unwrap_or_default()
    }

    /// The counters of topic `i`.
    pub(crate) fn counters_of(&self, i: usize) -> Option<Arc<Counters>> {
        self.topics.read().ok()?.get(i).map(|e| e.counters.clone())
    }

    /// Link outages so far: (count, total ns, an ongoing one included).
    pub(crate) fn outage_figures(&self) -> (u64, u64) {
        let since = self.down_since_ns.load(Relaxed);
        let ongoing = if since > 0 {
            now_ns().saturating_sub(since)
        } else {
            0
        };
        (
            self.outages.load(Relaxed),
            self.outage_ns.load(Relaxed) + ongoing,
        )
    }
}

pub(crate) enum Item {
    Message {
        topic: usize,
        log_time_ns: u64,
        payload: ZBytes,
        /// The sender's clock when it sent the message (rmw_zenoh's attachment, or the sample's
        /// Zenoh timestamp), when known.
        source_ns: Option<u64>,
        /// The publisher's rmw_zenoh gid, kept for latched topics only.
        gid: Option<Vec<u8>>,
    },
    /// A topic a `--topic` pattern found, before its first message.
    NewTopic(TopicSpec),
    Command(Command),
}

/// A cheap handle that sends commands to the writer; clone it into key handlers or timers.
#[derive(Clone)]
pub struct Control {
    tx: Sender<Item>,
    pub(crate) shared: Arc<Shared>,
}

impl Control {
    pub(crate) fn new(tx: Sender<Item>, shared: Arc<Shared>) -> Self {
        Self { tx, shared }
    }

    /// Queues a command behind every message received so far.
    pub fn send(&self, cmd: Command) {
        match cmd {
            Command::Start => self.shared.recording.store(true, Relaxed),
            Command::Toggle => {
                let on = self
                    .shared
                    .active
                    .lock()
                    .map(|a| a.is_none())
                    .unwrap_or(true);
                self.shared.recording.store(on, Relaxed);
            }
            Command::Stop(_) | Command::Quit => self.shared.recording.store(false, Relaxed),
        }
        let _ = self.tx.send(Item::Command(cmd));
    }

    /// A sample of topic `topic` (whose counters are `counters`); `latched` topics are queued
    /// whether an episode is open or not.
    pub(crate) fn on_sample(&self, topic: usize, counters: &Counters, latched: bool, s: &Sample) {
        let log_time_ns = now_ns();
        let len = s.payload().len();
        counters.received.fetch_add(1, Relaxed);
        counters.bytes.fetch_add(len as u64, Relaxed);
        let att = s.attachment().and_then(RmwAttachment::parse);
        let source_ns = att
            .as_ref()
            .and_then(|a| u64::try_from(a.source_timestamp_ns).ok())
            .or_else(|| {
                let t = s.timestamp()?.get_time().to_system_time();
                let d = t.duration_since(std::time::UNIX_EPOCH).ok()?;
                u64::try_from(d.as_nanos()).ok()
            });
        let gid = match &att {
            Some(a) if latched => Some(a.source_gid.clone()),
            _ => None,
        };
        if let Some(att) = att {
            self.check_sequence(topic, counters, att);
        }
        if !latched && !self.shared.recording.load(Relaxed) {
            return;
        }
        let before = self.shared.queued_bytes.fetch_add(len, Relaxed);
        // An empty queue always takes the message, so one message larger than the whole budget
        // is still recorded.
        if before > 0 && before + len > self.shared.max_queued_bytes {
            self.shared.queued_bytes.fetch_sub(len, Relaxed);
            counters.dropped.fetch_add(1, Relaxed);
            return;
        }
        let item = Item::Message {
            topic,
            log_time_ns,
            payload: s.payload().clone(),
            source_ns,
            gid,
        };
        if self.tx.send(item).is_err() {
            self.shared.queued_bytes.fetch_sub(len, Relaxed);
        }
    }

    /// A sample a `--topic` pattern matched, on topic `topic` of type `message_type` (when
    /// known): recorded on a topic of its own from its first message, unless it is a rig topic
    /// (recorded as such) or no pattern asks for it.
    pub(crate) fn on_found(&self, topic: &str, message_type: Option<&str>, s: &Sample) {
        let found = {
            let Ok(mut names) = self.shared.by_name.lock() else {
                return;
            };
            match names.get(topic) {
                Some(&i) if i < self.shared.rig_topics => return,
                Some(&i) => self.shared.counters_of(i).map(|c| (i, c)),
                None => {
                    let spec = discovered(topic, message_type);
                    let counters = Arc::new(Counters::default());
                    let Ok(mut topics) = self.shared.topics.write() else {
                        return;
                    };
                    let i = topics.len();
                    topics.push(Entry {
                        spec: spec.clone(),
                        counters: counters.clone(),
                    });
                    names.insert(topic.to_string(), i);
                    tracing::info!(topic, message_type, "recording a further topic");
                    let _ = self.tx.send(Item::NewTopic(spec));
                    Some((i, counters))
                }
            }
        };
        if let Some((i, counters)) = found {
            self.on_sample(i, &counters, false, s);
        }
    }

    fn check_sequence(&self, topic: usize, counters: &Counters, att: RmwAttachment) {
        let Ok(mut last) = self.shared.last_sequence.lock() else {
            return;
        };
        let prev = last.insert((topic, att.source_gid), att.sequence_number);
        if let Some(prev) = prev {
            let missing = att.sequence_number - prev - 1;
            if missing > 0 {
                counters.upstream_gaps.fetch_add(missing as u64, Relaxed);
            }
        }
    }
}

/// Nanoseconds since the Unix epoch, now.
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

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

/// A running recording session.
pub struct Recorder {
    session: zenoh::Session,
    subscribers: Vec<Sub>,
    control: Control,
    shared: Arc<Shared>,
    events: Receiver<Event>,
    writer: Option<JoinHandle<()>>,
    links: Option<LinkWatch>,
}

impl Recorder {
    pub(crate) fn new(
        session: zenoh::Session,
        subscribers: Vec<Sub>,
        control: Control,
        shared: Arc<Shared>,
        events: Receiver<Event>,
        writer: JoinHandle<()>,
        links: LinkWatch,
    ) -> Self {
        Self {
            session,
            subscribers,
            control,
            shared,
            events,
            writer: Some(writer),
            links: Some(links),
        }
    }
    /// Zenoh peers and routers the session is linked to (counted every 250 ms): 0 while the
    /// bridge or router is unreachable.
    pub fn zenoh_links(&self) -> usize {
        self.shared.links.load(Relaxed)
    }
    /// Times every link was lost since the session opened.
    pub fn link_outages(&self) -> u64 {
        self.shared.outage_figures().0
    }
    /// A handle for sending commands from other threads.
    pub fn control(&self) -> Control {
        self.control.clone()
    }
    /// Sends a command.
    pub fn send(&self, cmd: Command) {
        self.control.send(cmd);
    }
    /// Episode events, in order.
    pub fn events(&self) -> &Receiver<Event> {
        &self.events
    }
    /// The Zenoh session (for publishing status or bench loads on the same link).
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }
    /// Live figures.
    pub fn status(&self) -> Status {
        let topics = self
            .shared
            .topics
            .read()
            .map(|topics| {
                topics
                    .iter()
                    .map(|e| TopicStatus {
                        topic: e.spec.topic.clone(),
                        received: e.counters.received.load(Relaxed),
                        bytes: e.counters.bytes.load(Relaxed),
                        dropped: e.counters.dropped.load(Relaxed),
                        upstream_gaps: e.counters.upstream_gaps.load(Relaxed),
                    })
                    .collect()
            })
            .unwrap_or_default();
        let episode = self.shared.active.lock().ok().and_then(|a| *a);
        Status {
            episode,
            topics,
            queued_bytes: self.shared.queued_bytes.load(Relaxed),
        }
    }
    /// True while the writer thread runs (it stops after `quit`).
    pub fn is_running(&self) -> bool {
        self.writer.as_ref().is_some_and(|h| !h.is_finished())
    }

    /// Finishes an open episode as `unlabeled`, stops the writer and closes the session.
    pub fn finish(mut self) -> Result<()> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<()> {
        if let Some(links) = self.links.take() {
            links.stop();
        }
        for s in self.subscribers.drain(..) {
            s.undeclare();
        }
        self.control.send(Command::Quit);
        if let Some(h) = self.writer.take() {
            h.join().map_err(|_| Error::Stopped)?;
        }
        self.session
            .close()
            .wait()
            .map_err(|e| Error::Zenoh(e.to_string()))
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        if self.writer.is_some() {
            let _ = self.shutdown();
        }
    }
}
