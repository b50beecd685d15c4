//! The writer thread: drains the queue into the open episode, flushes on a timer, and turns
//! commands into episode files with their metadata.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;
use std::time::Instant;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use scaledp_schema::rig::TopicSpec;
use zenoh::Wait;

use crate::control::{Command, Label};
use scaledp_schema::msg::CompressedVideo;
use scaledp_schema::{EpisodeMetadata, RosMessage};

use crate::episode::EpisodeWriter;
use crate::error::{Error, Result};
use crate::session::{now_ns, EpisodeReport, Event, Item, RecorderOptions, Shared};

struct Active {
    index: u64,
    writer: EpisodeWriter,
    started: Instant,
    start_meta: EpisodeMetadata,
    dropped_at_start: Vec<u64>,
    gaps_at_start: Vec<u64>,
    /// Per topic: a video topic whose first keyframe has not come yet. Its frames until then
    /// cannot be decoded (they reference pictures from before the episode) and are not written.
    awaiting_keyframe: Vec<bool>,
    /// Per topic: frames left out that way.
    before_keyframe: Vec<u64>,
}

pub(crate) struct WriterThread {
    opts: RecorderOptions,
    topics: Vec<TopicSpec>,
    shared: Arc<Shared>,
    events: Sender<Event>,
    session: zenoh::Session,
    next_index: u64,
    active: Option<Active>,
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
        topics: Vec<TopicSpec>,
        shared: Arc<Shared>,
        events: Sender<Event>,
        session: zenoh::Session,
    ) -> Result<Self> {
        let next_index = next_free_index(&opts.out_dir);
        Ok(Self {
            opts,
            topics,
            shared,
            events,
            session,
            next_index,
            active: None,
        })
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
                }) => {
                    self.shared.queued_bytes.fetch_sub(payload.len(), Relaxed);
                    if let Some(a) = self.active.as_mut() {
                        let data = payload.to_bytes();
                        if a.awaiting_keyframe[topic] {
                            if !first_keyframe(&data) {
                                a.before_keyframe[topic] += 1;
                                continue;
                            }
                            a.awaiting_keyframe[topic] = false;
                        }
                        // publish_time = capture stamp; log_time when the header is unreadable.
                        let publish = scaledp_schema::msg::header_stamp(&data)
                            .map(|t| t.as_ns())
                            .unwrap_or(log_time_ns);
                        let res = self
                            .active
                            .as_mut()
                            .map(|a| a.writer.write(topic, log_time_ns, publish, &data));
                        if let Some(Err(e)) = res {
                            self.fail(e);
                        }
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

    fn handle(&mut self, cmd: Command) {
        match (cmd, self.active.is_some()) {
            (Command::Start | Command::Toggle, false) => self.start(),
            (Command::Stop(outcome), true) => self.stop(outcome),
            (Command::Toggle, true) => self.stop(Label::Unlabeled),
            (cmd, open) => tracing::debug!(?cmd, open, "command ignored in this state"),
        }
    }

    fn counters(&self, pick: fn(&crate::session::Counters) -> u64) -> Vec<u64> {
        self.shared.counters.iter().map(pick).collect()
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
        // The output directory is (re)created for every episode: one removed while the session
        // runs costs the episode being written, not the ones after it.
        let created = std::fs::create_dir_all(&self.opts.out_dir)
            .map_err(Error::io(&self.opts.out_dir))
            .and_then(|()| {
                self.opts
                    .episode
                    .create(&path, &self.topics, start_meta.start_record())
            });
        match created {
            Ok(writer) => {
                let partial = writer.partial_path().to_path_buf();
                self.active = Some(Active {
                    index,
                    writer,
                    started: Instant::now(),
                    start_meta,
                    dropped_at_start: self.counters(|c| c.dropped.load(Relaxed)),
                    gaps_at_start: self.counters(|c| c.upstream_gaps.load(Relaxed)),
                    awaiting_keyframe: self
                        .topics
                        .iter()
                        .map(|t| t.message_type == CompressedVideo::TYPE_NAME)
                        .collect(),
                    before_keyframe: vec![0; self.topics.len()],
                });
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
            Err(e) => {
                self.shared.recording.store(false, Relaxed);
                tracing::error!("episode {index}: {e}");
                let _ = self.events.send(Event::Failed {
                    index,
                    error: e.to_string(),
                });
            }
        }
    }

    fn stop(&mut self, outcome: Label) {
        let Some(active) = self.active.take() else {
            return;
        };
        if let Ok(mut a) = self.shared.active.lock() {
            *a = None;
        }
        let index = active.index;
        for ((t, &n), &waiting) in self
            .topics
            .iter()
            .zip(&active.before_keyframe)
            .zip(&active.awaiting_keyframe)
        {
            if waiting && n > 0 {
                tracing::warn!(index, topic = %t.topic, "{n} video frames and no keyframe: nothing of this camera was recorded");
            } else if n > 0 {
                tracing::info!(index, topic = %t.topic, "{n} video frames before the first keyframe left out (undecodable)");
            }
        }
        let end_ns = now_ns();
        let duration_s = active.started.elapsed().as_secs_f64();
        let per_topic = |now: Vec<u64>, start: &[u64]| -> BTreeMap<String, u64> {
            self.topics
                .iter()
                .zip(now.iter().zip(start))
                .map(|(t, (n, s))| (t.topic.clone(), n - s))
                .collect()
        };
        let dropped = per_topic(
            self.counters(|c| c.dropped.load(Relaxed)),
            &active.dropped_at_start,
        );
        let gaps = per_topic(
            self.counters(|c| c.upstream_gaps.load(Relaxed)),
            &active.gaps_at_start,
        );
        let counts: BTreeMap<&str, u64> = self
            .topics
            .iter()
            .zip(active.writer.message_counts())
            .map(|(t, n)| (t.topic.as_str(), *n))
            .collect();
        let meta = EpisodeMetadata {
            end_time_ns: Some(end_ns),
            duration_s: Some(duration_s),
            label: Some(outcome),
            message_counts: counts.iter().map(|(t, n)| (t.to_string(), *n)).collect(),
            dropped: dropped.clone(),
            upstream_gaps: gaps.clone(),
            ..active.start_meta.clone()
        }
        .end_record();
        let dest: Option<PathBuf> = (outcome == Label::Discarded).then(|| {
            self.opts
                .out_dir
                .join("discarded")
                .join(episode_file_name(index))
        });
        match active.writer.finish(meta, dest.as_deref()) {
            Ok(summary) => {
                tracing::info!(index, %outcome, path = %summary.path.display(), "episode finished");
                self.publish_status(&serde_json::json!({
                    "event": "finished", "episode": index, "outcome": outcome.as_str(),
                    "path": summary.path.display().to_string(), "messages": counts, "bytes": summary.bytes,
                    "dropped": dropped, "upstream_gaps": gaps,
                }));
                let report = EpisodeReport {
                    index,
                    outcome,
                    duration_s,
                    summary,
                    dropped,
                    upstream_gaps: gaps,
                };
                let _ = self.events.send(Event::Finished(report));
            }
            Err(e) => self.report_failure(index, e),
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
