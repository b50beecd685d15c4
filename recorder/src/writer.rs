//! The writer thread: drains the queue into the open episode, flushes on a timer, and turns
//! commands into episode files with their metadata. It keeps the latest message of every
//! latched publisher and writes them at the start of every episode (`log_time` the episode's
//! start, `publish_time` when they were published), and it notes what it sees wrong in the
//! cameras' streams (see [`crate::checks`]). Starting (its checks: topics live, room on disk)
//! is in `start`, ending, holding and finishing an episode in `stop`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
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
use crate::disk::DiskGuard;
use crate::episode::EpisodeWriter;
use crate::error::Error;
use crate::judge::Evidence;
use crate::latched::LatchedStore;
use crate::options::RecorderOptions;
use crate::report::Event;
use crate::state::{Item, Shared};

mod closed;
mod start;
mod stop;

use closed::Closed;

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
    /// What the verdict looks at.
    evidence: Evidence,
    /// Topics missing or slow when it started.
    prestart: Vec<String>,
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
    /// Ended, waiting for a label, keep, discard or re-record.
    held: Option<Closed>,
    /// The episode finished last (index, file), while a discard may still move it.
    last_finished: Option<(u64, PathBuf)>,
    latched: LatchedStore,
    checks: Checks,
    disk: DiskGuard,
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
        let disk = DiskGuard::new(opts.disk.clone());
        Self {
            opts,
            channels,
            search,
            shared,
            events,
            session,
            next_index,
            active: None,
            held: None,
            last_finished: None,
            latched: LatchedStore::default(),
            checks,
            disk,
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
                        a.evidence.push_topic();
                        a.writer.add_channel(&channel.channel)
                    });
                    self.channels.push(channel);
                    if let Some(Err(e)) = added {
                        self.fail(e);
                    }
                }
                Ok(Item::Command(Command::Quit)) | Err(RecvTimeoutError::Disconnected) => {
                    self.stop(Label::Unlabeled);
                    if let Some(held) = self.held.take() {
                        self.finalize(held, Label::Unlabeled);
                    }
                    break;
                }
                Ok(Item::Command(cmd)) => self.handle(cmd),
                Err(RecvTimeoutError::Timeout) => {}
            }
            if Instant::now() >= next_flush {
                if let Some(Err(e)) = self.active.as_mut().map(|a| a.writer.flush()) {
                    self.fail(e);
                }
                self.tick();
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
        let header = ch.stamp.read(data).map(|t| t.as_ns());
        let publish = header.or(source_ns).unwrap_or(log_time_ns);
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
        match a.writer.write(topic, log_time_ns, publish, data) {
            Ok(()) => a.evidence.message(topic, header, log_time_ns, data),
            Err(e) => self.fail(e),
        }
    }

    fn handle(&mut self, cmd: Command) {
        let open = self.active.is_some();
        match cmd {
            Command::Start | Command::Toggle if !open => self.start(false),
            Command::ForceStart if !open => self.start(true),
            Command::Toggle => self.stop(Label::Unlabeled),
            Command::Stop(label) if open => self.stop(label),
            Command::Stop(label) => match self.held.take() {
                Some(held) => self.finalize(held, label),
                None if label == Label::Discarded => self.discard_last(),
                None => tracing::debug!(?label, "no episode to label"),
            },
            Command::End if open => self.end(),
            Command::Keep => match self.held.take() {
                Some(held) => self.finalize(held, Label::Unlabeled),
                None => tracing::debug!("no episode held to keep"),
            },
            Command::Rerecord => {
                if open {
                    self.stop(Label::Discarded);
                } else if let Some(held) = self.held.take() {
                    self.finalize(held, Label::Discarded);
                } else {
                    self.discard_last();
                }
                self.start(false);
            }
            Command::Task(task) => self.set_task(task),
            Command::NextTask => {
                let tasks = &self.opts.tasks;
                let at = tasks.iter().position(|t| *t == self.opts.task);
                match at.map_or(tasks.first(), |i| tasks.get((i + 1) % tasks.len())) {
                    Some(next) => self.set_task(next.clone()),
                    None => tracing::warn!("next-task: the session was given no list of tasks"),
                }
            }
            cmd => tracing::debug!(?cmd, open, "command ignored in this state"),
        }
    }

    /// The task of the episodes started from now on.
    fn set_task(&mut self, task: String) {
        tracing::info!(task, "task of the next episodes");
        if let Ok(mut t) = self.shared.task.lock() {
            t.clone_from(&task);
        }
        self.publish_status(&serde_json::json!({"event": "task", "task": task}));
        self.opts.task.clone_from(&task);
        let _ = self.events.send(Event::Task(task));
    }

    /// Every flush: counters for rates, the disk's figures, and an episode ended before the
    /// disk is full.
    fn tick(&mut self) {
        self.shared.snapshot();
        let live = self.shared.rates().map(|r| r.bytes_per_s);
        let (status, low) = self.disk.status(&self.opts.out_dir, live);
        if let Ok(mut d) = self.shared.disk.lock() {
            d.clone_from(&status);
        }
        if let (Some(line), Some(s)) = (low, status) {
            tracing::warn!("{line}");
            self.publish_status(&serde_json::json!({
                "event": "disk", "free_bytes": s.free_bytes, "minutes_left": s.minutes_left,
                "line": line,
            }));
            let _ = self.events.send(Event::DiskLow(line));
        }
        let Some(file) = self
            .active
            .as_ref()
            .map(|a| a.writer.partial_path().to_path_buf())
        else {
            return;
        };
        if let Some(cut) = self.disk.check_running(&self.opts.out_dir, &file, live) {
            tracing::error!("{cut}");
            if let Some(mut closed) = self.close() {
                closed.warnings.push(cut.clone());
                closed.cut = Some(cut);
                self.finalize(closed, Label::Unlabeled);
            }
        }
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
