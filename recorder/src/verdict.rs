//! An episode's verdict: whether `scaledp convert` would take it, by the converter's own rules
//! (see [`crate::judge`]), with the figures behind it, in one line for the operator and as the
//! `scaledp.verdict` metadata record of the episode's file.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::liveness::hz;

/// Name of the metadata record holding an episode's verdict.
pub const VERDICT_RECORD: &str = "scaledp.verdict";
/// Key of the start and end records: JSON array of the rig topics missing or slow when the
/// episode started (it was started anyway), one line each.
pub const STARTED_WITH_MISSING_TOPICS: &str = "started_with_missing_topics";

/// One topic as the verdict measured it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TopicVerdict {
    /// ROS 2 topic.
    pub topic: String,
    /// Messages in the episode.
    pub messages: usize,
    /// The rig's rate (Hz), when it gives one.
    pub expected_hz: Option<f64>,
    /// Rate over the topic's own span of capture stamps (Hz; 0 with fewer than 2 messages).
    pub rate_hz: f64,
    /// Longest interval between consecutive capture stamps (s).
    pub max_gap_s: f64,
    /// Seconds between the topic's last stamp and the episode's last (a topic that stopped).
    pub stopped_early_s: f64,
    /// Seconds between the episode's first stamp and the topic's first (a topic that came late).
    pub started_late_s: f64,
    /// Whether the converter aligns on it (cameras, depth, joints, grippers).
    pub aligned: bool,
}

/// What the converter's rules say of an episode.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// `scaledp convert` (default settings) would take it.
    pub accepted: bool,
    /// Why it would not: the converter's reason, word for word.
    pub reason: Option<String>,
    /// What is off without making convert refuse it (a topic that stopped or came late, a slow
    /// topic, one without messages that is not aligned on).
    pub warnings: Vec<String>,
    /// The rules applied: tick rate (Hz), stale frame periods, invalid tick fraction.
    pub fps: f64,
    /// See [`scaledp_align::DEFAULT_STALE_PERIODS`].
    pub stale_periods: f64,
    /// See [`scaledp_align::DEFAULT_MAX_INVALID_FRACTION`].
    pub max_invalid_fraction: f64,
    /// Ticks convert would keep.
    pub ticks: usize,
    /// Invalid ticks trimmed at either end.
    pub trimmed: usize,
    /// Invalid ticks inside the kept range (a stale frame, a joint gap).
    pub invalid: usize,
    /// Seconds the kept ticks span.
    pub kept_s: f64,
    /// Seconds the aligned streams' stamps span.
    pub recorded_s: f64,
    /// Largest spread of the chosen cameras' stamps at a tick (s).
    pub max_camera_skew_s: f64,
    /// Oldest camera frame chosen at a tick (s).
    pub max_frame_age_s: f64,
    /// Per topic with a rate or aligned on, in rig order.
    pub topics: Vec<TopicVerdict>,
}

/// `12 ms`, `1.40 s`.
fn secs(s: f64) -> String {
    if s < 1.0 {
        format!("{:.0} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

impl Verdict {
    /// The verdict in one line, e.g. `accepted: 12.0 of 12.3 s kept, 121 ticks, 0 invalid,
    /// camera skew 4 ms, oldest frame 41 ms, longest gap 68 ms (/zed_wrist/…), every rate as
    /// the rig's` or `convert would reject it: <reason> │ …`.
    pub fn line(&self) -> String {
        let mut parts = Vec::new();
        match &self.reason {
            None => parts.push(format!(
                "accepted: {:.1} of {:.1} s kept, {} ticks, {} invalid, camera skew {}, oldest frame {}",
                self.kept_s,
                self.recorded_s,
                self.ticks,
                self.invalid,
                secs(self.max_camera_skew_s),
                secs(self.max_frame_age_s)
            )),
            Some(r) => parts.push(format!("convert would reject it: {r}")),
        }
        if let Some(t) = self
            .topics
            .iter()
            .filter(|t| t.messages > 1)
            .max_by(|a, b| a.max_gap_s.total_cmp(&b.max_gap_s))
        {
            parts.push(format!("longest gap {} ({})", secs(t.max_gap_s), t.topic));
        }
        let slow: Vec<String> = self
            .topics
            .iter()
            .filter(|t| {
                t.expected_hz.is_some_and(|e| {
                    t.messages > 1 && t.rate_hz < crate::liveness::SLOW_FRACTION * e
                })
            })
            .map(|t| {
                format!(
                    "{} {} of {}",
                    t.topic,
                    hz(t.rate_hz),
                    hz(t.expected_hz.unwrap_or(0.0))
                )
            })
            .collect();
        if slow.is_empty() {
            parts.push("every rate as the rig's".into());
        } else {
            parts.push(format!("slow: {}", slow.join(", ")));
        }
        let mut line = parts.join(", ");
        for w in &self.warnings {
            line.push_str(" │ ");
            line.push_str(w);
        }
        line
    }

    /// The `scaledp.verdict` record: `accepted`, `reason`, `line`, and the whole as `json`.
    pub fn record(&self) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("accepted".into(), self.accepted.to_string()),
            ("reason".into(), self.reason.clone().unwrap_or_default()),
            ("line".into(), self.line()),
            (
                "json".into(),
                serde_json::to_string(self).unwrap_or_default(),
            ),
        ])
    }

    /// Reads a `scaledp.verdict` record back.
    pub fn from_record(record: &BTreeMap<String, String>) -> Option<Self> {
        serde_json::from_str(record.get("json")?).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_and_records() {
        let v = Verdict {
            accepted: false,
            reason: Some("fewer than 2 aligned ticks".into()),
            warnings: vec!["/cam stopped 1.2 s before the end".into()],
            topics: vec![
                TopicVerdict {
                    topic: "/cam".into(),
                    messages: 10,
                    expected_hz: Some(30.0),
                    rate_hz: 15.0,
                    max_gap_s: 0.4,
                    ..TopicVerdict::default()
                },
                TopicVerdict {
                    topic: "/arm".into(),
                    messages: 100,
                    expected_hz: Some(100.0),
                    rate_hz: 99.0,
                    max_gap_s: 0.012,
                    ..TopicVerdict::default()
                },
            ],
            ..Verdict::default()
        };
        assert_eq!(
            v.line(),
            "convert would reject it: fewer than 2 aligned ticks, longest gap 400 ms (/cam), \
             slow: /cam 15 Hz of 30 Hz │ /cam stopped 1.2 s before the end"
        );
        let r = v.record();
        assert_eq!(r["accepted"], "false");
        assert_eq!(Verdict::from_record(&r), Some(v));
    }
}
