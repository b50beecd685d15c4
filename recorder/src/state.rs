//! What the Zenoh callbacks, the writer thread and the link watch share: each topic's
//! figures, the queue's budget, the open episode, link outages, and the items of the queue.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Instant;

use scaledp_schema::rig::TopicSpec;
use zenoh::bytes::ZBytes;

use crate::control::Command;
use crate::disk::DiskStatus;
use crate::liveness::{self, Liveness, Observed, RateWindow, Rates};

#[derive(Default)]
pub(crate) struct Counters {
    pub received: AtomicU64,
    pub bytes: AtomicU64,
    pub dropped: AtomicU64,
    pub upstream_gaps: AtomicU64,
    /// Receive time of the latest message (ns since the epoch; 0 before the first).
    pub last_ns: AtomicU64,
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
    pub max_queued_bytes: usize,
    /// The rig's topics, then the ones `--topic` patterns found, in the order they came.
    pub topics: RwLock<Vec<Entry>>,
    /// How many of `topics` are the rig's.
    pub rig_topics: usize,
    pub by_name: Mutex<HashMap<String, usize>>,
    /// Types zenoh-bridge-ros2dds announces for its keys (learned from its liveliness tokens).
    pub bridge_types: Mutex<HashMap<String, String>>,
    pub last_sequence: Mutex<HashMap<(usize, Vec<u8>), i64>>,
    pub active: Mutex<Option<(u64, Instant)>>,
    /// The episode that ended and waits for a label, keep, discard or re-record.
    pub held: Mutex<Option<u64>>,
    /// Counter snapshots of the last seconds, for rates (taken by the writer).
    pub window: Mutex<RateWindow>,
    /// The task of the episodes started from now on.
    pub task: Mutex<String>,
    /// The disk guard's latest figures.
    pub disk: Mutex<Option<DiskStatus>>,
}

impl Shared {
    pub(crate) fn new(topics: &[TopicSpec], max_queued_bytes: usize, task: &str) -> Self {
        Self {
            links: AtomicUsize::new(0),
            outages: AtomicU64::new(0),
            outage_ns: AtomicU64::new(0),
            down_since_ns: AtomicU64::new(0),
            recording: AtomicBool::new(false),
            queued_bytes: AtomicUsize::new(0),
            max_queued_bytes,
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
            held: Mutex::new(None),
            window: Mutex::default(),
            task: Mutex::new(task.to_string()),
            disk: Mutex::new(None),
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

    /// Takes a snapshot of the counters for rates (kept when 200 ms after the previous one).
    pub(crate) fn snapshot(&self) {
        let received = self.counters(|c| c.received.load(Relaxed));
        let bytes = self.counters(|c| c.bytes.load(Relaxed));
        if let Ok(mut w) = self.window.lock() {
            w.push(Instant::now(), received, bytes);
        }
    }

    /// Rates over the last seconds, when a snapshot is there to measure from.
    pub(crate) fn rates(&self) -> Option<Rates> {
        let received = self.counters(|c| c.received.load(Relaxed));
        let bytes = self.counters(|c| c.bytes.load(Relaxed));
        self.window
            .lock()
            .ok()?
            .rates(Instant::now(), &received, &bytes)
    }

    /// The liveness of the rig's topics now.
    pub(crate) fn liveness(&self) -> Liveness {
        let rates = self.rates();
        let Ok(topics) = self.topics.read() else {
            return Liveness::default();
        };
        let specs: Vec<TopicSpec> = topics.iter().map(|e| e.spec.clone()).collect();
        let pick = |f: fn(&Counters) -> &AtomicU64| -> Vec<u64> {
            topics
                .iter()
                .map(|e| f(&e.counters).load(Relaxed))
                .collect()
        };
        liveness::judge(&Observed {
            specs: &specs,
            rig_topics: self.rig_topics,
            received: &pick(|c| &c.received),
            last_ns: &pick(|c| &c.last_ns),
            rates: rates.as_ref(),
            now_ns: now_ns(),
        })
    }

    /// The task of the episodes started from now on.
    pub(crate) fn task(&self) -> String {
        self.task.lock().map(|t| t.clone()).unwrap_or_default()
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

/// Nanoseconds since the Unix epoch, now.
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}
