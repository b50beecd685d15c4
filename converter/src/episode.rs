//! One input → one training episode: aligned ticks, end-effector state and action per arm,
//! joint positions, and resized JPEG frames per camera.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use scaledp_schema::rig::Rig;

use crate::align::{align, Alignment, AlignmentReport, Stream};
use crate::error::{Error, Result};
use crate::frames::FrameStore;
use crate::images::{ChannelHistogram, EncodeSpec};
use crate::kinematics::ArmKinematics;
use crate::series::{stamp_of, unwrap_pose_angles, CommandPoses, JointSeries, Ordered};
use crate::source::{RawMessage, Recording};

/// How to convert one input, set with chained setters. Defaults: the rig given, else the one
/// stored in the recording, else one detected; the rig's control rate; 320×240 JPEG at quality
/// 90; a frame staler than 1.5 of its periods invalidates a tick; at most 5 % invalid ticks;
/// header stamps as time; messages up to 0.1 s out of stamp order put back in order.
///
/// ```
/// use scaledp_converter::ConvertOptions;
/// let opts = ConvertOptions::default()
///     .size(320, 240)
///     .jpeg_quality(90)
///     .task("put the cup on the plate")
///     .topic_override("wrist", "/camera/wrist/image_raw");
/// # let _ = opts;
/// ```
///
/// The fields are public for the callers that still build the struct literally
/// (`sim/tests/record_convert.rs`); they become private once none does: use the setters.
#[derive(Debug, Clone)]
pub struct ConvertOptions {
    /// Rig to map topics with (else the one stored in the recording, else detected).
    #[doc(hidden)]
    pub rig: Option<Rig>,
    /// Target rate (Hz); the rig's control rate when None.
    #[doc(hidden)]
    pub fps: Option<f64>,
    /// Output image width.
    #[doc(hidden)]
    pub width: u32,
    /// Output image height.
    #[doc(hidden)]
    pub height: u32,
    /// JPEG quality.
    #[doc(hidden)]
    pub jpeg_quality: u8,
    /// A camera frame older than this many of its periods invalidates a tick.
    #[doc(hidden)]
    pub stale_periods: f64,
    /// Largest fraction of invalid ticks an episode may keep.
    #[doc(hidden)]
    pub max_invalid_fraction: f64,
    /// Task when the recording stores none.
    #[doc(hidden)]
    pub task: Option<String>,
    /// Align on log (receive) times instead of header stamps.
    #[doc(hidden)]
    pub use_log_time: bool,
    /// Convert only messages logged in `[start, end)` (ns): one part of a split recording (set
    /// by the batch job).
    #[doc(hidden)]
    pub window_ns: Option<(u64, u64)>,
    /// (name, topic): read camera / arm `name` (or `<arm>_gripper`, `<arm>_command`) from
    /// `topic` instead of the rig's.
    #[doc(hidden)]
    pub topic_overrides: Vec<(String, String)>,
    /// How far back (s) a stamp may lie behind one stored before it on its topic and be put
    /// back in order; further back is a clock jump.
    #[doc(hidden)]
    pub reorder_window_s: f64,
}

impl ConvertOptions {
    /// Maps topics with `rig` (default: the rig stored in the recording, else one detected from
    /// message types and joint names).
    pub fn rig(mut self, rig: Rig) -> Self {
        self.rig = Some(rig);
        self
    }
    /// Ticks at `hz` (default: the rig's control rate).
    pub fn fps(mut self, hz: f64) -> Self {
        self.fps = Some(hz);
        self
    }
    /// Stored image size (default 320×240).
    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.width = width;
        self.height = height;
        self
    }
    /// JPEG quality of stored images, 1–100 (default 90).
    pub fn jpeg_quality(mut self, quality: u8) -> Self {
        self.jpeg_quality = quality;
        self
    }
    /// A camera frame older than `periods` of its frame periods invalidates a tick (default 1.5).
    pub fn stale_periods(mut self, periods: f64) -> Self {
        self.stale_periods = periods;
        self
    }
    /// Largest fraction of invalid ticks inside an episode (default 0.05); more rejects it.
    pub fn max_invalid_fraction(mut self, fraction: f64) -> Self {
        self.max_invalid_fraction = fraction;
        self
    }
    /// Task instruction for inputs that store none (bags).
    pub fn task(mut self, task: impl Into<String>) -> Self {
        self.task = Some(task.into());
        self
    }
    /// Aligns on log (receive) times instead of header stamps (default false).
    pub fn use_log_time(mut self, yes: bool) -> Self {
        self.use_log_time = yes;
        self
    }
    /// Reads camera or arm `name` (or `<arm>_gripper`, `<arm>_command`) from `topic` instead of
    /// the rig's (repeatable; an unknown name fails the input).
    pub fn topic_override(mut self, name: impl Into<String>, topic: impl Into<String>) -> Self {
        self.topic_overrides.push((name.into(), topic.into()));
        self
    }
    /// Messages stamped up to `seconds` before one stored earlier on their topic are put back
    /// in stamp order and counted (default 0.1); further back is a clock jump.
    pub fn reorder_window(mut self, seconds: f64) -> Self {
        self.reorder_window_s = seconds;
        self
    }
    /// Whether a message logged at `log_ns` is inside the window converted.
    pub(crate) fn in_window(&self, log_ns: u64) -> bool {
        self.window_ns.is_none_or(|(a, b)| (a..b).contains(&log_ns))
    }
    /// The reorder window in ns.
    pub(crate) fn reorder_window_ns(&self) -> u64 {
        (self.reorder_window_s.max(0.0) * 1e9).min(u64::MAX as f64) as u64
    }
    /// Output size and quality of frames.
    pub(crate) fn encode_spec(&self) -> EncodeSpec {
        EncodeSpec {
            width: self.width,
            height: self.height,
            quality: self.jpeg_quality,
        }
    }
}

impl Default for ConvertOptions {
    fn default() -> Self {
        Self {
            rig: None,
            fps: None,
            width: 320,
            height: 240,
            jpeg_quality: 90,
            stale_periods: 1.5,
            max_invalid_fraction: 0.05,
            task: None,
            use_log_time: false,
            window_ns: None,
            topic_overrides: Vec::new(),
            reorder_window_s: 0.1,
        }
    }
}

/// One camera's frames of an episode.
#[derive(Debug, Clone)]
pub struct CameraFrames {
    /// Camera name (feature `observation.images.<name>`).
    pub name: String,
    /// JPEG bytes per frame.
    pub jpeg: Vec<Vec<u8>>,
    /// Pixel statistics over the resized frames.
    pub histogram: ChannelHistogram,
}

/// A converted episode, ready to be written.
#[derive(Debug, Clone)]
pub struct Episode {
    /// The input.
    pub source: PathBuf,
    /// The task instruction.
    pub task: String,
    /// Frame rate (Hz).
    pub fps: f64,
    /// The rig used (robot type = its name).
    pub rig: Rig,
    /// Seconds since the first frame, per frame.
    pub timestamps: Vec<f32>,
    /// `observation.state`, frames × `state_names.len()`.
    pub state: Vec<f32>,
    /// `action`, frames × `state_names.len()`.
    pub action: Vec<f32>,
    /// `observation.joints`, frames × `joint_names.len()`.
    pub joints: Vec<f32>,
    /// Names of the state/action dimensions.
    pub state_names: Vec<String>,
    /// Names of the joint dimensions.
    pub joint_names: Vec<String>,
    /// Per camera.
    pub cameras: Vec<CameraFrames>,
    /// Output image size (width, height).
    pub image_size: (u32, u32),
    /// JPEG quality of the frames.
    pub jpeg_quality: u8,
    /// What alignment measured.
    pub report: AlignmentReport,
    /// `header.stamp` or `log_time`.
    pub time_source: String,
}

impl Episode {
    /// Number of frames.
    pub fn len(&self) -> usize {
        self.timestamps.len()
    }
    /// True without frames.
    pub fn is_empty(&self) -> bool {
        self.timestamps.is_empty()
    }
}

/// State and action names: `x, y, z, roll, pitch, yaw, gripper` per arm, prefixed `<arm>_`
/// when the rig has more than one arm; arms in rig order.
pub fn state_names(rig: &Rig) -> Vec<String> {
    let dims = ["x", "y", "z", "roll", "pitch", "yaw", "gripper"];
    rig.arms
        .iter()
        .flat_map(|a| {
            dims.iter().map(move |d| {
                if rig.arms.len() > 1 {
                    format!("{}_{d}", a.name)
                } else {
                    (*d).to_string()
                }
            })
        })
        .collect()
}

/// The rig, rate and task an input is converted with: `--rig`, else the rig stored in the
/// recording, else one detected; `--topic` overrides applied; the stored task, else `--task`.
fn rig_and_task(path: &Path, rec: &Recording, opts: &ConvertOptions) -> Result<(Rig, f64, String)> {
    let stored = crate::detect::from_metadata(path, rec)?;
    let mut rig = match (&opts.rig, stored) {
        (Some(r), _) => r.clone(),
        (None, Some(r)) => r,
        (None, None) => crate::detect::detect(path, rec, opts.fps.unwrap_or(10.0))?,
    };
    crate::detect::override_topics(path, &mut rig, &opts.topic_overrides)?;
    if rig.arms.is_empty() {
        return Err(Error::Rejected {
            path: path.into(),
            reason: format!(
                "no arm: rig '{}' has cameras but no arm joint states, and an episode needs a \
                 state and an action (pass --rig to map an arm's topic)",
                rig.name
            ),
        });
    }
    let fps = opts.fps.unwrap_or(rig.control_rate_hz);
    let task = crate::detect::task_from_metadata(path, rec)?
        .or_else(|| opts.task.clone())
        .ok_or_else(|| Error::Rejected {
            path: path.into(),
            reason: "no task instruction: the recording stores none; pass --task".into(),
        })?;
    Ok((rig, fps, task))
}

/// The messages of `topic` logged inside the options' window, in stored order.
fn messages_of<'r>(rec: &'r Recording, topic: &str, opts: &ConvertOptions) -> Vec<&'r RawMessage> {
    rec.messages
        .iter()
        .filter(|m| m.topic == topic && opts.in_window(m.log_time_ns))
        .collect()
}

/// A camera's frames in stamp order: the stream aligned on, and each frame's stored ordinal.
struct CameraStream {
    stream: Stream,
    ordinals: Vec<usize>,
    reordered: usize,
}

/// Every camera's frame stamps (only those logged inside the window), put in stamp order.
fn camera_streams(
    path: &Path,
    rig: &Rig,
    frames: &dyn FrameStore,
    opts: &ConvertOptions,
) -> Result<Vec<CameraStream>> {
    let mut out = Vec::with_capacity(rig.cameras.len());
    for c in &rig.cameras {
        let (ordinals, stamps): (Vec<usize>, Vec<u64>) = frames
            .stamps(&c.topic)
            .into_iter()
            .enumerate()
            .filter(|(_, (_, log))| opts.in_window(*log))
            .map(|(i, (header, log))| (i, stamp_of(header, log, opts)))
            .unzip();
        if stamps.is_empty() {
            return Err(Error::Rejected {
                path: path.into(),
                reason: format!("camera '{}' ({}) has no messages", c.name, c.topic),
            });
        }
        let ordered = Ordered::new(path, &c.topic, &stamps, opts.reorder_window_ns())?;
        out.push(CameraStream {
            stream: Stream::new(
                &c.topic,
                ordered.order.iter().map(|&k| stamps[k]).collect(),
                Some(c.fps),
            ),
            ordinals: ordered.order.iter().map(|&k| ordinals[k]).collect(),
            reordered: ordered.reordered,
        });
    }
    Ok(out)
}

/// The joint series of every arm and its gripper (in that order, arms in rig order) and each
/// arm's kinematics.
fn arm_series(
    path: &Path,
    rig: &Rig,
    rec: &Recording,
    opts: &ConvertOptions,
) -> Result<(Vec<JointSeries>, Vec<ArmKinematics>)> {
    let mut series = Vec::new();
    let mut kin = Vec::new();
    let silent = |what: String| Error::Rejected {
        path: path.into(),
        reason: format!("{what} has no messages"),
    };
    for arm in &rig.arms {
        let msgs = messages_of(rec, &arm.joint_state_topic, opts);
        if msgs.is_empty() {
            return Err(silent(format!(
                "arm '{}' ({})",
                arm.name, arm.joint_state_topic
            )));
        }
        let topic = &arm.joint_state_topic;
        series.push(JointSeries::read(
            path,
            &msgs,
            topic,
            &arm.joint_names,
            arm.rate_hz,
            opts,
        )?);
        if let Some(g) = &arm.gripper {
            let gm = messages_of(rec, &g.topic, opts);
            if gm.is_empty() {
                return Err(silent(format!("gripper of '{}' ({})", arm.name, g.topic)));
            }
            series.push(JointSeries::read(
                path,
                &gm,
                &g.topic,
                &g.joint_names,
                g.rate_hz,
                opts,
            )?);
        }
        kin.push(ArmKinematics::new(arm).map_err(|e| Error::input(path, e))?);
    }
    Ok((series, kin))
}

/// Per tick: the state (TCP pose with unwrapped angles, gripper opening, per arm) and the joint
/// positions (arm then gripper joints, per arm).
struct TickRows {
    state: Vec<Vec<f32>>,
    joints: Vec<Vec<f32>>,
}

/// The [`TickRows`] of every aligned tick.
fn tick_states(
    path: &Path,
    rig: &Rig,
    series: &[JointSeries],
    kin: &[ArmKinematics],
    aligned: &Alignment,
) -> Result<TickRows> {
    let n_ticks = aligned.ticks_ns.len();
    let mut state_ticks = vec![Vec::new(); n_ticks];
    let mut joint_ticks = vec![Vec::new(); n_ticks];
    let mut s_idx = 0;
    for (arm, k) in rig.arms.iter().zip(kin) {
        let arm_series = s_idx;
        let grip_series = arm.gripper.as_ref().map(|_| s_idx + 1);
        s_idx += 1 + usize::from(grip_series.is_some());
        let mut poses = Vec::with_capacity(n_ticks);
        for (t, brackets) in aligned.samples.iter().enumerate() {
            let q = series[arm_series].interpolate(brackets[arm_series]);
            let pose = k.tcp_pose(&q).map_err(|e| Error::Rejected {
                path: path.into(),
                reason: format!("arm '{}': {e}", arm.name),
            })?;
            poses.push(pose);
            joint_ticks[t].extend(q.iter().map(|&x| x as f32));
        }
        unwrap_pose_angles(&mut poses);
        for (t, pose) in poses.iter().enumerate() {
            let width = match (grip_series, &arm.gripper) {
                (Some(g), Some(gr)) => {
                    let q = series[g].interpolate(aligned.samples[t][g]);
                    joint_ticks[t].extend(q.iter().map(|&x| x as f32));
                    gr.model.width_m(&q)
                }
                _ => 0.0,
            };
            state_ticks[t].extend(pose.iter().map(|&v| v as f32));
            state_ticks[t].push(width as f32);
        }
    }
    Ok(TickRows {
        state: state_ticks,
        joints: joint_ticks,
    })
}

/// Arms with a command topic take the action's pose from the latest command at each tick
/// (instead of the next tick's state), its angles put on the state's branch; grippers with a
/// command topic likewise the action's opening. Returns the messages reordered on those topics.
#[allow(clippy::too_many_arguments)]
fn command_actions(
    path: &Path,
    rig: &Rig,
    kin: &[ArmKinematics],
    rec: &Recording,
    ticks_ns: &[u64],
    state_ticks: &[Vec<f32>],
    action: &mut [f32],
    opts: &ConvertOptions,
) -> Result<usize> {
    let dim = 7 * rig.arms.len();
    let mut reordered = 0;
    for (a, (arm, k)) in rig.arms.iter().zip(kin).enumerate() {
        // --- gripper command (scaledp-sim, issue 10): a gripper's `command_topic` (a leader
        // gripper's JointState, its joints mapped by name) gives the action's gripper opening:
        // the latest command at each tick.
        if let Some((g, topic)) = arm
            .gripper
            .as_ref()
            .and_then(|g| Some((g, g.command_topic.as_ref()?)))
        {
            let msgs = messages_of(rec, topic, opts);
            let rate = rig.control_rate_hz;
            let cmd = JointSeries::read(path, &msgs, topic, &g.joint_names, rate, opts)?;
            if cmd.positions.is_empty() {
                return Err(Error::Rejected {
                    path: path.into(),
                    reason: format!(
                        "gripper command topic {topic} of arm '{}' has no messages",
                        arm.name
                    ),
                });
            }
            reordered += cmd.reordered;
            for (t, tick) in ticks_ns.iter().enumerate() {
                let i = cmd.stream.latest_at(*tick).unwrap_or(0);
                action[t * dim + a * 7 + 6] = g.model.width_m(&cmd.positions[i]) as f32;
            }
        }
        // --- end gripper command
        let Some(topic) = &arm.command_topic else {
            continue;
        };
        let msgs = messages_of(rec, topic, opts);
        let command = CommandPoses::read(path, &msgs, arm, k, opts)?;
        if command.stamps_ns.is_empty() {
            return Err(Error::Rejected {
                path: path.into(),
                reason: format!(
                    "command topic {topic} of arm '{}' has no messages",
                    arm.name
                ),
            });
        }
        reordered += command.reordered;
        let stream = Stream::new(topic, command.stamps_ns, None);
        let chosen: Vec<usize> = ticks_ns
            .iter()
            .map(|tick| stream.latest_at(*tick).unwrap_or(0))
            .collect();
        // Put the command's angles on the state's branch (within π of it at the first tick),
        // so action − state never carries a spurious full turn.
        let mut turn = [0.0; 6];
        if let Some(&first) = chosen.first() {
            for (d, shift) in turn.iter_mut().enumerate().skip(3) {
                let gap = f64::from(state_ticks[0][a * 7 + d]) - command.poses[first][d];
                *shift = std::f64::consts::TAU * (gap / std::f64::consts::TAU).round();
            }
        }
        for (t, &i) in chosen.iter().enumerate() {
            for (d, v) in command.poses[i].iter().enumerate() {
                action[t * dim + a * 7 + d] = (*v + turn[d]) as f32;
            }
        }
    }
    Ok(reordered)
}

/// Each camera's chosen frame at each of the first `frames` ticks: decoded, resized and
/// JPEG-encoded once (in parallel), with the episode's pixel statistics.
fn camera_frames(
    path: &Path,
    rig: &Rig,
    store: &dyn FrameStore,
    cams: &[CameraStream],
    aligned: &Alignment,
    frames: usize,
    spec: &EncodeSpec,
) -> Result<Vec<CameraFrames>> {
    let mut wanted: BTreeMap<String, BTreeSet<usize>> = BTreeMap::new();
    for (ci, cam) in rig.cameras.iter().enumerate() {
        wanted.entry(cam.topic.clone()).or_default().extend(
            aligned.frames[..frames]
                .iter()
                .map(|f| cams[ci].ordinals[f[ci]]),
        );
    }
    let done = store.encode(path, &wanted, spec)?;
    let mut cameras = Vec::with_capacity(rig.cameras.len());
    for (ci, cam) in rig.cameras.iter().enumerate() {
        let mut histogram = ChannelHistogram::default();
        let mut jpeg = Vec::with_capacity(frames);
        for f in &aligned.frames[..frames] {
            let ordinal = cams[ci].ordinals[f[ci]];
            let e = done
                .get(&(cam.topic.clone(), ordinal))
                .ok_or_else(|| Error::Rejected {
                    path: path.into(),
                    reason: format!(
                        "frame {ordinal} of {} was not found on the second read",
                        cam.topic
                    ),
                })?;
            histogram.absorb(&e.histogram);
            jpeg.push(e.jpeg.clone());
        }
        cameras.push(CameraFrames {
            name: cam.name.clone(),
            jpeg,
            histogram,
        });
    }
    Ok(cameras)
}

/// Converts one recording: picks the rig, aligns the camera and joint streams on a tick grid,
/// computes state (TCP poses by forward kinematics) and action per tick, and encodes the
/// frames chosen.
pub fn convert(
    path: &Path,
    rec: &Recording,
    frames_store: &dyn FrameStore,
    opts: &ConvertOptions,
) -> Result<Episode> {
    let (rig, fps, task) = rig_and_task(path, rec, opts)?;
    // Cameras: stamps only; pixels later, for the frames chosen.
    let cams = camera_streams(path, &rig, frames_store, opts)?;
    let (series, kin) = arm_series(path, &rig, rec, opts)?;
    let cam_streams: Vec<Stream> = cams.iter().map(|c| c.stream.clone()).collect();
    let joint_streams: Vec<Stream> = series.iter().map(|s| s.stream.clone()).collect();
    let mut aligned = align(
        &cam_streams,
        &joint_streams,
        fps,
        opts.stale_periods,
        opts.max_invalid_fraction,
    )
    .map_err(|reason| Error::Rejected {
        path: path.into(),
        reason,
    })?;
    let reordered = cams.iter().map(|c| c.reordered);
    let reordered = reordered.chain(series.iter().map(|s| s.reordered));
    for (report, n) in aligned.report.streams.iter_mut().zip(reordered) {
        report.reordered = n;
    }

    let TickRows {
        state: state_ticks,
        joints: joint_ticks,
    } = tick_states(path, &rig, &series, &kin, &aligned)?;
    // The action is the next tick's state: the last tick has none and is dropped. An arm with a
    // command topic takes its pose from the latest command at the tick instead (its gripper
    // from its gripper's command topic, if any, else still from the next tick).
    let frames = aligned.ticks_ns.len() - 1;
    let state: Vec<f32> = state_ticks[..frames].concat();
    let mut action: Vec<f32> = state_ticks[1..].concat();
    let reordered_commands = command_actions(
        path,
        &rig,
        &kin,
        rec,
        &aligned.ticks_ns[..frames],
        &state_ticks,
        &mut action,
        opts,
    )?;
    aligned.report.reordered = aligned
        .report
        .streams
        .iter()
        .map(|s| s.reordered)
        .sum::<usize>()
        + reordered_commands;
    let joints: Vec<f32> = joint_ticks[..frames].concat();
    let t0 = aligned.ticks_ns[0];
    let timestamps = aligned.ticks_ns[..frames]
        .iter()
        .map(|t| ((t - t0) as f64 * 1e-9) as f32)
        .collect();

    let spec = opts.encode_spec();
    let cameras = camera_frames(path, &rig, frames_store, &cams, &aligned, frames, &spec)?;
    let joint_names = rig
        .arms
        .iter()
        .flat_map(|a| {
            a.joint_names
                .iter()
                .chain(a.gripper.iter().flat_map(|g| g.joint_names.iter()))
                .cloned()
        })
        .collect();
    Ok(Episode {
        source: path.into(),
        task,
        fps,
        state_names: state_names(&rig),
        joint_names,
        rig,
        timestamps,
        state,
        action,
        joints,
        cameras,
        image_size: (spec.width, spec.height),
        jpeg_quality: spec.quality,
        report: aligned.report,
        time_source: if opts.use_log_time {
            "log_time".into()
        } else {
            "header.stamp".into()
        },
    })
}
