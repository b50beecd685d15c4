//! What a soak measured: per episode, per topic, and over the run (the JSON report's shape).

use std::collections::BTreeMap;

use serde::Serialize;

/// Resident memory may grow by at most this fraction over its value after the first episode.
pub const RSS_GROWTH_LIMIT: f64 = 0.05;

/// One topic over one episode: sent by the publisher, recorded by the recorder, dropped by its
/// queue.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct TopicCount {
    /// Ticks the publisher's schedule offered (sent + missed).
    pub offered: u64,
    /// Messages put.
    pub sent: u64,
    /// Messages in the episode's file.
    pub recorded: u64,
    /// Messages the recorder's queue dropped.
    pub dropped: u64,
    /// Payload bytes put.
    pub sent_bytes: u64,
    /// Payload bytes recorded.
    pub recorded_bytes: u64,
}

impl TopicCount {
    /// Messages sent that are not in the file.
    pub fn lost(&self) -> u64 {
        self.sent.saturating_sub(self.recorded)
    }
    /// Adds `o`.
    pub fn add(&mut self, o: &TopicCount) {
        self.offered += o.offered;
        self.sent += o.sent;
        self.recorded += o.recorded;
        self.dropped += o.dropped;
        self.sent_bytes += o.sent_bytes;
        self.recorded_bytes += o.recorded_bytes;
    }
}

/// One episode.
#[derive(Debug, Clone, Default, Serialize)]
pub struct EpisodeFigures {
    /// The recorder's episode index.
    pub index: u64,
    /// Seconds the load was on.
    pub load_s: f64,
    /// The episode's duration as the recorder measured it (start to stop).
    pub recorder_s: f64,
    /// Seconds from the end of the load until the recorder had received everything sent (or
    /// gave up waiting, see `drained`).
    pub drain_s: f64,
    /// Whether the recorder received every message sent before the episode was stopped.
    pub drained: bool,
    /// Per topic.
    pub topics: BTreeMap<String, TopicCount>,
    /// Bytes of the episode's file.
    pub file_bytes: u64,
    /// `ok`, or what the check of the file found.
    pub check: String,
    /// Why the episode ended before its time, if it did.
    pub cut: Option<String>,
    /// The recorder's CPU seconds over the episode (start to finished).
    pub cpu_s: Option<f64>,
    /// Wall seconds from `start` to `finished`.
    pub wall_s: f64,
    /// Whether the file was deleted after the check.
    pub deleted: bool,
    /// The recorder's largest resident memory sample during the episode, its end included
    /// (its working set under load, the queue's contents with it).
    pub rss_max: Option<u64>,
    /// Its resident memory once the episode had finished.
    pub rss_end: Option<u64>,
}

/// One resident memory sample: seconds since the first episode started, bytes.
pub type RssSample = (f64, u64);

/// The whole soak.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Soak {
    /// The command's settings.
    pub settings: serde_json::Value,
    /// Cores of the machine.
    pub cores: usize,
    /// The 1-minute load average before and after (other work on the machine).
    pub load_average: (Option<f64>, Option<f64>),
    /// Offered payload MB/s (the reference load at `--load`).
    pub offered_mb_s: f64,
    /// Per topic: nominal rate (Hz) and payload bytes per message.
    pub offered: BTreeMap<String, (f64, u64)>,
    /// Episodes, in order.
    pub episodes: Vec<EpisodeFigures>,
    /// Resident memory of the recorder.
    pub rss: Vec<RssSample>,
    /// The recorder's resident memory once the first episode has run: its largest sample
    /// during that episode (bytes; the working set under load, compared like with like).
    pub rss_after_first: Option<u64>,
    /// The largest sample of every later episode.
    pub rss_max_after_first: Option<u64>,
    /// The largest sample of the run.
    pub rss_peak: Option<u64>,
    /// The recorder's CPU seconds from the first start to the last finish.
    pub cpu_s: Option<f64>,
    /// Wall seconds of the same span.
    pub wall_s: f64,
    /// This process's CPU seconds over the same span (the publisher: the load's own cost).
    pub publisher_cpu_s: Option<f64>,
    /// Why the soak stopped before `--minutes`, if it did.
    pub stopped_early: Option<String>,
    /// The worker's exit code.
    pub worker_exit: Option<i32>,
}

impl Soak {
    /// Per topic over every episode.
    pub fn topic_totals(&self) -> BTreeMap<String, TopicCount> {
        let mut out: BTreeMap<String, TopicCount> = BTreeMap::new();
        for e in &self.episodes {
            for (t, c) in &e.topics {
                out.entry(t.clone()).or_default().add(c);
            }
        }
        out
    }
    /// Seconds of load over every episode.
    pub fn load_s(&self) -> f64 {
        self.episodes.iter().map(|e| e.load_s).sum()
    }
    /// Messages lost over the run.
    pub fn lost(&self) -> u64 {
        self.topic_totals().values().map(TopicCount::lost).sum()
    }
    /// Episodes whose file check found something.
    pub fn bad_files(&self) -> usize {
        self.episodes.iter().filter(|e| e.check != "ok").count()
    }
    /// Growth of resident memory after the first episode over its value then (None with one
    /// episode or no samples).
    pub fn rss_growth(&self) -> Option<f64> {
        let base = self.rss_after_first? as f64;
        let max = self.rss_max_after_first? as f64;
        (base > 0.0).then(|| max / base - 1.0)
    }
    /// The recorder's CPU time over wall time (1.0 = one core busy).
    pub fn cpu_share(&self) -> Option<f64> {
        self.cpu_s.map(|c| c / self.wall_s.max(1e-9))
    }
    /// MB written to episode files per second of recording (start to finished).
    pub fn written_mb_s(&self) -> f64 {
        let bytes: u64 = self.episodes.iter().map(|e| e.file_bytes).sum();
        let secs: f64 = self.episodes.iter().map(|e| e.wall_s).sum();
        bytes as f64 / 1e6 / secs.max(1e-9)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn losses_and_memory_growth_are_counted_from_the_episodes() {
        let ep = |sent: u64, recorded: u64| EpisodeFigures {
            topics: BTreeMap::from([(
                "/a".to_string(),
                TopicCount {
                    sent,
                    recorded,
                    ..TopicCount::default()
                },
            )]),
            check: "ok".into(),
            ..EpisodeFigures::default()
        };
        let mut s = Soak {
            episodes: vec![ep(10, 10), ep(12, 9)],
            rss_after_first: Some(200),
            rss_max_after_first: Some(209),
            ..Soak::default()
        };
        assert_eq!(s.lost(), 3);
        assert_eq!(s.topic_totals()["/a"].sent, 22);
        let g = s.rss_growth().unwrap_or(f64::NAN);
        assert!((g - 0.045).abs() < 1e-12, "{g}");
        s.rss_max_after_first = None;
        assert_eq!(s.rss_growth(), None);
        s.episodes[1].check = "no summary".into();
        assert_eq!(s.bad_files(), 1);
    }
}
