//! Time alignment on capture stamps: a uniform grid of ticks at the target rate, a quarter
//! frame after the cameras' frame instants so that synchronised cameras agree on their frames
//! (see [`first_tick`]); at each tick
//! every camera gives its latest frame at or before the tick and every joint stream is linearly
//! interpolated. A camera frame older than `stale_periods` frame periods, or a joint stream with
//! no samples around the tick, makes the tick invalid; invalid ticks at either end are trimmed,
//! interior ones are counted (and the episode rejected past a threshold).
//!
//! Its own crate because three places must apply the very same rules: `scaledp convert`
//! (training data), the recorder's verdict on each episode before the scene is reset, and
//! `serve`'s live observations; so do the stamps put in order before it ([`StampOrder`]).
//! It depends on nothing but serde and thiserror.

use serde::{Deserialize, Serialize};

mod order;
pub use order::{ClockJump, StampOrder, DEFAULT_REORDER_WINDOW_S, MAX_HOLE_NS};

/// A camera frame older than this many frame periods at its tick makes the tick invalid
/// (`scaledp convert --stale-periods`).
pub const DEFAULT_STALE_PERIODS: f64 = 1.5;
/// An episode with more invalid ticks inside its kept range than this fraction is rejected
/// (`scaledp convert --max-invalid-fraction`).
pub const DEFAULT_MAX_INVALID_FRACTION: f64 = 0.05;

/// One time series: capture stamps (ns, non-decreasing) and its nominal period (s).
#[derive(Debug, Clone)]
pub struct Stream {
    /// Topic, for reports.
    pub topic: String,
    /// Capture stamps (ns).
    pub stamps_ns: Vec<u64>,
    /// Nominal period (s): from the rig, or the median interval.
    pub period_s: f64,
}

impl Stream {
    /// A stream whose nominal period comes from `rate_hz`, or from the median interval when None.
    pub fn new(topic: &str, stamps_ns: Vec<u64>, rate_hz: Option<f64>) -> Self {
        let period_s = match rate_hz {
            Some(r) if r > 0.0 => 1.0 / r,
            _ => median_interval_s(&stamps_ns).unwrap_or(0.1),
        };
        Self {
            topic: topic.into(),
            stamps_ns,
            period_s,
        }
    }

    /// Index of the latest sample at or before `t_ns`.
    pub fn latest_at(&self, t_ns: u64) -> Option<usize> {
        latest_at(&self.stamps_ns, t_ns)
    }

    /// (i, i + 1, weight of i + 1) bracketing `t_ns`, or the exact sample.
    pub fn bracket(&self, t_ns: u64) -> Option<(usize, usize, f64)> {
        bracket(&self.stamps_ns, t_ns)
    }

    /// The frame rule, see [`frame_at`].
    pub fn frame_at(&self, t_ns: u64, stale_periods: f64) -> (usize, bool) {
        frame_at(&self.stamps_ns, self.period_s, t_ns, stale_periods)
    }

    /// The joint rule at ticks `tick_s` apart, see [`sample_at`].
    pub fn sample_at(&self, t_ns: u64, tick_s: f64) -> ((usize, usize, f64), bool) {
        sample_at(&self.stamps_ns, self.period_s, t_ns, tick_s)
    }
}

/// Index of the latest of `stamps_ns` (ascending) at or before `t_ns`.
pub fn latest_at(stamps_ns: &[u64], t_ns: u64) -> Option<usize> {
    stamps_ns.partition_point(|&s| s <= t_ns).checked_sub(1)
}

/// (i, i + 1, weight of i + 1) of `stamps_ns` bracketing `t_ns`, or the exact sample.
pub fn bracket(stamps_ns: &[u64], t_ns: u64) -> Option<(usize, usize, f64)> {
    let i = latest_at(stamps_ns, t_ns)?;
    if stamps_ns[i] == t_ns || i + 1 >= stamps_ns.len() {
        return (stamps_ns[i] == t_ns).then_some((i, i, 0.0));
    }
    let (a, b) = (stamps_ns[i], stamps_ns[i + 1]);
    Some((i, i + 1, (t_ns - a) as f64 / (b - a).max(1) as f64))
}

/// The frame rule: the latest of a camera's frames (stamps ascending, nominal period
/// `period_s`) at or before `t_ns` (the first when none is), and whether it is fresh — at or
/// before the tick and at most `stale_periods` periods old.
pub fn frame_at(stamps_ns: &[u64], period_s: f64, t_ns: u64, stale_periods: f64) -> (usize, bool) {
    let i = latest_at(stamps_ns, t_ns).unwrap_or(0);
    let s = stamps_ns.get(i).copied().unwrap_or(u64::MAX);
    let age_s = t_ns.saturating_sub(s) as f64 * 1e-9;
    (i, s <= t_ns && age_s <= stale_periods * period_s)
}

/// The joint rule: the bracket of `t_ns` in a joint stream (stamps ascending, nominal period
/// `period_s`; the first sample when there is no bracket), and whether interpolating across it
/// is sound — the samples around the tick at most [`max_hole_s`] apart, so no motion is
/// invented across a hole. `tick_s` is the period of the ticks sampled (the dataset's or the
/// controller's).
pub fn sample_at(
    stamps_ns: &[u64],
    period_s: f64,
    t_ns: u64,
    tick_s: f64,
) -> ((usize, usize, f64), bool) {
    let b = bracket(stamps_ns, t_ns);
    let gap_s = b.map_or(f64::INFINITY, |(i, k, _)| {
        (stamps_ns[k] - stamps_ns[i]) as f64 * 1e-9
    });
    (
        b.unwrap_or((0, 0, 0.0)),
        gap_s <= max_hole_s(period_s, tick_s),
    )
}

/// The widest hole (s) interpolated across in a joint stream of nominal period `period_s`
/// sampled every `tick_s`: ten periods, 50 ms, or one tick, whichever is widest. A hole no
/// wider than a tick hides no motion the ticks could resolve: a 1 kHz arm whose host stalls
/// for 60 ms (a busy machine) still gives a sound 10 Hz sample, where 50 ms alone rejected it.
pub fn max_hole_s(period_s: f64, tick_s: f64) -> f64 {
    (MAX_GAP_PERIODS * period_s).max(MIN_MAX_GAP_S).max(tick_s)
}

/// Joint samples further apart than this many periods are not interpolated across…
const MAX_GAP_PERIODS: f64 = 10.0;
/// …unless they are at most this far apart (s) or one tick apart.
const MIN_MAX_GAP_S: f64 = 0.05;

/// Median interval between consecutive stamps (s).
pub fn median_interval_s(stamps_ns: &[u64]) -> Option<f64> {
    let mut d: Vec<u64> = stamps_ns
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]))
        .filter(|&x| x > 0)
        .collect();
    if d.is_empty() {
        return None;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable(mid);
    Some(*m as f64 * 1e-9)
}

/// Gaps and drops of one stream: intervals longer than 1.5 nominal periods.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamReport {
    /// Topic.
    pub topic: String,
    /// Messages.
    pub messages: usize,
    /// Intervals longer than 1.5 periods.
    pub gaps: usize,
    /// Frames or samples missing inside those gaps.
    pub dropped: u64,
    /// Longest interval (s).
    pub max_interval_s: f64,
    /// Messages that came after a later-stamped one and were put back in stamp order.
    #[serde(default)]
    pub reordered: usize,
}

/// What alignment measured for an episode.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct AlignmentReport {
    /// Ticks kept.
    pub ticks: usize,
    /// Invalid ticks trimmed from the start and end.
    pub trimmed: usize,
    /// Invalid ticks inside the kept range (they reuse the last frame / sample).
    pub invalid: usize,
    /// Largest spread of the chosen cameras' capture stamps at one tick (s).
    pub max_camera_skew_s: f64,
    /// Largest age of a chosen camera frame at its tick (s).
    pub max_frame_age_s: f64,
    /// Per stream.
    pub streams: Vec<StreamReport>,
    /// Messages put back in stamp order, over every stream and command topic.
    #[serde(default)]
    pub reordered: usize,
}

/// The tick grid and, per tick, the chosen frame of every camera and the bracket of every
/// joint stream.
#[derive(Debug, Clone)]
pub struct Alignment {
    /// Tick times (ns).
    pub ticks_ns: Vec<u64>,
    /// `[tick][camera]` → frame index in that camera's stream.
    pub frames: Vec<Vec<usize>>,
    /// `[tick][joint stream]` → (i, j, weight of j).
    pub samples: Vec<Vec<(usize, usize, f64)>>,
    /// Measurements.
    pub report: AlignmentReport,
}

/// Ticks allowed per message of the busiest stream (see [`align`]).
const MAX_TICKS_PER_MESSAGE: usize = 4;

/// Aligns `cameras` and `joints` at `fps`. `Err` names the reason an episode cannot be aligned.
pub fn align(
    cameras: &[Stream],
    joints: &[Stream],
    fps: f64,
    stale_periods: f64,
    max_invalid_fraction: f64,
) -> Result<Alignment, String> {
    let all: Vec<&Stream> = cameras.iter().chain(joints).collect();
    for s in &all {
        if s.stamps_ns.is_empty() {
            return Err(format!("{} has no messages", s.topic));
        }
    }
    let start = all.iter().map(|s| s.stamps_ns[0]).max().unwrap_or(0);
    let end = all
        .iter()
        .map(|s| s.stamps_ns[s.stamps_ns.len() - 1])
        .min()
        .unwrap_or(0);
    if end <= start {
        return Err("the streams do not overlap in time".into());
    }
    let step_ns = 1e9 / fps;
    let min_camera_period_s = cameras
        .iter()
        .map(|c| c.period_s)
        .fold(f64::INFINITY, f64::min);
    let latest_camera_first = cameras.iter().map(|c| c.stamps_ns[0]).max();
    let start = first_tick(start, latest_camera_first, min_camera_period_s, step_ns);
    if end < start {
        return Err("the streams overlap for less than a tick".into());
    }
    let n = ((end - start) as f64 / step_ns).floor() as usize + 1;
    // Every stream has messages all through [start, end], and a tick is only valid with a recent
    // sample of each, so a grid far denser than the busiest stream cannot be an episode: it is a
    // stamp that jumps (clock reset, corrupt header). Refused before allocating for it.
    let busiest = all.iter().map(|s| s.stamps_ns.len()).max().unwrap_or(0);
    let max_ticks = busiest
        .saturating_mul(MAX_TICKS_PER_MESSAGE)
        .saturating_add(1000);
    if n > max_ticks {
        return Err(format!(
            "the streams span {:.0} s, {n} ticks at {fps} Hz, but the busiest has only {busiest} \
             messages (limit {MAX_TICKS_PER_MESSAGE} ticks per message + 1000): a stamp jumps",
            (end - start) as f64 * 1e-9
        ));
    }
    let mut ticks = Vec::with_capacity(n);
    let mut frames = Vec::with_capacity(n);
    let mut samples = Vec::with_capacity(n);
    // Per tick, the streams (indices into `all`) that made it invalid (none: a valid tick).
    let mut blamed: Vec<Vec<usize>> = Vec::with_capacity(n);
    let (mut max_skew, mut max_age) = (0.0f64, 0.0f64);
    for k in 0..n {
        let t = start + (k as f64 * step_ns).round() as u64;
        let mut blame = Vec::new();
        let mut chosen = Vec::with_capacity(cameras.len());
        let (mut lo, mut hi) = (u64::MAX, 0);
        for (ci, c) in cameras.iter().enumerate() {
            let (i, fresh) = c.frame_at(t, stale_periods);
            let s = c.stamps_ns[i];
            let age = t.saturating_sub(s) as f64 * 1e-9;
            if !fresh {
                blame.push(ci);
            }
            max_age = max_age.max(age);
            lo = lo.min(s);
            hi = hi.max(s);
            chosen.push(i);
        }
        if !cameras.is_empty() {
            max_skew = max_skew.max((hi - lo) as f64 * 1e-9);
        }
        let mut brackets = Vec::with_capacity(joints.len());
        for (ji, j) in joints.iter().enumerate() {
            let (b, sound) = j.sample_at(t, step_ns * 1e-9);
            if !sound {
                blame.push(cameras.len() + ji);
            }
            brackets.push(b);
        }
        ticks.push(t);
        frames.push(chosen);
        samples.push(brackets);
        blamed.push(blame);
    }
    let first = blamed
        .iter()
        .position(|b| b.is_empty())
        .ok_or("no tick has fresh data from every stream")?;
    let last = blamed.iter().rposition(|b| b.is_empty()).unwrap_or(first);
    let kept = last - first + 1;
    let invalid = blamed[first..=last]
        .iter()
        .filter(|b| !b.is_empty())
        .count();
    if kept < 2 {
        return Err("fewer than 2 aligned ticks".into());
    }
    if invalid as f64 > max_invalid_fraction * kept as f64 {
        return Err(format!(
            "{invalid} of {kept} ticks have a stale camera frame or a joint gap (limit {:.0} %): {}",
            max_invalid_fraction * 100.0,
            blame_list(&all, &blamed[first..=last])
        ));
    }
    let streams = all.iter().map(|s| stream_report(s)).collect();
    Ok(Alignment {
        ticks_ns: ticks[first..=last].to_vec(),
        frames: frames[first..=last].to_vec(),
        samples: samples[first..=last].to_vec(),
        report: AlignmentReport {
            ticks: kept,
            trimmed: n - kept,
            invalid,
            max_camera_skew_s: max_skew,
            max_frame_age_s: max_age,
            streams,
            reordered: 0,
        },
    })
}

/// "topic N, topic M" — how many invalid ticks each stream made invalid, most first.
fn blame_list(all: &[&Stream], blamed: &[Vec<usize>]) -> String {
    let mut counts = vec![0usize; all.len()];
    for &i in blamed.iter().flatten() {
        counts[i] += 1;
    }
    let mut order: Vec<usize> = (0..all.len()).filter(|&i| counts[i] > 0).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(counts[i]));
    order
        .iter()
        .map(|&i| format!("{} {}", all[i].topic, counts[i]))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The first tick: a quarter of the fastest camera's frame period after the latest camera's
/// first frame, then on at `step_ns` intervals to the first such instant at or after `start`.
/// Ticks on the frame instants would let capture jitter split synchronised cameras a whole frame
/// apart (one camera's frame stamped a little before the tick, the other's a little after);
/// a quarter period later every camera's capture of that instant is in. Shared with
/// the converter's prefetcher, which must predict the same ticks while the file streams past.
pub fn first_tick(
    start: u64,
    latest_camera_first: Option<u64>,
    min_camera_period_s: f64,
    step_ns: f64,
) -> u64 {
    let Some(anchor) = latest_camera_first else {
        return start;
    };
    if !(min_camera_period_s.is_finite() && min_camera_period_s > 0.0 && step_ns > 0.0) {
        return start;
    }
    let origin = anchor.saturating_add((min_camera_period_s * 1e9 / 4.0).round() as u64);
    if origin >= start {
        return origin;
    }
    let k = ((start - origin) as f64 / step_ns).ceil();
    origin
        .saturating_add((k * step_ns).round() as u64)
        .max(start)
}

fn stream_report(s: &Stream) -> StreamReport {
    let mut r = StreamReport {
        topic: s.topic.clone(),
        messages: s.stamps_ns.len(),
        ..Default::default()
    };
    for w in s.stamps_ns.windows(2) {
        let dt = (w[1] - w[0]) as f64 * 1e-9;
        r.max_interval_s = r.max_interval_s.max(dt);
        if dt > 1.5 * s.period_s {
            r.gaps += 1;
            r.dropped += ((dt / s.period_s).round() as u64).saturating_sub(1);
        }
    }
    r
}

#[cfg(test)]
mod tests;
