//! A recording as the converter sees it: the converter's own `convert` computes the episode's
//! state and action (no image is decoded: the viewer's frame store hands back empty frames),
//! and the converter's `align` on the same stamps gives the absolute tick times, the frame each
//! camera contributes per tick (camera skew) and which ticks are invalid, even for an episode
//! the converter would reject.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use rerun::{RecordingStream, TextLog};
use scaledp_converter::images::{ChannelHistogram, EncodeSpec, EncodedFrame};
use scaledp_converter::{
    align, convert, ConvertOptions, Episode, FrameKey, FrameStore, Recording, Stream,
};
use scaledp_schema::rig::Rig;
use scaledp_schema::EpisodeMetadata;

use crate::episode::{log_quality, log_rows, Quality, Rows};
use crate::error::{Error, Result};
use crate::layout;
use crate::recording::Collected;

/// Frame stamps without pixels: `encode` returns empty frames.
pub(crate) struct NoPixels(BTreeMap<String, Vec<(u64, u64)>>);

impl NoPixels {
    /// The stamps of the image messages of an in-memory recording.
    pub fn from_recording(rec: &Recording) -> Self {
        let mut stamps: BTreeMap<String, Vec<(u64, u64)>> = BTreeMap::new();
        for m in &rec.messages {
            if m.message_type.ends_with("/Image") || m.message_type.ends_with("/CompressedImage") {
                let header = match m.serialization {
                    scaledp_converter::Serialization::Cdr => {
                        scaledp_schema::msg::header_stamp(&m.data).map_or(0, |t| t.as_ns())
                    }
                    scaledp_converter::Serialization::Ros1 => {
                        let w = |r: Option<&[u8]>| {
                            r.map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64)
                        };
                        w(m.data.get(4..8)) * 1_000_000_000 + w(m.data.get(8..12))
                    }
                };
                stamps
                    .entry(m.topic.clone())
                    .or_default()
                    .push((header, m.log_time_ns));
            }
        }
        Self(stamps)
    }
}

impl FrameStore for NoPixels {
    fn stamps(&self, topic: &str) -> Vec<(u64, u64)> {
        self.0.get(topic).cloned().unwrap_or_default()
    }
    fn encode(
        &self,
        _path: &Path,
        wanted: &BTreeMap<String, BTreeSet<usize>>,
        _spec: &EncodeSpec,
    ) -> scaledp_converter::Result<HashMap<FrameKey, EncodedFrame>> {
        Ok(wanted
            .iter()
            .flat_map(|(t, set)| set.iter().map(move |&o| (t.clone(), o)))
            .map(|k| {
                (
                    k,
                    EncodedFrame {
                        bytes: Vec::new(),
                        histogram: ChannelHistogram::default(),
                        source: Default::default(),
                        depth: None,
                    },
                )
            })
            .collect())
    }
}

/// What the episode view of a recording showed.
pub(crate) struct EpisodeShown {
    /// Frames shown as state and action.
    pub frames: usize,
    /// Why the converter would reject the episode, or could not align it.
    pub warnings: Vec<String>,
}

/// Capture stamp of each frame / message: the header stamp, else (0) the log time.
fn capture(stamps: &[(u64, u64)]) -> Vec<u64> {
    stamps
        .iter()
        .map(|&(h, l)| if h == 0 { l } else { h })
        .collect()
}

/// Alignment ticks (ns) and per-tick quality, with the converter's rules.
fn quality(
    rig: &Rig,
    c: &Collected,
    opts: &ConvertOptions,
) -> std::result::Result<(Vec<u64>, Quality), String> {
    let fps = opts.fps.unwrap_or(rig.control_rate_hz);
    let cams: Vec<Stream> = rig
        .cameras
        .iter()
        .map(|cam| {
            let s = c
                .frame_stamps
                .get(&cam.topic)
                .map(|s| capture(s))
                .unwrap_or_default();
            Stream::new(&cam.topic, s, Some(cam.fps))
        })
        .collect();
    let mut joints = Vec::new();
    for arm in &rig.arms {
        let mut add = |topic: &str, rate: f64| {
            let s = c.joint_stamps.get(topic).cloned().unwrap_or_default();
            joints.push(Stream::new(topic, s, Some(rate)));
        };
        add(&arm.joint_state_topic, arm.rate_hz);
        if let Some(g) = &arm.gripper {
            add(&g.topic, g.rate_hz);
        }
    }
    let a = align(&cams, &joints, fps, opts.stale_periods, 1.0)?;
    let mut q = Quality::default();
    for &t in &a.ticks_ns {
        let (mut lo, mut hi, mut ok) = (u64::MAX, 0u64, true);
        for cam in &cams {
            // The converter's own rules: each camera's frame and whether it is fresh, each
            // joint stream's samples around the tick and whether the hole is small enough.
            let (i, fresh) = cam.frame_at(t, opts.stale_periods);
            let s = cam.stamps_ns[i];
            lo = lo.min(s);
            hi = hi.max(s);
            ok &= fresh;
        }
        for j in &joints {
            ok &= j.sample_at(t, 1.0 / fps).1;
        }
        q.skew_s.push(if cams.is_empty() {
            0.0
        } else {
            hi.saturating_sub(lo) as f64 * 1e-9
        });
        q.invalid.push(!ok);
    }
    for s in cams.iter().chain(&joints) {
        for w in s.stamps_ns.windows(2) {
            let dt = w[1].saturating_sub(w[0]) as f64 * 1e-9;
            if dt > 1.5 * s.period_s {
                let missing = ((dt / s.period_s).round() as u64).saturating_sub(1);
                q.gaps.push((w[0], dt, s.topic.clone(), missing));
            }
        }
    }
    q.gaps.sort_by_key(|g| g.0);
    Ok((a.ticks_ns, q))
}

/// Rows of a converted episode.
fn rows(ep: &Episode) -> Rows {
    let split = |v: &[f32], dim: usize| -> Vec<Vec<f32>> {
        if dim == 0 {
            return Vec::new();
        }
        v.chunks(dim).map(<[f32]>::to_vec).collect()
    };
    Rows {
        state: split(&ep.state, ep.state_names.len()),
        action: split(&ep.action, ep.state_names.len()),
        joints: split(&ep.joints, ep.joint_names.len()),
        state_names: ep.state_names.clone(),
        action_names: ep.state_names.clone(),
        joint_names: ep.joint_names.clone(),
        plot_joints: false,
        predicted: Vec::new(),
        space: ep.action_space,
    }
}

/// Logs the metadata records as text at the episode's start.
fn log_metadata(
    rec: &RecordingStream,
    meta: Option<&EpisodeMetadata>,
    start_ns: u64,
) -> Result<()> {
    let Some(m) = meta else { return Ok(()) };
    rec.set_timestamp_nanos_since_epoch(
        layout::CAPTURE_TIME,
        m.start_time_ns.unwrap_or(start_ns) as i64,
    );
    let total = |x: &BTreeMap<String, u64>| x.values().sum::<u64>();
    let mut lines = vec![
        format!("task: {}", m.task),
        format!("operator: {}", m.operator),
        format!("rig: {}", m.rig_name),
        format!(
            "outcome: {}",
            m.label.map_or("(none recorded)", |l| l.as_str())
        ),
    ];
    if let Some(d) = m.duration_s {
        lines.push(format!("duration: {d:.1} s"));
    }
    lines.push(format!(
        "messages: {} written, {} dropped by the recorder's queue, {} lost upstream",
        total(&m.message_counts),
        total(&m.dropped),
        total(&m.upstream_gaps)
    ));
    for (topic, n) in m
        .dropped
        .iter()
        .chain(&m.upstream_gaps)
        .filter(|(_, &n)| n > 0)
    {
        lines.push(format!("{topic}: {n} lost"));
    }
    if let Some(s) = &m.synthetic {
        lines.push(format!("synthetic episode ({s})"));
    }
    for l in lines {
        rec.log(layout::LOG, &TextLog::new(l))
            .map_err(Error::rerun)?;
    }
    Ok(())
}

/// The converter's view of a collected recording: state, action and 3-D per tick, quality
/// signals, metadata. Problems that stop part of it are returned as warnings.
pub(crate) fn show_episode(
    rec: &RecordingStream,
    path: &Path,
    c: &Collected,
    opts: &ConvertOptions,
    chunk: usize,
) -> Result<EpisodeShown> {
    let mut warnings = Vec::new();
    rec.reset_time();
    let meta =
        EpisodeMetadata::from_records(&c.recording.metadata).and_then(std::result::Result::ok);
    log_metadata(rec, meta.as_ref(), c.first_ns())?;
    let stamps = NoPixels(c.frame_stamps.clone());
    let episode = convert(path, &c.recording, &stamps, opts);
    let rig = match (&episode, &opts.rig) {
        (Ok(ep), _) => Some(ep.rig.clone()),
        (Err(_), Some(r)) => Some(r.clone()),
        (Err(_), None) => None,
    };
    let Some(rig) = rig else {
        if let Err(e) = &episode {
            warnings.push(format!("not shown as an episode: {e}"));
        }
        return Ok(EpisodeShown {
            frames: 0,
            warnings,
        });
    };
    let shape = layout::Shape {
        cameras: c.frames_logged.keys().cloned().collect(),
        arms: rig.arms.iter().map(|a| a.name.clone()).collect(),
        dims: rig
            .arms
            .iter()
            .map(|a| crate::space::labels(a, opts.action_space))
            .collect(),
        space: opts.action_space,
        topics: Vec::new(),
        quality: true,
        timeline: layout::CAPTURE_TIME,
    };
    layout::blueprint(&shape)
        .send(
            rec,
            rerun::blueprint::BlueprintActivation {
                make_active: true,
                make_default: true,
            },
        )
        .map_err(Error::rerun)?;
    let (ticks, q) = match quality(&rig, c, opts) {
        Ok(x) => x,
        Err(e) => {
            warnings.push(format!("cannot be aligned: {e}"));
            return Ok(EpisodeShown {
                frames: 0,
                warnings,
            });
        }
    };
    let at = |t: usize| {
        rec.set_time_sequence(layout::TICK, t as i64);
        if let Some(&ns) = ticks.get(t) {
            rec.set_timestamp_nanos_since_epoch(layout::CAPTURE_TIME, ns as i64);
        }
    };
    let invalid = q.invalid.iter().filter(|&&v| v).count();
    let limit = ConvertOptions::default().max_invalid_fraction;
    if invalid as f64 > limit * ticks.len() as f64 {
        warnings.push(format!(
            "{invalid} of {} ticks have a stale camera frame or a joint gap: `scaledp convert` would reject it (limit {:.0} %)",
            ticks.len(),
            limit * 100.0
        ));
    }
    let frames = match &episode {
        Ok(ep) => {
            if ep.len() + 1 != ticks.len() {
                warnings.push(format!(
                    "{} frames but {} ticks: the plots may be shifted",
                    ep.len(),
                    ticks.len()
                ));
            }
            log_rows(rec, &rows(ep), Some(&rig), chunk, &at)?;
            ep.len()
        }
        Err(e) => {
            warnings.push(format!("no state or action: {e}"));
            0
        }
    };
    log_quality(rec, &q, &at)?;
    Ok(EpisodeShown { frames, warnings })
}
