//! Ending an episode: its end figures (counts, drops, gaps, latched messages, link outages,
//! warnings) and its verdict when recording stops; then, at once or once the operator decides,
//! the verdict and end records, the rename into place (or `discarded/`), the event and the
//! status message.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering::Relaxed;

use scaledp_schema::episode::keys;
use scaledp_schema::EpisodeMetadata;

use super::closed::Closed;
use super::{episode_file_name, WriterThread};
use crate::control::Label;
use crate::judge::judge;
use crate::report::{EpisodeReport, Event};
use crate::state::now_ns;
use crate::verdict::VERDICT_RECORD;

impl WriterThread {
    /// Stops recording the open episode: its figures and verdict, the file left open.
    pub(super) fn close(&mut self) -> Option<Closed> {
        let active = self.active.take()?;
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
        let counts: BTreeMap<String, u64> = self
            .channels
            .iter()
            .zip(active.writer.message_counts())
            .map(|(c, n)| (c.spec.topic.clone(), *n))
            .collect();
        let (outages, outage_ns) = self.shared.outage_figures();
        let link_outages = outages - active.outages_at_start.0;
        let link_outage_s = outage_ns.saturating_sub(active.outages_at_start.1) as f64 * 1e-9;
        let verdict = judge(&self.opts.rig, &active.start_meta.task, &active.evidence);
        tracing::info!(index, "verdict: {}", verdict.line());
        let mut extra = active.start_meta.extra.clone();
        extra.insert(
            keys::LATCHED_AT_START.into(),
            serde_json::json!(active.latched_at_start).to_string(),
        );
        extra.insert(keys::LINK_OUTAGES.into(), link_outages.to_string());
        extra.insert(keys::LINK_OUTAGE_S.into(), format!("{link_outage_s:.3}"));
        let meta = EpisodeMetadata {
            end_time_ns: Some(end_ns),
            duration_s: Some(duration_s),
            message_counts: counts.clone(),
            dropped: dropped.clone(),
            upstream_gaps: gaps.clone(),
            extra,
            ..active.start_meta.clone()
        };
        Some(Closed {
            index,
            writer: active.writer,
            meta,
            verdict,
            duration_s,
            counts,
            dropped,
            gaps,
            latched_at_start: active.latched_at_start,
            link_outages,
            link_outage_s,
            warnings: active.warnings.into_iter().collect(),
            prestart: active.prestart,
            cut: None,
        })
    }

    /// Closes the open episode and finishes its file as `outcome`.
    pub(super) fn stop(&mut self, outcome: Label) {
        if let Some(closed) = self.close() {
            self.finalize(closed, outcome);
        }
    }

    /// Closes the open episode and holds it for the operator's decision.
    pub(super) fn end(&mut self) {
        let Some(closed) = self.close() else { return };
        let index = closed.index;
        self.publish_status(&serde_json::json!({
            "event": "ended", "episode": index, "verdict": closed.verdict,
        }));
        let _ = self.events.send(Event::Ended {
            index,
            verdict: closed.verdict.clone(),
        });
        if let Ok(mut h) = self.shared.held.lock() {
            *h = Some(index);
        }
        self.held = Some(closed);
    }

    /// Writes the verdict and end records of `closed` with `outcome`, and renames the file into
    /// place (`discarded/` for a discarded episode).
    pub(super) fn finalize(&mut self, closed: Closed, outcome: Label) {
        if let Ok(mut h) = self.shared.held.lock() {
            *h = None;
        }
        let Closed {
            index,
            mut writer,
            mut meta,
            verdict,
            duration_s,
            counts,
            dropped,
            gaps,
            latched_at_start,
            link_outages,
            link_outage_s,
            warnings,
            prestart,
            cut,
            ..
        } = closed;
        meta.label = Some(outcome);
        meta.extra.insert(
            keys::WARNINGS.into(),
            serde_json::json!(warnings).to_string(),
        );
        let dest: Option<PathBuf> = (outcome == Label::Discarded).then(|| {
            self.opts
                .out_dir
                .join("discarded")
                .join(episode_file_name(index))
        });
        let finished = writer
            .write_metadata(VERDICT_RECORD, verdict.record())
            .and_then(|()| writer.finish(meta.end_record(), dest.as_deref()));
        let summary = match finished {
            Ok(summary) => summary,
            Err(e) => {
                self.report_failure(index, e);
                return;
            }
        };
        let file_bytes = std::fs::metadata(&summary.path).map_or(0, |m| m.len());
        self.disk.finished(file_bytes, duration_s);
        if outcome != Label::Discarded {
            self.last_finished = Some((index, summary.path.clone()));
        }
        tracing::info!(index, %outcome, path = %summary.path.display(), "episode finished");
        self.publish_status(&serde_json::json!({
            "event": "finished", "episode": index, "outcome": outcome.as_str(),
            "path": summary.path.display().to_string(), "messages": counts, "bytes": summary.bytes,
            "dropped": dropped, "upstream_gaps": gaps, "link_outages": link_outages,
            "warnings": warnings, "verdict": verdict, "cut": cut,
        }));
        let report = EpisodeReport {
            index,
            outcome,
            duration_s,
            summary,
            dropped,
            upstream_gaps: gaps,
            latched_at_start,
            link_outages,
            link_outage_s,
            warnings,
            verdict,
            cut,
            started_with_missing_topics: prestart,
            file_bytes,
        };
        let _ = self.events.send(Event::Finished(report));
    }

    /// Moves the episode finished last to `discarded/` (its records say how it was labelled).
    pub(super) fn discard_last(&mut self) {
        let Some((index, path)) = self.last_finished.take() else {
            tracing::debug!("no episode to discard");
            return;
        };
        let dir = self.opts.out_dir.join("discarded");
        let dest = dir.join(episode_file_name(index));
        let moved = std::fs::create_dir_all(&dir).and_then(|()| std::fs::rename(&path, &dest));
        if let Err(e) = moved {
            tracing::error!("{}: not moved to {}: {e}", path.display(), dir.display());
            return;
        }
        tracing::info!(index, path = %dest.display(), "episode discarded");
        self.publish_status(&serde_json::json!({
            "event": "discarded", "episode": index, "path": dest.display().to_string(),
        }));
        let _ = self.events.send(Event::Discarded { index, path: dest });
    }
}
