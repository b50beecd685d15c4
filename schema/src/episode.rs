//! The metadata contract of a recorded episode: the two MCAP metadata records `scaledp record`
//! writes (and the simulator's synthetic episodes, and `scaledp eval`'s rollouts), and how the
//! converter reads them back.
//!
//! - [`START_RECORD`] (`scaledp.episode.start`) is written right after the channels, so a file
//!   cut by a crash still names its task, operator and rig.
//! - [`END_RECORD`] (`scaledp.episode`) is written when the episode ends: every start key again,
//!   plus end time, duration, the operator's [`Label`], and per-topic message, drop and gap counts.
//!
//! Both are flat string maps, as MCAP metadata records are; [`EpisodeMetadata`] is the typed view.
//! Unknown keys are kept in [`EpisodeMetadata::extra`], so a newer writer's keys survive a round
//! trip through an older reader.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

/// Name of the metadata record written when an episode starts.
pub const START_RECORD: &str = "scaledp.episode.start";
/// Name of the metadata record written when an episode ends.
pub const END_RECORD: &str = "scaledp.episode";

/// The keys of the two records, one constant each so no crate spells them on its own.
pub mod keys {
    /// The episode's number in its directory (`episode_NNNNNN.mcap`).
    pub const EPISODE_INDEX: &str = "episode_index";
    /// The task instruction.
    pub const TASK: &str = "task";
    /// Who teleoperated (or `scripted-expert`, `policy:<checkpoint>`).
    pub const OPERATOR: &str = "operator";
    /// The rig's name.
    pub const RIG_NAME: &str = "rig_name";
    /// The whole rig description as TOML.
    pub const RIG: &str = "rig";
    /// Start time, ns since the Unix epoch.
    pub const START_TIME_NS: &str = "start_time_ns";
    /// Start time, RFC 3339 (for people).
    pub const START_TIME: &str = "start_time";
    /// Version of the program that wrote the file.
    pub const RECORDER_VERSION: &str = "recorder_version";
    /// Set on episodes the simulator wrote straight to disk (`seed N`).
    pub const SYNTHETIC: &str = "synthetic";
    /// End time, ns since the Unix epoch.
    pub const END_TIME_NS: &str = "end_time_ns";
    /// End time, RFC 3339.
    pub const END_TIME: &str = "end_time";
    /// Duration in seconds.
    pub const DURATION_S: &str = "duration_s";
    /// The operator's label, see [`super::Label`].
    pub const OUTCOME: &str = "outcome";
    /// JSON object: messages written per topic.
    pub const MESSAGE_COUNTS: &str = "message_counts";
    /// JSON object: messages dropped by the recorder's queue per topic.
    pub const DROPPED: &str = "dropped";
    /// JSON object: messages lost upstream per topic (rmw_zenoh sequence gaps).
    pub const UPSTREAM_GAPS: &str = "upstream_gaps";
    /// JSON object: per latched topic (`/tf_static`), the messages kept from before the
    /// episode and written at its start (kept in [`super::EpisodeMetadata::extra`]).
    pub const LATCHED_AT_START: &str = "latched_at_start";
    /// Times every Zenoh link was lost during the episode (a bridge or peer restarting).
    pub const LINK_OUTAGES: &str = "link_outages";
    /// Seconds without any Zenoh link during the episode.
    pub const LINK_OUTAGE_S: &str = "link_outage_s";
    /// JSON array: what the recorder noticed, one line each naming the topic (depth in an
    /// encoding the rig does not declare, a `camera_info` of another size than its images, a
    /// latched topic with nothing to write at the start).
    pub const WARNINGS: &str = "warnings";
}

/// How the operator labelled an episode (stored under `outcome`). Not to be confused with the
/// result of converting an episode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Label {
    /// The demonstration succeeded.
    Success,
    /// The demonstration failed (kept: failures are data too).
    Failure,
    /// Thrown away by the operator; the file moves to `discarded/`.
    Discarded,
    /// Ended without a verdict (plain `stop`, unattended runs, quitting mid-episode).
    Unlabeled,
}

impl Label {
    /// The word stored in metadata.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Success => "success",
            Self::Failure => "failure",
            Self::Discarded => "discarded",
            Self::Unlabeled => "unlabeled",
        }
    }
}

impl fmt::Display for Label {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Label {
    type Err = MetadataError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s {
            "success" => Self::Success,
            "failure" => Self::Failure,
            "discarded" => Self::Discarded,
            "unlabeled" => Self::Unlabeled,
            _ => {
                return Err(MetadataError {
                    key: keys::OUTCOME,
                    value: s.to_string(),
                })
            }
        })
    }
}

/// A key of an episode record holds a value of the wrong form.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("episode metadata: {key} = {value:?} is not valid")]
pub struct MetadataError {
    /// The key.
    pub key: &'static str,
    /// The value found.
    pub value: String,
}

/// Everything the two records say about an episode, typed. Fields the end record adds are
/// `None` (or empty) for a file that only has its start record.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EpisodeMetadata {
    /// The episode's number in its directory.
    pub episode_index: Option<u64>,
    /// The task instruction ("" when none was given).
    pub task: String,
    /// Who teleoperated.
    pub operator: String,
    /// The rig's name.
    pub rig_name: String,
    /// The rig description as TOML, when stored.
    pub rig_toml: Option<String>,
    /// Start, ns since the Unix epoch.
    pub start_time_ns: Option<u64>,
    /// Version of the writer.
    pub recorder_version: Option<String>,
    /// `seed N` for the simulator's synthetic episodes.
    pub synthetic: Option<String>,
    /// End, ns since the Unix epoch.
    pub end_time_ns: Option<u64>,
    /// Duration in seconds.
    pub duration_s: Option<f64>,
    /// The operator's label.
    pub label: Option<Label>,
    /// Messages written per topic.
    pub message_counts: BTreeMap<String, u64>,
    /// Messages the recorder's queue dropped per topic.
    pub dropped: BTreeMap<String, u64>,
    /// Messages lost before the recorder per topic.
    pub upstream_gaps: BTreeMap<String, u64>,
    /// Keys this version does not know, kept as they were.
    pub extra: BTreeMap<String, String>,
}

impl EpisodeMetadata {
    /// The `scaledp.episode.start` record: what is known when the episode opens.
    pub fn start_record(&self) -> BTreeMap<String, String> {
        let mut m = self.extra.clone();
        let mut put = |k: &str, v: String| {
            m.insert(k.to_string(), v);
        };
        if let Some(i) = self.episode_index {
            put(keys::EPISODE_INDEX, i.to_string());
        }
        put(keys::TASK, self.task.clone());
        put(keys::OPERATOR, self.operator.clone());
        put(keys::RIG_NAME, self.rig_name.clone());
        if let Some(rig) = &self.rig_toml {
            put(keys::RIG, rig.clone());
        }
        if let Some(ns) = self.start_time_ns {
            put(keys::START_TIME_NS, ns.to_string());
            put(keys::START_TIME, rfc3339_millis(ns));
        }
        if let Some(v) = &self.recorder_version {
            put(keys::RECORDER_VERSION, v.clone());
        }
        if let Some(s) = &self.synthetic {
            put(keys::SYNTHETIC, s.clone());
        }
        m
    }

    /// The `scaledp.episode` record: the start keys plus what is known at the end.
    pub fn end_record(&self) -> BTreeMap<String, String> {
        let mut m = self.start_record();
        let json = |x: &BTreeMap<String, u64>| serde_json::to_string(x).unwrap_or_default();
        if let Some(ns) = self.end_time_ns {
            m.insert(keys::END_TIME_NS.into(), ns.to_string());
            m.insert(keys::END_TIME.into(), rfc3339_millis(ns));
        }
        if let Some(d) = self.duration_s {
            m.insert(keys::DURATION_S.into(), format!("{d:.3}"));
        }
        if let Some(l) = self.label {
            m.insert(keys::OUTCOME.into(), l.as_str().into());
        }
        m.insert(keys::MESSAGE_COUNTS.into(), json(&self.message_counts));
        m.insert(keys::DROPPED.into(), json(&self.dropped));
        m.insert(keys::UPSTREAM_GAPS.into(), json(&self.upstream_gaps));
        m
    }

    /// Reads one record (start or end). Missing keys stay empty; a key of the wrong form is an
    /// error naming it.
    pub fn from_record(record: &BTreeMap<String, String>) -> Result<Self, MetadataError> {
        let mut m = Self::default();
        for (k, v) in record {
            let bad = |key: &'static str| MetadataError {
                key,
                value: v.clone(),
            };
            let int = |key: &'static str| v.trim().parse::<u64>().map_err(|_| bad(key));
            let counts = |key: &'static str| {
                if v.trim().is_empty() {
                    Ok(BTreeMap::new())
                } else {
                    serde_json::from_str::<BTreeMap<String, u64>>(v).map_err(|_| bad(key))
                }
            };
            match k.as_str() {
                keys::EPISODE_INDEX => m.episode_index = Some(int(keys::EPISODE_INDEX)?),
                keys::TASK => m.task = v.clone(),
                keys::OPERATOR => m.operator = v.clone(),
                keys::RIG_NAME => m.rig_name = v.clone(),
                keys::RIG => m.rig_toml = Some(v.clone()),
                keys::START_TIME_NS => m.start_time_ns = Some(int(keys::START_TIME_NS)?),
                keys::RECORDER_VERSION => m.recorder_version = Some(v.clone()),
                keys::SYNTHETIC => m.synthetic = Some(v.clone()),
                keys::END_TIME_NS => m.end_time_ns = Some(int(keys::END_TIME_NS)?),
                keys::DURATION_S => {
                    m.duration_s = Some(v.trim().parse().map_err(|_| bad(keys::DURATION_S))?)
                }
                keys::OUTCOME => m.label = Some(v.parse()?),
                keys::MESSAGE_COUNTS => m.message_counts = counts(keys::MESSAGE_COUNTS)?,
                keys::DROPPED => m.dropped = counts(keys::DROPPED)?,
                keys::UPSTREAM_GAPS => m.upstream_gaps = counts(keys::UPSTREAM_GAPS)?,
                // Derived from the `_ns` keys: not kept twice.
                keys::START_TIME | keys::END_TIME => {}
                _ => {
                    m.extra.insert(k.clone(), v.clone());
                }
            }
        }
        Ok(m)
    }

    /// Reads a file's metadata records (by record name, as an MCAP reader returns them): the
    /// end record when there is one, else the start record (a file cut by a crash), else
    /// `None` (a file not written by scaledp).
    pub fn from_records(
        records: &BTreeMap<String, BTreeMap<String, String>>,
    ) -> Option<Result<Self, MetadataError>> {
        records
            .get(END_RECORD)
            .or_else(|| records.get(START_RECORD))
            .map(Self::from_record)
    }
}

/// `ns` since the Unix epoch as RFC 3339 UTC with milliseconds, e.g. `2026-11-23T08:15:02.125Z`.
pub fn rfc3339_millis(ns: u64) -> String {
    let secs = ns / 1_000_000_000;
    let millis = (ns / 1_000_000) % 1000;
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let (y, mo, d) = civil_from_days(days);
    format!(
        "{y:04}-{mo:02}-{d:02}T{:02}:{:02}:{:02}.{millis:03}Z",
        rem / 3600,
        (rem / 60) % 60,
        rem % 60
    )
}

/// Days since 1970-01-01 → (year, month, day), Howard Hinnant's `civil_from_days`.
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rfc3339_matches_known_instants() {
        assert_eq!(rfc3339_millis(0), "1970-01-01T00:00:00.000Z");
        // 2000-02-29 (a leap day in a century leap year) 12:34:56.789 UTC = 951827696.789 s.
        assert_eq!(
            rfc3339_millis(951_827_696_789_000_000),
            "2000-02-29T12:34:56.789Z"
        );
        // 2026-11-23T00:00:00Z = 1795392000 s.
        assert_eq!(
            rfc3339_millis(1_795_392_000_000_000_000),
            "2026-11-23T00:00:00.000Z"
        );
    }

    #[test]
    fn records_round_trip_and_keep_unknown_keys() {
        let meta = EpisodeMetadata {
            episode_index: Some(3),
            task: "stack the cubes".into(),
            operator: "ada".into(),
            rig_name: "franka_2zed".into(),
            rig_toml: Some("name = \"franka_2zed\"\n".into()),
            start_time_ns: Some(1_700_000_000_123_000_000),
            recorder_version: Some("0.1.0".into()),
            synthetic: None,
            end_time_ns: Some(1_700_000_010_123_000_000),
            duration_s: Some(10.0),
            label: Some(Label::Failure),
            message_counts: BTreeMap::from([("/a".into(), 10)]),
            dropped: BTreeMap::from([("/a".into(), 1)]),
            upstream_gaps: BTreeMap::new(),
            extra: BTreeMap::from([("site".into(), "lab 2".into())]),
        };
        let end = meta.end_record();
        assert_eq!(end[keys::OUTCOME], "failure");
        assert_eq!(end[keys::START_TIME], "2023-11-14T22:13:20.123Z");
        assert_eq!(EpisodeMetadata::from_record(&end).unwrap(), meta);
        let start = EpisodeMetadata::from_record(&meta.start_record()).unwrap();
        assert_eq!(start.label, None);
        assert_eq!(start.task, meta.task);
        let records = BTreeMap::from([(START_RECORD.to_string(), meta.start_record())]);
        assert_eq!(
            EpisodeMetadata::from_records(&records).unwrap().unwrap(),
            start
        );
        assert!(EpisodeMetadata::from_records(&BTreeMap::new()).is_none());
    }

    #[test]
    fn a_malformed_value_names_its_key() {
        let bad = BTreeMap::from([(keys::OUTCOME.to_string(), "maybe".to_string())]);
        let e = EpisodeMetadata::from_record(&bad).unwrap_err();
        assert_eq!(e.key, keys::OUTCOME);
        let bad = BTreeMap::from([(keys::MESSAGE_COUNTS.to_string(), "{".to_string())]);
        assert_eq!(
            EpisodeMetadata::from_record(&bad).unwrap_err().key,
            keys::MESSAGE_COUNTS
        );
    }
}
