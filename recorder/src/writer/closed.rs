//! An episode that stopped recording: its file still open, what its end record and report will
//! say, and its verdict; held until it is labelled, kept, discarded or re-recorded.

use std::collections::BTreeMap;

use scaledp_schema::EpisodeMetadata;

use crate::episode::EpisodeWriter;
use crate::verdict::Verdict;

pub(crate) struct Closed {
    pub index: u64,
    pub writer: EpisodeWriter,
    /// The end record but its label.
    pub meta: EpisodeMetadata,
    pub verdict: Verdict,
    pub duration_s: f64,
    pub counts: BTreeMap<String, u64>,
    pub dropped: BTreeMap<String, u64>,
    pub gaps: BTreeMap<String, u64>,
    pub latched_at_start: BTreeMap<String, u64>,
    pub link_outages: u64,
    pub link_outage_s: f64,
    pub warnings: Vec<String>,
    pub prestart: Vec<String>,
    /// Why the recorder ended it itself.
    pub cut: Option<String>,
}
