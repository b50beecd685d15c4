//! The writer thread: drains the queue into the open episode, flushes on a timer, and turns
//! commands into episode files with their metadata. It keeps the latest message of every
//! latched publisher and writes them at the start of every episode (`log_time` the episode's
//! start, `publish_time` when they were published), and it notes what it sees wrong in the
//! cameras' streams (see [`crate::checks`]).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::time::Instant;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use scaledp_schema::msg::{CompressedVideo, MsgSearch};
use scaledp_schema::{EpisodeMetadata, RosMessage};
use zenoh::Wait;

use crate::channels::Channel;
use crate::checks::Checks;
use crate::control::{Command, Label};
use crate::episode::EpisodeWriter;
use crate::error::{Error, Result};
use crate::latched::LatchedStore;
use crate::options::RecorderOptions;
use crate::report::Event;
use crate::state::{now_ns, Item, Shared};

mod stop;

struct Active {
    index: u64,
    writer: EpisodeWriter,
    started: Instant,
    start_meta: EpisodeMetadata,
    dropped_at_start: Vec<u64>,
    gaps_at_start: Vec<u64>,
    /// Link outages (count, ns) when the episode started.
    outages_at_start: (u64, u64),
    /// Per topic: a video topic whose first keyframe has not come yet. Its frames until then
    /// cannot be decoded (they reference pictures from before the episode) and are not written.
    awaiting_keyframe: Vec<bool>,
    /// Per topic: frames left out that way.
    before_keyframe: Vec<u64>,
    /// Per latched topic: messages written at the start.
    latched_at_start: BTreeMap<String, u64>,
    /// What was noticed, each once.
    warnings: BTreeSet<String>,
}

pub(crate) struct WriterThread {
    opts: RecorderOptions,
    channels: Vec<Channel>,
    search: MsgSearch,
    shared: Arc<Shared>,
    events: Sender<Event>,
    session: zenoh::Session,
    next_index: u64,
    active: Option<Active>,
    latched: LatchedStore,
    checks: Checks,
}

/// The first index not used by any `episode_NNNNNN.mcap[.partial]` in `dir` or `dir/discarded`.
fn next_free_index(dir: &Path) -> u64 {
    let mut next = 0;
    for d in [dir.to_path_buf(), dir.join("discarded")] {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name();
            let Some(name) = name.to_str() else { continue };
            let digits = name
                .strip_prefix("episode_")
                .and_then(|r| r.split('.').next());
            if let Some(n) = digits.and_then(|d| d.parse::<u64>().ok()) {
                next = next.max(n + 1);
            }
        }
    }
    next
}

/// Whether a `CompressedVideo` payload is a keyframe (an unreadable one is written as it is:
/// the converter reports it).
fn first_keyframe(payload: &[u8]) -> bool {
    CompressedVideo::from_cdr(payload).map_or(true, |v| v.is_keyframe())
}

/// `episode_000042.mcap`.
pub fn episode_file_name(index: u64) -> String {
    format!("episode_{index:06}.mcap")
}

impl WriterThread {
    pub(crate) fn new(
        opts: RecorderOptions,
        channels: Vec<Channel>,
        search: MsgSearch,
        shared: Arc<Shared>,
        events: Sender<Event>,
        session: zenoh::Session,
    ) -> Self {
        let next_index = next_free_index(&opts.out_dir);
        let specs: Vec<_> = channels.iter().map(|c| c.spec.clone()).collect();
        let checks = Checks::new(&opts.rig, &specs);
        Self {
            opts,
            channels,
            search,
            shared,
            events,
            session,
            next_index,
            active: None,
            latched: LatchedStore::default(),
            checks,
        }
    }

    pub(crate) fn run(mut self, rx: Receiver<Item>) {
        let every = self.opts.flush_interval;
        let mut next_flush = Instant::now() + every;
        loop {
            match rx.recv_timeout(next_flush.saturating_duration_since(Instant::now())) {
                Ok(Item::Message {
                    topic,
                    log_time_ns,
                    payload,
                    source_ns,
                    gid,
                }) => {
                    self.shared.queued_bytes.fetch_sub(payload.len(), Relaxed);
                    let data = payload.to_bytes();
                    self.message(topic, log_time_ns, &data, source_ns, gid.as_deref());
                }
                Ok(Item::NewTopic(spec)) => {
                    let channel = Channel::resolve(spec, &mut self.search);
                    self.checks.push_topic(&channel.spec.topic);
                    let added = self.active.as_mut().map(|a| {
                        a.awaiting_keyframe.push(false);
                        a.before_keyframe.push(0);
                        a.writer.add_channel(&channel.channel)
                    });
                    self.channels.push(channel);
                    if let Some(Err(e)) = added {
                        self.fail(e);
                    }
                }
                Ok(Item::Command(Command::Quit)) | Err(RecvTimeoutError::Disconnected) => {
                    self.stop(Label::Unlabeled);
                    break;
                }
                Ok(Item::Command(cmd)) => self.handle(cmd),
                Err(RecvTimeoutError::Timeout) => {}
            }
            if Instant::now() >= next_flush {
                if let Some(Err(e)) = self.active.as_mut().map(|a| a.writer.flush()) {
                    self.fail(e);
                }
                next_flush = Instant::now() + every;
            }
        }
    }

    /// One received message: kept if latched, written if an episode is open.
    fn message(
        &mut self,
        topic: usize,
        log_time_ns: u64,
        data: &[u8],
        source_ns: Option<u64>,
        gid: Option<&[u8]>,
    ) {
        let Some(ch) = self.channels.get(topic) else {
            return;
        };
        // publish_time = the capture stamp; else the sender's clock; else when it arrived.
        let publish = ch
            .stamp
            .read(data)
            .map(|t| t.as_ns())
            .or(source_ns)
            .unwrap_or(log_time_ns);
        if ch.spec.latched && !self.latched.update(topic, gid, data, publish) {
            return; // already kept, and written at the start of the open episode
        }
        let problem = self.checks.inspect(topic, data);
        let Some(a) = self.active.as_mut() else {
            return;
        };
        if a.awaiting_keyframe[topic] {
            if !first_keyframe(data) {
                a.before_keyframe[topic] += 1;
                return;
            }
            a.awaiting_keyframe[topic] = false;
        }
        if let Some(p) = problem {
            a.warnings.insert(p);
        }
        if let Err(e) = a.writer.write(topic, log_time_ns, publish, data) {
            self.fail(e);
        }
    }

    fn handle(&mut self, cmd: Command) {
        match (cmd, self.active.is_some()) {
            (Command::Start | Command::Toggle, false) => self.start(),
            (Command::Stop(outcome), true) => self.stop(outcome),
            (Command::Toggle, true) => self.stop(Label::Unlabeled),
            (cmd, open) => tracing::debug!(?cmd, open, "command ignored in this state"),
        }
    }

    fn start(&mut self) {
        let index = self.next_index;
        self.next_index += 1;
        let path = self.opts.out_dir.join(episode_file_name(index));
        let started_ns = now_ns();
        let start_meta = EpisodeMetadata {
            episode_index: Some(index),
            task: self.opts.task.clone(),
            operator: self.opts.operator.clone(),
            rig_name: self.opts.rig.name.clone(),
            rig_toml: toml::to_string(&self.opts.rig).ok(),
            start_time_ns: Some(started_ns),
            recorder_version: Some(env!("CARGO_PKG_VERSION").into()),
            ..EpisodeMetadata::default()
        };
        let channels: Vec<_> = self.channels.iter().map(|c| c.channel.clone()).collect();
        // The output directory is (re)created for every episode: one removed while the session
        // runs costs the episode being written, not the ones after it.
        let created = std::fs::create_dir_all(&self.opts.out_dir)
            .map_err(Error::io(&self.opts.out_dir))
            .and_then(|()| {
                self.opts
                    .episode
                    .create_channels(&path, &channels, start_meta.start_record())
            });
        let writer = match created {
            Ok(w) => w,
            Err(e) => {
                self.shared.recording.store(false, Relaxed);
                tracing::error!("episode {index}: {e}");
                let _ = self.events.send(Event::Failed {
                    index,
                    error: e.to_string(),
                });
                return;
            }
        };
        let partial = writer.partial_path().to_path_buf();
        let n = self.channels.len();
        self.active = Some(Active {
            index,
            writer,
            started: Instant::now(),
            start_meta,
            dropped_at_start: self.shared.counters(|c| c.dropped.load(Relaxed)),
            gaps_at_start: self.shared.counters(|c| c.upstream_gaps.load(Relaxed)),
            outages_at_start: self.shared.outage_figures(),
            awaiting_keyframe: self
                .channels
                .iter()
                .map(|c| c.spec.message_type == CompressedVideo::TYPE_NAME)
                .collect(),
            before_keyframe: vec![0; n],
            latched_at_start: BTreeMap::new(),
            warnings: BTreeSet::new(),
        });
        if let Err(e) = self.write_latched(index, started_ns) {
            self.fail(e);
            return;
        }
        if let Ok(mut a) = self.shared.active.lock() {
            *a = Some((index, Instant::now()));
        }
        tracing::info!(index, path = %partial.display(), "episode started");
        self.publish_status(&serde_json::json!({"event": "started", "episode": index}));
        let _ = self.events.send(Event::Started {
            index,
            path: partial,
        });
    }

    /// Writes what every latched topic holds at the episode's start; a latched topic with
    /// nothing yet is a warning (it is written as soon as it arrives).
    fn write_latched(&mut self, index: u64, started_ns: u64) -> Result<()> {
        let Some(a) = self.active.as_mut() else {
            return Ok(());
        };
        for (i, ch) in self.channels.iter().enumerate() {
            if !ch.spec.latched {
                continue;
            }
            let mut n = 0;
            for l in self.latched.of(i) {
                a.writer.write(i, started_ns, l.publish_ns, &l.payload)?;
                n += 1;
            }
            a.latched_at_start.insert(ch.spec.topic.clone(), n);
            if n == 0 {
                let w = format!(
                    "{}: nothing latched at the start of the episode (its publisher not up, \
                     or not serving late joiners); written when it arrives",
                    ch.spec.topic
                );
                tracing::warn!("episode {index}: {w}");
                a.warnings.insert(w);
            }
        }
        Ok(())
    }

    fn fail(&mut self, e: Error) {
        self.shared.recording.store(false, Relaxed);
        if let Some(active) = self.active.take() {
            if let Ok(mut a) = self.shared.active.lock() {
                *a = None;
            }
            // Dropping the writer flushes what it can and leaves the .partial for `recover`.
            drop(active.writer);
            self.report_failure(active.index, e);
        }
    }

    fn report_failure(&mut self, index: u64, e: Error) {
        let partial =
            crate::episode::partial_path(&self.opts.out_dir.join(episode_file_name(index)));
        if partial.exists() {
            tracing::error!(
                "episode {index}: {e} (its complete chunks are in {}: `scaledp recover` makes an MCAP of them)",
                partial.display()
            );
        } else {
            tracing::error!("episode {index}: {e}");
        }
        self.publish_status(
            &serde_json::json!({"event": "failed", "episode": index, "error": e.to_string()}),
        );
        let _ = self.events.send(Event::Failed {
            index,
            error: e.to_string(),
        });
    }

    fn publish_status(&self, value: &serde_json::Value) {
        let key = format!("{}/status", self.opts.control_prefix);
        if let Err(e) = self.session.put(key, value.to_string()).wait() {
            tracing::debug!("status not published: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbering_continues_after_kept_partial_and_discarded_episodes() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(next_free_index(dir.path()), 0);
        assert_eq!(next_free_index(&dir.path().join("missing")), 0);
        std::fs::create_dir(dir.path().join("discarded")).unwrap();
        for name in [
            "episode_000002.mcap",
            "episode_000004.mcap.partial",
            "discarded/episode_000007.mcap",
            "episode_x.mcap",
            "notes.txt",
        ] {
            std::fs::write(dir.path().join(name), b"").unwrap();
        }
        assert_eq!(next_free_index(dir.path()), 8);
        assert_eq!(episode_file_name(8), "episode_000008.mcap");
    }
}
