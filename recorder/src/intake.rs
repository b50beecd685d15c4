//! What arrives: the handle that queues commands, and the Zenoh callbacks' side of the queue
//! (receive time, counts, rmw_zenoh sequence gaps, the byte budget, topics `--topic` patterns
//! find). Callbacks never block.

use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;

use crossbeam_channel::Sender;
use zenoh::sample::Sample;

use crate::channels::discovered;
use crate::control::Command;
use crate::keys::RmwAttachment;
use crate::state::{now_ns, Counters, Entry, Item, Shared};

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
            Command::Start | Command::ForceStart | Command::Rerecord => {
                self.shared.recording.store(true, Relaxed)
            }
            Command::Toggle => {
                let on = self
                    .shared
                    .active
                    .lock()
                    .map(|a| a.is_none())
                    .unwrap_or(true);
                self.shared.recording.store(on, Relaxed);
            }
            // Messages stop being queued at once; the writer closes the episode behind them.
            Command::Stop(_) | Command::End | Command::Quit => {
                self.shared.recording.store(false, Relaxed)
            }
            Command::Keep | Command::Task(_) | Command::NextTask => {}
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
        counters.last_ns.store(log_time_ns, Relaxed);
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
