//! The converter's rules applied to an episode while it is written, so the recorder's verdict
//! and `scaledp convert` (default settings) cannot disagree: the capture stamp of every message
//! (its header's, read from the CDR prefix only; the receive time when the header holds none),
//! the topics the converter requires in the order it checks them, stamps put in order within
//! its 0.1 s reorder window, then [`scaledp_align::align`] on the rig's cameras (colour, then
//! depth) and joint streams at the rig's control rate with the converter's defaults
//! ([`DEFAULT_STALE_PERIODS`], [`DEFAULT_MAX_INVALID_FRACTION`]). Left to the converter: image
//! decoding and kinematics (a pose the arm's model cannot reach).

use scaledp_align::{
    align, StampOrder, Stream, DEFAULT_MAX_INVALID_FRACTION, DEFAULT_REORDER_WINDOW_S,
    DEFAULT_STALE_PERIODS,
};
use scaledp_schema::msg::JointState;
use scaledp_schema::rig::{Rig, TopicKind, TopicSpec};
use scaledp_schema::RosMessage;

use crate::verdict::{TopicVerdict, Verdict};

/// `scaledp convert`'s default reorder window, in ns.
const REORDER_WINDOW_NS: u64 = (DEFAULT_REORDER_WINDOW_S * 1e9) as u64;
/// A topic that ends (or begins) more than this many of its periods, and half a second, before
/// the episode's last stamp (after its first) is named.
const EDGE_PERIODS: f64 = 3.0;
const MIN_EDGE_S: f64 = 0.5;

/// The joint names the converter maps on a JointState topic, and the first problem it would
/// reject the episode for.
#[derive(Debug, Clone)]
struct JointCheck {
    names: Vec<String>,
    seen: Vec<String>,
    index: Vec<Option<usize>>,
    problem: Option<String>,
}

impl JointCheck {
    fn new(names: &[String]) -> Self {
        Self {
            names: names.to_vec(),
            seen: Vec::new(),
            index: Vec::new(),
            problem: None,
        }
    }

    /// `JointSeries::read`'s checks on one message.
    fn message(&mut self, topic: &str, js: &JointState, log_ns: u64) {
        if self.problem.is_some() {
            return;
        }
        if js.name.len() != js.position.len() {
            self.problem = Some(format!(
                "{topic} at {log_ns} ns: {} names but {} positions",
                js.name.len(),
                js.position.len()
            ));
            return;
        }
        if js.name != self.seen {
            self.index = self
                .names
                .iter()
                .map(|n| js.name.iter().position(|x| x == n))
                .collect();
            self.seen = js.name.clone();
        }
        for (n, i) in self.names.iter().zip(&self.index) {
            let Some(i) = *i else {
                self.problem = Some(format!(
                    "joint '{n}' is missing from {topic} (it has {:?})",
                    js.name
                ));
                return;
            };
            let v = js.position[i];
            if !v.is_finite() {
                self.problem = Some(format!("joint '{n}' on {topic} is {v} at {log_ns} ns"));
                return;
            }
        }
    }
}

/// One topic's capture stamps, in the order they were written.
#[derive(Debug, Clone)]
struct Series {
    topic: String,
    expected_hz: Option<f64>,
    aligned: bool,
    stamps: Vec<u64>,
    joints: Vec<JointCheck>,
}

/// What an open episode has shown so far of the topics the verdict looks at.
#[derive(Debug, Clone)]
pub(crate) struct Evidence {
    /// Per topic number of the session: its series.
    slot: Vec<Option<usize>>,
    series: Vec<Series>,
}

impl Evidence {
    /// For `rig`, whose topics are `specs` (the session's list, the rig's first): every topic
    /// with a rate, and the joint names mapped on each joint state topic.
    pub fn new(rig: &Rig, specs: &[TopicSpec]) -> Self {
        let mut series: Vec<Series> = Vec::new();
        let mut slot = Vec::with_capacity(specs.len());
        let aligned: Vec<&str> = rig
            .cameras
            .iter()
            .flat_map(|c| {
                std::iter::once(c.topic.as_str()).chain(c.depth.as_ref().map(|d| d.topic.as_str()))
            })
            .chain(rig.arms.iter().flat_map(|a| {
                std::iter::once(a.joint_state_topic.as_str())
                    .chain(a.gripper.as_ref().map(|g| g.topic.as_str()))
            }))
            .collect();
        for s in specs {
            let wanted = s.rate_hz > 0.0 || aligned.contains(&s.topic.as_str());
            if !wanted || s.kind == TopicKind::Extra && s.rate_hz <= 0.0 {
                slot.push(series.iter().position(|x| x.topic == s.topic));
                continue;
            }
            if let Some(i) = series.iter().position(|x| x.topic == s.topic) {
                slot.push(Some(i));
                continue;
            }
            slot.push(Some(series.len()));
            series.push(Series {
                topic: s.topic.clone(),
                expected_hz: (s.rate_hz > 0.0).then_some(s.rate_hz),
                aligned: aligned.contains(&s.topic.as_str()),
                stamps: Vec::new(),
                joints: Vec::new(),
            });
        }
        let mut ev = Self { slot, series };
        for a in &rig.arms {
            ev.check_joints(&a.joint_state_topic, &a.joint_names);
            if let Some(g) = &a.gripper {
                ev.check_joints(&g.topic, &g.joint_names);
                if let Some(c) = &g.command_topic {
                    ev.check_joints(c, &g.joint_names);
                }
            }
        }
        ev
    }

    fn check_joints(&mut self, topic: &str, names: &[String]) {
        if let Some(s) = self.series.iter_mut().find(|s| s.topic == topic) {
            if !s.joints.iter().any(|j| j.names == names) {
                s.joints.push(JointCheck::new(names));
            }
        }
    }

    fn series_of(&self, topic: &str) -> Option<&Series> {
        self.series.iter().find(|s| s.topic == topic)
    }

    /// A topic added to the session mid-way (not looked at).
    pub fn push_topic(&mut self) {
        self.slot.push(None);
    }

    /// A message of topic number `topic` was written: its header stamp (None or 0 when it has
    /// none: the receive time stands in, as in the converter), receive time and payload.
    pub fn message(&mut self, topic: usize, header_ns: Option<u64>, log_ns: u64, data: &[u8]) {
        let Some(Some(i)) = self.slot.get(topic) else {
            return;
        };
        let s = &mut self.series[*i];
        s.stamps
            .push(header_ns.filter(|&h| h != 0).unwrap_or(log_ns));
        if s.joints.is_empty() {
            return;
        }
        match JointState::from_cdr(data) {
            Ok(js) => {
                for j in &mut s.joints {
                    j.message(&s.topic, &js, log_ns);
                }
            }
            Err(e) => {
                for j in s.joints.iter_mut().filter(|j| j.problem.is_none()) {
                    j.problem = Some(format!(
                        "{} at {log_ns} ns: not a sensor_msgs/JointState: {e}",
                        s.topic
                    ));
                }
            }
        }
    }
}

/// Stamps in stamp order as the converter takes them, or the clock jump it refuses them for.
fn ordered(topic: &str, stamps: &[u64]) -> Result<Vec<u64>, String> {
    StampOrder::new(topic, stamps, REORDER_WINDOW_NS)
        .map(|o| o.sorted(stamps))
        .map_err(|e| e.to_string())
}

/// The joint check of `names` on `topic`'s series.
fn joint_problem(ev: &Evidence, topic: &str, names: &[String]) -> Option<String> {
    ev.series_of(topic)?
        .joints
        .iter()
        .find(|j| j.names == names)?
        .problem
        .clone()
}

/// The stream of `topic`, or the reason the converter refuses it.
fn stream(
    ev: &Evidence,
    topic: &str,
    rate: f64,
    silent: impl FnOnce() -> String,
    names: Option<&[String]>,
) -> Result<Stream, String> {
    let stamps = ev.series_of(topic).map_or(&[][..], |s| &s.stamps[..]);
    if stamps.is_empty() {
        return Err(silent());
    }
    if let Some(p) = names.and_then(|n| joint_problem(ev, topic, n)) {
        return Err(p);
    }
    Ok(Stream::new(topic, ordered(topic, stamps)?, Some(rate)))
}

/// The converter's checks in its order, up to alignment and the command topics.
fn convert_rules(rig: &Rig, task: &str, ev: &Evidence) -> Result<scaledp_align::Alignment, String> {
    if rig.arms.is_empty() {
        return Err(format!(
            "no arm: rig '{}' has cameras but no arm joint states, and an episode needs a \
             state and an action (pass --rig to map an arm's topic)",
            rig.name
        ));
    }
    if task.is_empty() {
        return Err("no task instruction: the recording stores none; pass --task".into());
    }
    let mut cams = Vec::new();
    for c in &rig.cameras {
        let silent = || match c.video_codec() {
            Some(codec) => format!(
                "camera '{}' ({}) has no {codec} frame that decodes",
                c.name, c.topic
            ),
            None => format!("camera '{}' ({}) has no messages", c.name, c.topic),
        };
        cams.push(stream(ev, &c.topic, c.fps, silent, None)?);
    }
    for c in &rig.cameras {
        let Some(d) = &c.depth else { continue };
        let silent = || {
            format!(
                "depth of camera '{}' ({}) has no messages (convert with --no-depth to leave \
                 depth out)",
                c.name, d.topic
            )
        };
        cams.push(stream(ev, &d.topic, c.fps, silent, None)?);
    }
    let mut joints = Vec::new();
    for a in &rig.arms {
        let t = &a.joint_state_topic;
        let silent = || format!("arm '{}' ({t}) has no messages", a.name);
        joints.push(stream(ev, t, a.rate_hz, silent, Some(&a.joint_names))?);
        if let Some(g) = &a.gripper {
            let silent = || format!("gripper of '{}' ({}) has no messages", a.name, g.topic);
            joints.push(stream(
                ev,
                &g.topic,
                g.rate_hz,
                silent,
                Some(&g.joint_names),
            )?);
        }
    }
    let aligned = align(
        &cams,
        &joints,
        rig.control_rate_hz,
        DEFAULT_STALE_PERIODS,
        DEFAULT_MAX_INVALID_FRACTION,
    )?;
    for a in &rig.arms {
        let count = |t: &str| ev.series_of(t).map_or(0, |s| s.stamps.len());
        if let Some((g, t)) = a
            .gripper
            .as_ref()
            .and_then(|g| Some((g, g.command_topic.as_ref()?)))
        {
            if let Some(p) = joint_problem(ev, t, &g.joint_names) {
                return Err(p);
            }
            if count(t) == 0 {
                return Err(format!(
                    "gripper command topic {t} of arm '{}' has no messages",
                    a.name
                ));
            }
        }
        if let Some(t) = &a.command_topic {
            if count(t) == 0 {
                return Err(format!(
                    "command topic {t} of arm '{}' has no messages",
                    a.name
                ));
            }
        }
    }
    Ok(aligned)
}

/// The figures of one series (stamps in stamp order).
fn figures(s: &Series, sorted: &[u64], first: u64, last: u64) -> TopicVerdict {
    let n = sorted.len();
    let span = match (sorted.first(), sorted.last()) {
        (Some(a), Some(b)) if b > a => (b - a) as f64 * 1e-9,
        _ => 0.0,
    };
    TopicVerdict {
        topic: s.topic.clone(),
        messages: n,
        expected_hz: s.expected_hz,
        rate_hz: if span > 0.0 {
            (n - 1) as f64 / span
        } else {
            0.0
        },
        max_gap_s: sorted
            .windows(2)
            .map(|w| (w[1] - w[0]) as f64 * 1e-9)
            .fold(0.0, f64::max),
        stopped_early_s: sorted
            .last()
            .map_or(0.0, |&l| last.saturating_sub(l) as f64 * 1e-9),
        started_late_s: sorted
            .first()
            .map_or(0.0, |&f| f.saturating_sub(first) as f64 * 1e-9),
        aligned: s.aligned,
    }
}

/// The verdict on an episode of `rig` with task `task`, from what it showed.
pub(crate) fn judge(rig: &Rig, task: &str, ev: &Evidence) -> Verdict {
    let sorted: Vec<Vec<u64>> = ev
        .series
        .iter()
        .map(|s| {
            let mut v = s.stamps.clone();
            v.sort_unstable();
            v
        })
        .collect();
    // The episode's extent: the aligned streams' (every series' when none is aligned).
    let any_aligned = ev
        .series
        .iter()
        .zip(&sorted)
        .any(|(s, v)| s.aligned && !v.is_empty());
    let (first, last) = ev
        .series
        .iter()
        .zip(&sorted)
        .filter(|(s, v)| !v.is_empty() && (s.aligned || !any_aligned))
        .fold((u64::MAX, 0), |(a, b), (_, v)| {
            (a.min(v[0]), b.max(v[v.len() - 1]))
        });
    let recorded_s = if last > first {
        (last - first) as f64 * 1e-9
    } else {
        0.0
    };
    let topics: Vec<TopicVerdict> = ev
        .series
        .iter()
        .zip(&sorted)
        .map(|(s, v)| figures(s, v, first, last))
        .collect();
    let mut v = Verdict {
        fps: rig.control_rate_hz,
        stale_periods: DEFAULT_STALE_PERIODS,
        max_invalid_fraction: DEFAULT_MAX_INVALID_FRACTION,
        recorded_s,
        ..Verdict::default()
    };
    match convert_rules(rig, task, ev) {
        Ok(a) => {
            v.accepted = true;
            v.ticks = a.report.ticks;
            v.trimmed = a.report.trimmed;
            v.invalid = a.report.invalid;
            v.kept_s = a.report.ticks.saturating_sub(1) as f64 / rig.control_rate_hz;
            v.max_camera_skew_s = a.report.max_camera_skew_s;
            v.max_frame_age_s = a.report.max_frame_age_s;
        }
        Err(reason) => v.reason = Some(reason),
    }
    for t in &topics {
        let period = t.expected_hz.map_or(0.0, |r| 1.0 / r);
        let edge = (EDGE_PERIODS * period).max(MIN_EDGE_S);
        if t.messages == 0 {
            if !v.reason.as_deref().is_some_and(|r| r.contains(&t.topic)) {
                v.warnings.push(format!("{}: no messages", t.topic));
            }
        } else if t.stopped_early_s > edge {
            v.warnings.push(format!(
                "{} stopped {:.1} s before the end",
                t.topic, t.stopped_early_s
            ));
        }
        if t.messages > 0 && t.started_late_s > edge {
            v.warnings.push(format!(
                "{} started {:.1} s after the others",
                t.topic, t.started_late_s
            ));
        }
    }
    v.topics = topics;
    v
}

#[cfg(test)]
mod tests;
