//! Whether the rig's topics are live at the rates the rig gives them: the check before an
//! episode starts. Rates are counted over the last few seconds (a window of counter snapshots
//! the writer takes as it goes); a topic is silent when nothing came for five of its periods
//! (at least half a second), slow below 80 % of its rate. Latched topics must have delivered
//! something; further topics without a rate are not checked. Command topics are named but do
//! not hold a start back: a leader that publishes only while it moves is silent before it.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use scaledp_schema::rig::{TopicKind, TopicSpec};

/// How long snapshots are kept: rates are averaged over up to this span.
const WINDOW: Duration = Duration::from_secs(3);
/// Snapshots closer together than this are not kept.
const MIN_STEP: Duration = Duration::from_millis(200);
/// A rate is judged over at least this span…
const MIN_SPAN_S: f64 = 1.0;
/// …and at least this many expected messages (a 1 Hz topic over 2 s says nothing).
const MIN_EXPECTED_MESSAGES: f64 = 10.0;
/// Below this fraction of its rate a topic is slow.
pub const SLOW_FRACTION: f64 = 0.8;
/// Silent after this many periods without a message…
const SILENT_PERIODS: f64 = 5.0;
/// …but never less than this (s).
const MIN_SILENCE_S: f64 = 0.5;

/// Counter snapshots of the last few seconds.
#[derive(Debug, Default)]
pub(crate) struct RateWindow {
    samples: VecDeque<(Instant, Vec<u64>, Vec<u64>)>,
}

/// Rates measured over a window.
#[derive(Debug, Clone, Default)]
pub(crate) struct Rates {
    /// The span measured (s).
    pub span_s: f64,
    /// Messages per second, per topic.
    pub hz: Vec<f64>,
    /// Payload bytes per second, all topics.
    pub bytes_per_s: f64,
}

impl RateWindow {
    /// Keeps a snapshot of the per-topic `received` and `bytes` counters taken `at`.
    pub fn push(&mut self, at: Instant, received: Vec<u64>, bytes: Vec<u64>) {
        if self
            .samples
            .back()
            .is_some_and(|(t, _, _)| at.saturating_duration_since(*t) < MIN_STEP)
        {
            return;
        }
        self.samples.push_back((at, received, bytes));
        while self
            .samples
            .front()
            .is_some_and(|(t, _, _)| at.saturating_duration_since(*t) > WINDOW)
        {
            self.samples.pop_front();
        }
    }

    /// Rates from the oldest snapshot to the counters `now`; None before any snapshot.
    pub fn rates(&self, now: Instant, received: &[u64], bytes: &[u64]) -> Option<Rates> {
        let (at, r0, b0) = self.samples.front()?;
        let span_s = now.saturating_duration_since(*at).as_secs_f64();
        if span_s <= 0.0 {
            return None;
        }
        let delta = |now: &[u64], then: &[u64], i: usize| {
            now[i].saturating_sub(then.get(i).copied().unwrap_or(0)) as f64
        };
        let hz = (0..received.len())
            .map(|i| delta(received, r0, i) / span_s)
            .collect();
        let bytes_per_s = (0..bytes.len()).map(|i| delta(bytes, b0, i)).sum::<f64>() / span_s;
        Some(Rates {
            span_s,
            hz,
            bytes_per_s,
        })
    }
}

/// What the check found on one topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LiveState {
    /// At its rate (or, without one, delivered).
    Live,
    /// Below [`SLOW_FRACTION`] of its rate.
    Slow,
    /// Delivered before, nothing lately.
    Silent,
    /// Nothing received since the session opened.
    Never,
    /// Not judged (a further topic without a rate).
    Unchecked,
}

/// One topic's liveness.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicLive {
    /// ROS 2 topic.
    pub topic: String,
    /// The rig's rate (Hz), when it gives one.
    pub expected_hz: Option<f64>,
    /// Measured over the last seconds, when measured long enough.
    pub rate_hz: Option<f64>,
    /// Seconds since its latest message, when it had one.
    pub silent_s: Option<f64>,
    /// The finding.
    pub state: LiveState,
    /// Whether it holds a start back (command topics do not).
    pub blocking: bool,
}

impl TopicLive {
    /// The finding in words, None when live or unchecked.
    pub fn problem(&self) -> Option<String> {
        let t = &self.topic;
        Some(match self.state {
            LiveState::Live | LiveState::Unchecked => return None,
            LiveState::Never => format!("{t}: nothing received"),
            LiveState::Silent => format!("{t}: silent for {:.1} s", self.silent_s.unwrap_or(0.0)),
            LiveState::Slow => format!(
                "{t}: {:.1} Hz, the rig expects {}",
                self.rate_hz.unwrap_or(0.0),
                hz(self.expected_hz.unwrap_or(0.0))
            ),
        })
    }
}

/// A rate as people write it: `30 Hz`, `12.5 Hz`.
pub(crate) fn hz(r: f64) -> String {
    if (r - r.round()).abs() < 0.05 {
        format!("{r:.0} Hz")
    } else {
        format!("{r:.1} Hz")
    }
}

/// The rig's topics, live or not.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Liveness {
    /// The rig's topics, in rig order.
    pub topics: Vec<TopicLive>,
    /// Seconds the rates were measured over (0 before a second of measurements).
    pub span_s: f64,
}

impl Liveness {
    /// What holds a start back, one line per topic.
    pub fn problems(&self) -> Vec<String> {
        self.topics
            .iter()
            .filter(|t| t.blocking)
            .filter_map(TopicLive::problem)
            .collect()
    }
    /// What is off but does not hold a start back (command topics).
    pub fn notes(&self) -> Vec<String> {
        self.topics
            .iter()
            .filter(|t| !t.blocking)
            .filter_map(TopicLive::problem)
            .collect()
    }
    /// True when nothing holds a start back.
    pub fn is_ready(&self) -> bool {
        self.problems().is_empty()
    }
}

/// What [`judge`] looks at, per topic of the session (the rig's first).
pub(crate) struct Observed<'a> {
    pub specs: &'a [TopicSpec],
    /// How many of `specs` are the rig's.
    pub rig_topics: usize,
    pub received: &'a [u64],
    /// Receive time of each topic's latest message (ns since the epoch, 0 for none).
    pub last_ns: &'a [u64],
    pub rates: Option<&'a Rates>,
    pub now_ns: u64,
}

/// The liveness of the rig's topics.
pub(crate) fn judge(o: &Observed<'_>) -> Liveness {
    let span_s = o.rates.map_or(0.0, |r| r.span_s);
    let topics = o
        .specs
        .iter()
        .take(o.rig_topics)
        .enumerate()
        .map(|(i, spec)| {
            let expected = (spec.rate_hz > 0.0).then_some(spec.rate_hz);
            let received = o.received.get(i).copied().unwrap_or(0);
            let last = o.last_ns.get(i).copied().unwrap_or(0);
            let silent_s = (last > 0).then(|| o.now_ns.saturating_sub(last) as f64 * 1e-9);
            let rate_hz = o
                .rates
                .filter(|r| r.span_s >= MIN_SPAN_S)
                .and_then(|r| r.hz.get(i).copied());
            let state = match expected {
                _ if received == 0 && (expected.is_some() || spec.latched) => LiveState::Never,
                None => LiveState::Unchecked,
                Some(r) => {
                    let limit = (SILENT_PERIODS / r).max(MIN_SILENCE_S);
                    let judged = rate_hz.filter(|_| r * span_s >= MIN_EXPECTED_MESSAGES);
                    if silent_s.is_some_and(|s| s > limit) {
                        LiveState::Silent
                    } else if judged.is_some_and(|m| m < SLOW_FRACTION * r) {
                        LiveState::Slow
                    } else {
                        LiveState::Live
                    }
                }
            };
            TopicLive {
                topic: spec.topic.clone(),
                expected_hz: expected,
                rate_hz,
                silent_s,
                state,
                blocking: spec.kind != TopicKind::Command,
            }
        })
        .collect();
    Liveness { topics, span_s }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scaledp_schema::Rig;

    #[test]
    fn missing_slow_and_silent_topics_are_named_commands_do_not_block() {
        let rig = Rig::builtin("franka_sim").expect("shipped rig");
        let specs = rig.topics();
        let n = specs.len();
        let t0 = Instant::now();
        let mut w = RateWindow::default();
        w.push(t0, vec![0; n], vec![0; n]);
        // Two seconds later: every topic at its rate but the first camera (silent from the
        // start), the second at half its rate, the joints silent for a second.
        let now = t0 + Duration::from_secs(2);
        let received: Vec<u64> = specs
            .iter()
            .enumerate()
            .map(|(i, s)| match i {
                0 => 0,
                1 => (s.rate_hz * 1.0) as u64,
                _ => (s.rate_hz * 2.0) as u64,
            })
            .collect();
        let rates = w.rates(now, &received, &vec![100; n]).expect("rates");
        assert!((rates.bytes_per_s - 50.0 * n as f64).abs() < 1e-6);
        let now_ns = 10_000_000_000;
        let joints = specs
            .iter()
            .position(|s| s.kind == TopicKind::Joints)
            .expect("joints");
        let last_ns: Vec<u64> = (0..n)
            .map(|i| match i {
                0 => 0,
                i if i == joints => now_ns - 1_000_000_000,
                _ => now_ns - 1_000_000,
            })
            .collect();
        let command = specs
            .iter()
            .position(|s| s.kind == TopicKind::Command)
            .expect("a command topic");
        let mut received = received;
        received[command] = 0;
        let live = judge(&Observed {
            specs: &specs,
            rig_topics: n,
            received: &received,
            last_ns: &last_ns,
            rates: Some(&rates),
            now_ns,
        });
        let problems = live.problems();
        assert_eq!(problems.len(), 3, "{problems:?}");
        assert_eq!(problems[0], format!("{}: nothing received", specs[0].topic));
        assert!(problems[1].starts_with(&specs[1].topic), "{problems:?}");
        assert!(
            problems[1].ends_with("Hz, the rig expects 30 Hz"),
            "{problems:?}"
        );
        assert_eq!(
            problems[2],
            format!("{}: silent for 1.0 s", specs[joints].topic)
        );
        assert_eq!(live.notes().len(), 1, "the silent command topic is a note");
        assert!(!live.is_ready());
    }

    #[test]
    fn the_window_keeps_a_few_seconds() {
        let t0 = Instant::now();
        let mut w = RateWindow::default();
        for k in 0..100u64 {
            w.push(t0 + Duration::from_millis(100 * k), vec![k], vec![k]);
        }
        // Every other snapshot kept (200 ms apart), none older than 3 s.
        let now = t0 + Duration::from_millis(9_900);
        let r = w.rates(now, &[99], &[99]).expect("rates");
        assert!(r.span_s <= 3.2 && r.span_s > 2.5, "{}", r.span_s);
        assert!((r.hz[0] - 10.0).abs() < 0.5, "{}", r.hz[0]);
    }
}
