//! Closing an episode: its end metadata (counts, drops, gaps, latched messages, link outages,
//! warnings), the rename into place (or `discarded/`), the event and the status message.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering::Relaxed;

use scaledp_schema::episode::keys;
use scaledp_schema::EpisodeMetadata;

use super::{episode_file_name, WriterThread};
use crate::control::Label;
use crate::report::{EpisodeReport, Event};
use crate::state::now_ns;

impl WriterThread {
    pub(super) fn stop(&mut self, outcome: Label) {
        let Some(active) = self.active.take() else {
            return;
        };
        if let Ok(mut a) = self.shared.active.lock() {
            *a = None;
        }
        let index = active.index;
        for ((ch, &n), &waiting) in self
            .channels
            .iter()
            .zip(&active.before_keyframe)
            .zip(&active.awaiting_keyframe)
        {
            let topic = &ch.spec.topic;
            if waiting && n > 0 {
                tracing::warn!(index, %topic, "{n} video frames and no keyframe: nothing of this camera was recorded");
            } else if n > 0 {
                tracing::info!(index, %topic, "{n} video frames before the first keyframe left out (undecodable)");
            }
        }
        let end_ns = now_ns();
        let duration_s = active.started.elapsed().as_secs_f64();
        let per_topic = |now: Vec<u64>, start: &[u64]| -> BTreeMap<String, u64> {
            self.channels
                .iter()
                .zip(now.iter().zip(start.iter().chain(std::iter::repeat(&0))))
                .map(|(c, (n, s))| (c.spec.topic.clone(), n.saturating_sub(*s)))
                .collect()
        };
        let dropped = per_topic(
            self.shared.counters(|c| c.dropped.load(Relaxed)),
            &active.dropped_at_start,
        );
        let gaps = per_topic(
            self.shared.counters(|c| c.upstream_gaps.load(Relaxed)),
            &active.gaps_at_start,
        );
        let counts: BTreeMap<&str, u64> = self
            .channels
            .iter()
            .zip(active.writer.message_counts())
            .map(|(c, n)| (c.spec.topic.as_str(), *n))
            .collect();
        let (outages, outage_ns) = self.shared.outage_figures();
        let link_outages = outages - active.outages_at_start.0;
        let link_outage_s = outage_ns.saturating_sub(active.outages_at_start.1) as f64 * 1e-9;
        let warnings: Vec<String> = active.warnings.iter().cloned().collect();
        let json = |v: &serde_json::Value| v.to_string();
        let mut extra = active.start_meta.extra.clone();
        extra.insert(
            keys::LATCHED_AT_START.into(),
            json(&serde_json::json!(active.latched_at_start)),
        );
        extra.insert(keys::LINK_OUTAGES.into(), link_outages.to_string());
        extra.insert(keys::LINK_OUTAGE_S.into(), format!("{link_outage_s:.3}"));
        extra.insert(keys::WARNINGS.into(), json(&serde_json::json!(warnings)));
        let meta = EpisodeMetadata {
            end_time_ns: Some(end_ns),
            duration_s: Some(duration_s),
            label: Some(outcome),
            message_counts: counts.iter().map(|(t, n)| (t.to_string(), *n)).collect(),
            dropped: dropped.clone(),
            upstream_gaps: gaps.clone(),
            extra,
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
                    "dropped": dropped, "upstream_gaps": gaps, "link_outages": link_outages,
                    "warnings": warnings,
                }));
                let report = EpisodeReport {
                    index,
                    outcome,
                    duration_s,
                    summary,
                    dropped,
                    upstream_gaps: gaps,
                    latched_at_start: active.latched_at_start,
                    link_outages,
                    link_outage_s,
                    warnings,
                };
                let _ = self.events.send(Event::Finished(report));
            }
            Err(e) => self.report_failure(index, e),
        }
    }
}
