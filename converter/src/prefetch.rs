//! Which camera frames the conversion of an MCAP recording will pick, worked out while the file
//! streams past, so that they are decoded, resized and encoded during the one read instead of on
//! a second read (decompressing every camera byte again).
//!
//! Alignment (see [`scaledp_align`]) puts ticks at `first + round(k × period)`, `first` following
//! from the first stamps of the rig's cameras, arms and grippers ([`first_tick`]), and gives each
//! tick each camera's latest frame at or before it. So once every stream has started, frame `i`
//! of a camera is picked only if a tick falls in `[stamp i, stamp i+1)`, which is known when frame
//! `i + 1` arrives; the last frame is kept too. That is a superset of the frames alignment picks (it does not know where the
//! episode ends or which ticks are trimmed). It is a guess all the same (the rig may come from
//! the end-of-file metadata, stamps may run backwards): the conversion takes what it needs from
//! here and reads the file again only for frames this missed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crate::encode_pool::FrameJob;
use crate::mcap_stream::{FrameBytes, Metadata, Payload};
use crate::options::ConvertOptions;
use crate::source::{Recording, TopicInfo};
use scaledp_align::first_tick;

/// Frames held per camera while `start` is unknown (a stream that never starts).
const MAX_HELD: usize = 16;

/// A camera frame not decided on yet.
#[derive(Debug)]
struct Candidate {
    ordinal: usize,
    stamp_ns: u64,
    log_time_ns: u64,
    message_type: String,
    bytes: FrameBytes,
}

#[derive(Debug, Default)]
struct Camera {
    /// The latest frame (its successor is not known yet).
    latest: Option<Candidate>,
    /// Frames with their successor's stamp, waiting for the first tick.
    held: Vec<(Candidate, u64)>,
}

#[derive(Debug)]
struct Plan {
    use_log_time: bool,
    period_ns: f64,
    min_camera_period_s: f64,
    cameras: BTreeMap<String, Camera>,
    /// Topics whose first stamps make `start`: cameras, arms, grippers.
    streams: BTreeSet<String>,
    first: BTreeMap<String, u64>,
    /// The latest first stamp seen: the first tick is at least this.
    lower_ns: u64,
    /// The first tick, once every stream has started.
    start_ns: Option<u64>,
}

#[derive(Debug)]
enum State {
    /// The rig is looked up at the first message.
    Unresolved(Box<ConvertOptions>),
    /// No rig known up front: every frame is left to the second read.
    Off,
    On(Box<Plan>),
}

/// Picks frames to encode during the read; see the module docs.
#[derive(Debug)]
pub struct Selector(State);

impl Selector {
    /// A selector for converting with `opts` (its rig, else the rig stored at the start of the
    /// recording); none for a split into windows, whose ticks start elsewhere.
    pub fn new(opts: &ConvertOptions) -> Self {
        Self(State::Unresolved(Box::new(opts.clone())))
    }

    fn resolve(path: &Path, opts: &ConvertOptions, metadata: &Metadata) -> State {
        if opts.window_ns.is_some() {
            return State::Off;
        }
        let rec = Recording {
            metadata: metadata.clone(),
            ..Recording::default()
        };
        let rig = match (&opts.rig, crate::detect::from_metadata(path, &rec)) {
            (Some(r), _) => r.clone(),
            (None, Ok(Some(r))) => r,
            _ => return State::Off,
        };
        let mut rig = rig;
        if crate::detect::override_topics(path, &mut rig, &opts.topic_overrides).is_err() {
            return State::Off;
        }
        let fps = opts.fps.unwrap_or(rig.control_rate_hz);
        if !(fps.is_finite() && fps > 0.0) {
            return State::Off;
        }
        let mut streams = BTreeSet::new();
        let mut cameras = BTreeMap::new();
        // As `Stream::new` makes a camera's period from the rig's rate, so ticks match exactly.
        let mut min_camera_period_s = f64::INFINITY;
        for c in &rig.cameras {
            if c.fps.is_nan() || c.fps <= 0.0 {
                return State::Off;
            }
            min_camera_period_s = min_camera_period_s.min(1.0 / c.fps);
            // Kept depth is aligned as one more camera, so it moves the first tick too.
            let depth = c.depth.as_ref().filter(|_| opts.depth).map(|d| &d.topic);
            for topic in std::iter::once(&c.topic).chain(depth) {
                streams.insert(topic.clone());
                cameras.insert(topic.clone(), Camera::default());
            }
        }
        for a in &rig.arms {
            streams.insert(a.joint_state_topic.clone());
            if let Some(g) = &a.gripper {
                streams.insert(g.topic.clone());
            }
        }
        State::On(Box::new(Plan {
            use_log_time: opts.use_log_time,
            period_ns: 1e9 / fps,
            min_camera_period_s,
            cameras,
            streams,
            first: BTreeMap::new(),
            lower_ns: 0,
            start_ns: None,
        }))
    }

    /// A message of `topic` (`ordinal` among that topic's image messages, None for others) with
    /// its header stamp (0 when unreadable); frames to encode now go to `out`.
    #[allow(clippy::too_many_arguments)]
    pub fn message(
        &mut self,
        path: &Path,
        topic: &TopicInfo,
        ordinal: Option<usize>,
        header_ns: u64,
        log_time_ns: u64,
        payload: &Payload<'_>,
        metadata: &Metadata,
        out: &mut dyn FnMut(FrameJob),
    ) {
        if let State::Unresolved(opts) = &self.0 {
            self.0 = Self::resolve(path, opts, metadata);
        }
        let State::On(plan) = &mut self.0 else {
            return;
        };
        let stamp_ns = if plan.use_log_time || header_ns == 0 {
            log_time_ns
        } else {
            header_ns
        };
        if plan.start_ns.is_none()
            && plan.streams.contains(&topic.topic)
            && !plan.first.contains_key(&topic.topic)
        {
            plan.first.insert(topic.topic.clone(), stamp_ns);
            plan.lower_ns = plan.lower_ns.max(stamp_ns);
            if plan.first.len() == plan.streams.len() {
                let latest_camera_first = plan
                    .cameras
                    .keys()
                    .filter_map(|c| plan.first.get(c).copied())
                    .max();
                plan.start_ns = Some(first_tick(
                    plan.lower_ns,
                    latest_camera_first,
                    plan.min_camera_period_s,
                    plan.period_ns,
                ));
                plan.release_held(out);
            }
        }
        let Some(ordinal) = ordinal else {
            return;
        };
        if !plan.cameras.contains_key(&topic.topic) {
            return;
        }
        let frame = Candidate {
            ordinal,
            stamp_ns,
            log_time_ns,
            message_type: topic.message_type.clone(),
            bytes: payload.share(),
        };
        let (start, lower, period) = (plan.start_ns, plan.lower_ns, plan.period_ns);
        let Some(cam) = plan.cameras.get_mut(&topic.topic) else {
            return;
        };
        if let Some(prev) = cam.latest.replace(frame) {
            match start {
                Some(_) if plan_picks(period, start, prev.stamp_ns, stamp_ns) => {
                    out(job(&topic.topic, prev));
                }
                Some(_) => {}
                // No tick comes before `start`, which is at least `lower`.
                None if stamp_ns > lower => {
                    cam.held.push((prev, stamp_ns));
                    cam.held.retain(|(_, next)| *next > lower);
                    if cam.held.len() > MAX_HELD {
                        cam.held.remove(0);
                    }
                }
                None => {}
            }
        }
    }

    /// The end of the file: each camera's last frame goes to `out` (once `start` is known).
    pub fn finish(&mut self, out: &mut dyn FnMut(FrameJob)) {
        let State::On(plan) = &mut self.0 else {
            return;
        };
        if plan.start_ns.is_none() {
            return;
        }
        for (topic, cam) in &mut plan.cameras {
            if let Some(last) = cam.latest.take() {
                out(job(topic, last));
            }
        }
    }
}

impl Plan {
    /// `start` just became known: decide on the frames held.
    fn release_held(&mut self, out: &mut dyn FnMut(FrameJob)) {
        let (period, start) = (self.period_ns, self.start_ns);
        for (topic, cam) in &mut self.cameras {
            for (frame, next) in std::mem::take(&mut cam.held) {
                if plan_picks(period, start, frame.stamp_ns, next) {
                    out(job(topic, frame));
                }
            }
        }
    }
}

fn job(topic: &str, c: Candidate) -> FrameJob {
    FrameJob {
        key: (topic.to_string(), c.ordinal),
        message_type: c.message_type,
        log_time_ns: c.log_time_ns,
        bytes: c.bytes,
    }
}

/// Whether a tick `start + round(k × period)`, k ≥ 0, falls in `[stamp, next)` (as
/// [`scaledp_align::align`] computes ticks).
fn plan_picks(period_ns: f64, start: Option<u64>, stamp: u64, next: u64) -> bool {
    let Some(start) = start else {
        return true;
    };
    if next <= stamp {
        return false;
    }
    // Saturating: near u64::MAX a tick stays at the end of time instead of wrapping to 0.
    let tick = |k: u64| start.saturating_add((k as f64 * period_ns).round() as u64);
    let mut k = if stamp <= start {
        0
    } else {
        ((stamp - start) as f64 / period_ns).ceil() as u64
    };
    // The estimate is off by float rounding only, a step or two. Should it not settle within
    // `MAX_STEPS` (a period below the float resolution of the stamps), the frame is picked: the
    // plan only has to be a superset.
    const MAX_STEPS: usize = 64;
    let mut steps = 0;
    while k > 0 && tick(k - 1) >= stamp {
        k -= 1;
        steps += 1;
        if steps > MAX_STEPS {
            return true;
        }
    }
    while tick(k) < stamp {
        k = k.saturating_add(1);
        steps += 1;
        if steps > MAX_STEPS {
            return true;
        }
    }
    tick(k) < next
}

#[cfg(test)]
mod tests {
    use super::plan_picks;

    #[test]
    fn frames_covering_a_tick_are_picked() {
        let p = 100.0; // ticks at 1000, 1100, 1200…
        let s = Some(1000);
        assert!(plan_picks(p, s, 990, 1010)); // covers tick 0
        assert!(!plan_picks(p, s, 900, 1000)); // ends right at tick 0
        assert!(plan_picks(p, s, 1000, 1001));
        assert!(!plan_picks(p, s, 1001, 1100));
        assert!(plan_picks(p, s, 1001, 1101));
        assert!(plan_picks(p, s, 1150, 1450)); // covers several
        assert!(!plan_picks(p, s, 1150, 1150));
        // Rounding as alignment does: 1/3 period → ticks at 0, 33, 67, 100.
        let third = 100.0 / 3.0;
        assert!(plan_picks(third, Some(0), 34, 68));
        assert!(!plan_picks(third, Some(0), 34, 67));
    }

    /// Calls `plan_picks` on another thread; None if it has not returned within 10 s.
    fn picks_in_time(period: f64, start: u64, stamp: u64, next: u64) -> Option<bool> {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(plan_picks(period, Some(start), stamp, next));
        });
        rx.recv_timeout(std::time::Duration::from_secs(10)).ok()
    }

    #[test]
    fn stamps_near_the_end_of_time_neither_wrap_nor_hang() {
        let period = 1e9 / 30.0;
        let start = u64::MAX - 100;
        // The next tick lies past u64::MAX: none in [stamp, next).
        let r = picks_in_time(period, start, u64::MAX - 50, u64::MAX);
        assert_eq!(r, Some(false));
        // A tick well inside the range still counts.
        let start = u64::MAX - 1_000_000_000;
        let r = picks_in_time(period, start, start + 50_000_000, start + 90_000_000);
        assert_eq!(r, Some(true));
        // A period below the stamps' float resolution: settles (picking the frame) or answers.
        let r = picks_in_time(1e-6, 1 << 62, (1 << 62) + 7, (1 << 62) + 9);
        assert!(r.is_some());
    }
}
