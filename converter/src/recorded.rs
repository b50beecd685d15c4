//! What the recording says about an episode beyond its messages, as the dataset keeps it per
//! episode (`scaledp/operator`, `scaledp/label`, `scaledp/verdict*` in `meta/episodes/`): who
//! teleoperated, the operator's label, and the verdict on the episode — the recorder's
//! (`scaledp.verdict`, taken when the episode ended, by the converter's own rules at their
//! defaults) when the file has one, else what this conversion's alignment measured.

use std::collections::BTreeMap;

use scaledp_schema::{EpisodeMetadata, Label};
use serde::{Deserialize, Serialize};

use scaledp_align::AlignmentReport;

/// Name of the metadata record in which `scaledp record` stores its verdict on an episode.
pub const VERDICT_RECORD: &str = "scaledp.verdict";

/// Who judged an episode: the recorder when it ended, or the conversion itself.
pub const VERDICT_BY_RECORDER: &str = "record";
/// See [`VERDICT_BY_RECORDER`].
pub const VERDICT_BY_CONVERT: &str = "convert";

/// A verdict on an episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Verdict {
    /// [`VERDICT_BY_RECORDER`] or [`VERDICT_BY_CONVERT`].
    pub by: String,
    /// Whether `scaledp convert` at its default settings takes the episode (the recorder's
    /// judgement; always true for convert's own: an episode it stored, it took).
    pub accepted: bool,
    /// Why not, when not accepted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// The verdict in one line, with its figures.
    pub line: String,
}

/// The operator, label and verdict of one episode.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Recorded {
    /// Who teleoperated ("" when the recording does not say).
    #[serde(default)]
    pub operator: String,
    /// `success`, `failure` or `unlabeled` (a recording without a label, ours or a foreign
    /// one). None only in datasets converted before labels were kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub label: Option<String>,
    /// The verdict. None only in datasets converted before verdicts were kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
}

impl Recorded {
    /// True when nothing is known (a dataset converted before these were kept).
    pub fn is_empty(&self) -> bool {
        self == &Self::default()
    }
}

/// The operator's label, [`Label::Unlabeled`] when the recording has none.
pub(crate) fn label_of(meta: Option<&EpisodeMetadata>) -> Label {
    meta.and_then(|m| m.label).unwrap_or(Label::Unlabeled)
}

/// The recorder's verdict stored in `records` (MCAP metadata records by name), if any.
fn recorder_verdict(records: &BTreeMap<String, BTreeMap<String, String>>) -> Option<Verdict> {
    let r = records.get(VERDICT_RECORD)?;
    let accepted = r.get("accepted")? == "true";
    let reason = r.get("reason").filter(|s| !s.is_empty()).cloned();
    let line = r
        .get("line")
        .cloned()
        .or_else(|| reason.clone())
        .unwrap_or_else(|| if accepted { "accepted" } else { "rejected" }.into());
    Some(Verdict {
        by: VERDICT_BY_RECORDER.into(),
        accepted,
        reason,
        line,
    })
}

/// `12 ms`, `1.40 s`.
fn secs(s: f64) -> String {
    if s < 1.0 {
        format!("{:.0} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

/// The conversion's own verdict, from what alignment measured at `fps`.
fn convert_verdict(report: &AlignmentReport, fps: f64) -> Verdict {
    let dropped: u64 = report.streams.iter().map(|s| s.dropped).sum();
    let mut line = format!(
        "accepted: {:.1} s kept, {} ticks, {} invalid, {} trimmed, camera skew {}, oldest frame {}, {dropped} frames or samples dropped",
        report.ticks as f64 / fps.max(1e-9),
        report.ticks,
        report.invalid,
        report.trimmed,
        secs(report.max_camera_skew_s),
        secs(report.max_frame_age_s),
    );
    if let Some(s) = report
        .streams
        .iter()
        .filter(|s| s.messages > 1)
        .max_by(|a, b| a.max_interval_s.total_cmp(&b.max_interval_s))
    {
        line.push_str(&format!(
            ", longest gap {} ({})",
            secs(s.max_interval_s),
            s.topic
        ));
    }
    Verdict {
        by: VERDICT_BY_CONVERT.into(),
        accepted: true,
        reason: None,
        line,
    }
}

/// What the dataset keeps of an episode read from a recording with metadata `records`, aligned
/// as `report` says at `fps`.
pub(crate) fn recorded(
    records: &BTreeMap<String, BTreeMap<String, String>>,
    meta: Option<&EpisodeMetadata>,
    report: &AlignmentReport,
    fps: f64,
) -> Recorded {
    Recorded {
        operator: meta.map(|m| m.operator.clone()).unwrap_or_default(),
        label: Some(label_of(meta).as_str().to_string()),
        verdict: Some(recorder_verdict(records).unwrap_or_else(|| convert_verdict(report, fps))),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use scaledp_align::StreamReport;

    #[test]
    fn the_recorders_verdict_is_taken_when_there_else_converts_own() {
        let report = AlignmentReport {
            ticks: 25,
            invalid: 1,
            max_camera_skew_s: 0.004,
            max_frame_age_s: 0.041,
            streams: vec![StreamReport {
                topic: "/cam".into(),
                messages: 80,
                dropped: 2,
                max_interval_s: 0.1,
                ..StreamReport::default()
            }],
            ..AlignmentReport::default()
        };
        let meta = EpisodeMetadata {
            operator: "ana".into(),
            label: Some(Label::Failure),
            ..EpisodeMetadata::default()
        };
        let none = BTreeMap::new();
        let r = recorded(&none, Some(&meta), &report, 10.0);
        assert_eq!(
            (r.operator.as_str(), r.label.as_deref()),
            ("ana", Some("failure"))
        );
        let v = r.verdict.unwrap();
        assert_eq!((v.by.as_str(), v.accepted), (VERDICT_BY_CONVERT, true));
        assert_eq!(
            v.line,
            "accepted: 2.5 s kept, 25 ticks, 1 invalid, 0 trimmed, camera skew 4 ms, oldest \
             frame 41 ms, 2 frames or samples dropped, longest gap 100 ms (/cam)"
        );

        let mut records = BTreeMap::new();
        records.insert(
            VERDICT_RECORD.to_string(),
            BTreeMap::from([
                ("accepted".to_string(), "false".to_string()),
                (
                    "reason".to_string(),
                    "fewer than 2 aligned ticks".to_string(),
                ),
                ("line".to_string(), "convert would reject it: …".to_string()),
            ]),
        );
        let r = recorded(&records, None, &report, 10.0);
        assert_eq!(
            (r.operator.as_str(), r.label.as_deref()),
            ("", Some("unlabeled"))
        );
        let v = r.verdict.unwrap();
        assert_eq!((v.by.as_str(), v.accepted), (VERDICT_BY_RECORDER, false));
        assert_eq!(v.reason.as_deref(), Some("fewer than 2 aligned ticks"));
        assert_eq!(v.line, "convert would reject it: …");
    }
}
