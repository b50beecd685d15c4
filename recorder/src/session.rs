//! A recording session: Zenoh subscribers → a byte-bounded queue → one writer thread → files.
//!
//! Zenoh callbacks never block: they stamp the receive time, count, and hand the payload (a
//! reference-counted buffer, not a copy) to the queue, or count a drop when the queue already
//! holds `queue_bytes`. Commands travel through the same queue, so an episode holds exactly the
//! messages received between its start and stop.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender};
use scaledp_schema::rig::{Rig, TopicSpec};
use zenoh::bytes::ZBytes;
use zenoh::sample::Sample;
use zenoh::Wait;

use crate::control::{Command, Label};
use crate::episode::{Compression, EpisodeOptions, EpisodeSummary};
use crate::error::{Error, Result};
use crate::keys::{bridge_key, rmw_key_expr, RmwAttachment};
use crate::writer::WriterThread;

/// Settings of a recording session; `start` opens it.
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    pub(crate) rig: Rig,
    pub(crate) out_dir: PathBuf,
    pub(crate) task: String,
    pub(crate) operator: String,
    pub(crate) episode: EpisodeOptions,
    pub(crate) queue_bytes: usize,
    pub(crate) flush_interval: Duration,
    pub(crate) control_prefix: String,
    pub(crate) bridge_namespace: String,
}

impl RecorderOptions {
    /// Records every topic of `rig` into `out_dir`. Defaults: LZ4 chunks of 8 MiB, a 1 GiB
    /// queue, a flush every 500 ms, control on `scaledp/recorder/control`, no bridge namespace.
    pub fn new(rig: Rig, out_dir: impl Into<PathBuf>) -> Self {
        Self {
            rig,
            out_dir: out_dir.into(),
            task: String::new(),
            operator: String::new(),
            episode: EpisodeOptions::new(),
            queue_bytes: 1 << 30,
            flush_interval: Duration::from_millis(500),
            control_prefix: "scaledp/recorder".into(),
            bridge_namespace: String::new(),
        }
    }
    /// The task instruction stored with every episode, e.g. "put the cup on the plate".
    pub fn task(mut self, task: impl Into<String>) -> Self {
        self.task = task.into();
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

    /// Opens a Zenoh session with `config`, subscribes to every topic of the rig (bridge and
    /// rmw_zenoh keys) and to the control key, and starts the writer thread. No episode is
    /// open until a [`Command::Start`].
    pub fn start(self, config: zenoh::Config) -> Result<Recorder> {
        std::fs::create_dir_all(&self.out_dir).map_err(Error::io(&self.out_dir))?;
        let topics = self.rig.topics();
        let session = crate::net::open(config)?;
        let shared = Arc::new(Shared {
            links: AtomicUsize::new(0),
            recording: AtomicBool::new(false),
            queued_bytes: AtomicUsize::new(0),
            max_queued_bytes: self.queue_bytes,
            counters: topics.iter().map(|_| Counters::default()).collect(),
            last_sequence: Mutex::new(HashMap::new()),
            active: Mutex::new(None),
        });
        let (tx, rx) = crossbeam_channel::unbounded();
        let control = Control {
            tx,
            shared: shared.clone(),
        };
        let zerr = |e: zenoh::Error| Error::Zenoh(e.to_string());
        let mut subscribers = Vec::new();
        for (i, t) in topics.iter().enumerate() {
            for key in [
                bridge_key(&self.bridge_namespace, &t.topic),
                rmw_key_expr(&t.topic, &t.message_type),
            ] {
                let control = control.clone();
                let sub = session
                    .declare_subscriber(key)
                    .callback(move |s: Sample| control.on_sample(i, &s))
                    .wait()
                    .map_err(zerr)?;
                subscribers.push(sub);
            }
        }
        let c = control.clone();
        let control_sub = session
            .declare_subscriber(format!("{}/control", self.control_prefix))
            .callback(move |s: Sample| {
                let text = String::from_utf8_lossy(&s.payload().to_bytes()).into_owned();
                match text.parse::<Command>() {
                    Ok(cmd) => {
                        tracing::info!(command = ?cmd, "control over zenoh");
                        c.send(cmd);
                    }
                    Err(e) => tracing::warn!("{}: {e}", s.key_expr()),
                }
            })
            .wait()
            .map_err(zerr)?;
        subscribers.push(control_sub);
        let (events_tx, events) = crossbeam_channel::unbounded();
        let writer = WriterThread::new(
            self,
            topics.clone(),
            shared.clone(),
            events_tx,
            session.clone(),
        )?;
        let handle = std::thread::Builder::new()
            .name("scaledp-writer".into())
            .spawn(move || writer.run(rx))
            .map_err(Error::io("writer thread"))?;
        let links = LinkWatch::start(session.clone(), shared.clone())?;
        Ok(Recorder {
            session,
            subscribers,
            control,
            shared,
            topics,
            events,
            writer: Some(handle),
            links: Some(links),
        })
    }
}

#[derive(Default)]
pub(crate) struct Counters {
    pub received: AtomicU64,
    pub bytes: AtomicU64,
    pub dropped: AtomicU64,
    pub upstream_gaps: AtomicU64,
}

/// Watches the session's links (to the bridge, a router, peers) and says when the last one is
/// lost and when one is back: Zenoh reconnects to its `connect` endpoints by itself, but what
/// is published meanwhile never arrives, and an operator should know.
struct LinkWatch {
    stop: Arc<AtomicBool>,
    handle: JoinHandle<()>,
}

impl LinkWatch {
    /// How often the links are counted.
    const EVERY: Duration = Duration::from_millis(250);

    fn start(session: zenoh::Session, shared: Arc<Shared>) -> Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let stopped = stop.clone();
        let handle = std::thread::Builder::new()
            .name("scaledp-links".into())
            .spawn(move || {
                // None until the first link: a recorder started before the bridge is not "down".
                let mut up: Option<bool> = None;
                while !stopped.load(Relaxed) {
                    let info = session.info();
                    let n = info.routers_zid().wait().count() + info.peers_zid().wait().count();
                    shared.links.store(n, Relaxed);
                    match (up, n > 0) {
                        (Some(true), false) => tracing::warn!(
                            "zenoh: every link is down (bridge or router gone?): reconnecting; \
                             messages published meanwhile are lost"
                        ),
                        (Some(false), true) => {
                            tracing::warn!("zenoh: link back ({n} peers and routers)")
                        }
                        _ => {}
                    }
                    if up.is_some() || n > 0 {
                        up = Some(n > 0);
                    }
                    std::thread::sleep(Self::EVERY);
                }
            })
            .map_err(Error::io("link watch thread"))?;
        Ok(Self { stop, handle })
    }

    fn stop(self) {
        self.stop.store(true, Relaxed);
        let _ = self.handle.join();
    }
}

pub(crate) struct Shared {
    /// Zenoh peers and routers linked to the session, as last counted.
    pub links: AtomicUsize,
    pub recording: AtomicBool,
    pub queued_bytes: AtomicUsize,
    max_queued_bytes: usize,
    pub counters: Vec<Counters>,
    last_sequence: Mutex<HashMap<(usize, Vec<u8>), i64>>,
    pub active: Mutex<Option<(u64, Instant)>>,
}

pub(crate) enum Item {
    Message {
        topic: usize,
        log_time_ns: u64,
        payload: ZBytes,
    },
    Command(Command),
}

/// A cheap handle that sends commands to the writer; clone it into key handlers or timers.
#[derive(Clone)]
pub struct Control {
    tx: Sender<Item>,
    shared: Arc<Shared>,
}

impl Control {
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

    fn on_sample(&self, topic: usize, sample: &Sample) {
        let log_time_ns = now_ns();
        let len = sample.payload().len();
        let counters = &self.shared.counters[topic];
        counters.received.fetch_add(1, Relaxed);
        counters.bytes.fetch_add(len as u64, Relaxed);
        if let Some(att) = sample.attachment().and_then(RmwAttachment::parse) {
            self.check_sequence(topic, att);
        }
        if !self.shared.recording.load(Relaxed) {
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
            payload: sample.payload().clone(),
        };
        if self.tx.send(item).is_err() {
            self.shared.queued_bytes.fetch_sub(len, Relaxed);
        }
    }

    fn check_sequence(&self, topic: usize, att: RmwAttachment) {
        let Ok(mut last) = self.shared.last_sequence.lock() else {
            return;
        };
        let prev = last.insert((topic, att.source_gid), att.sequence_number);
        if let Some(prev) = prev {
            let missing = att.sequence_number - prev - 1;
            if missing > 0 {
                self.shared.counters[topic]
                    .upstream_gaps
                    .fetch_add(missing as u64, Relaxed);
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
    /// Per-topic figures, in rig order.
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
}

/// A running recording session.
pub struct Recorder {
    session: zenoh::Session,
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    control: Control,
    shared: Arc<Shared>,
    topics: Vec<TopicSpec>,
    events: Receiver<Event>,
    writer: Option<JoinHandle<()>>,
    links: Option<LinkWatch>,
}

impl Recorder {
    /// Zenoh peers and routers the session is linked to (counted every 250 ms): 0 while the
    /// bridge or router is unreachable.
    pub fn zenoh_links(&self) -> usize {
        self.shared.links.load(Relaxed)
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
            .topics
            .iter()
            .zip(&self.shared.counters)
            .map(|(t, c)| TopicStatus {
                topic: t.topic.clone(),
                received: c.received.load(Relaxed),
                bytes: c.bytes.load(Relaxed),
                dropped: c.dropped.load(Relaxed),
                upstream_gaps: c.upstream_gaps.load(Relaxed),
            })
            .collect();
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
            let _ = s.undeclare().wait();
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
