//! Starting an episode: the held one kept first, the checks (rig topics live, room on the
//! disk), the file with its start metadata, and what every latched topic holds.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use scaledp_schema::msg::CompressedVideo;
use scaledp_schema::{EpisodeMetadata, RosMessage};

use super::{episode_file_name, Active, WriterThread};
use crate::control::Label;
use crate::error::{Error, Result};
use crate::judge::Evidence;
use crate::report::Event;
use crate::state::now_ns;
use crate::verdict::STARTED_WITH_MISSING_TOPICS;

impl WriterThread {
    /// Opens the next episode, unless a check refuses it (`force` overrides the topics' check,
    /// not the disk's).
    pub(super) fn start(&mut self, force: bool) {
        if let Some(held) = self.held.take() {
            self.finalize(held, Label::Unlabeled);
        }
        let index = self.next_index;
        let problems = self.shared.liveness().problems();
        if self.opts.check_topics && !force && !problems.is_empty() {
            let reason = format!(
                "episode {index} not started, topics not live: {} (force starts it anyway)",
                problems.join("; ")
            );
            self.refuse(reason, problems, true);
            return;
        }
        let live = self.shared.rates().map(|r| r.bytes_per_s);
        if let Err(reason) = self.disk.check_start(&self.opts.out_dir, index, live) {
            self.refuse(reason, Vec::new(), false);
            return;
        }
        if !problems.is_empty() {
            tracing::warn!(
                "episode {index} starts with topics not live: {}",
                problems.join("; ")
            );
        }
        self.next_index += 1;
        self.last_finished = None;
        let path = self.opts.out_dir.join(episode_file_name(index));
        let started_ns = now_ns();
        let mut start_meta = EpisodeMetadata {
            episode_index: Some(index),
            task: self.opts.task.clone(),
            operator: self.opts.operator.clone(),
            rig_name: self.opts.rig.name.clone(),
            rig_toml: toml::to_string(&self.opts.rig).ok(),
            start_time_ns: Some(started_ns),
            recorder_version: Some(env!("CARGO_PKG_VERSION").into()),
            ..EpisodeMetadata::default()
        };
        if !problems.is_empty() {
            start_meta.extra.insert(
                STARTED_WITH_MISSING_TOPICS.into(),
                serde_json::json!(problems).to_string(),
            );
        }
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
        let specs: Vec<_> = self.channels.iter().map(|c| c.spec.clone()).collect();
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
            evidence: Evidence::new(&self.opts.rig, &specs),
            prestart: problems.clone(),
        });
        if let Err(e) = self.write_latched(index, started_ns) {
            self.fail(e);
            return;
        }
        if let Ok(mut a) = self.shared.active.lock() {
            *a = Some((index, Instant::now()));
        }
        tracing::info!(index, path = %partial.display(), "episode started");
        self.publish_status(&serde_json::json!({
            "event": "started", "episode": index, STARTED_WITH_MISSING_TOPICS: problems,
        }));
        let _ = self.events.send(Event::Started {
            index,
            path: partial,
        });
    }

    /// A start refused: said in the log, on the status key and as an event.
    fn refuse(&mut self, reason: String, problems: Vec<String>, force: bool) {
        self.shared.recording.store(false, Relaxed);
        tracing::warn!("{reason}");
        self.publish_status(&serde_json::json!({
            "event": "refused", "reason": reason, "problems": problems, "force": force,
        }));
        let _ = self.events.send(Event::Refused {
            reason,
            problems,
            force,
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
}
