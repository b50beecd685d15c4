//! One input → one training episode: aligned ticks, end-effector state and action per arm,
//! joint positions, and per camera resized JPEG frames, depth and intrinsics (see
//! [`crate::cameras`]).

use std::path::{Path, PathBuf};

use scaledp_codec::VideoSettings;
use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;

pub use scaledp_schema::action::state_names;

use crate::actions::command_actions;
use crate::cameras::{camera_frames, camera_streams, Chosen};
pub use crate::cameras::{CameraFrames, DepthFrames};
use crate::error::{Error, Result};
use crate::frames::FrameStore;
use crate::kinematics::ArmKinematics;
pub use crate::options::ConvertOptions;
pub use crate::recorded::Recorded;
use crate::series::{messages_of, unwrap_pose_angles, JointSeries};
use crate::source::Recording;
use scaledp_align::{align, Alignment, AlignmentReport, Stream};

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
    /// The space of the state and action.
    pub action_space: ActionSpace,
    /// Names of the joint dimensions.
    pub joint_names: Vec<String>,
    /// Per camera.
    pub cameras: Vec<CameraFrames>,
    /// Output image size (width, height).
    pub image_size: (u32, u32),
    /// JPEG quality of the frames.
    pub jpeg_quality: u8,
    /// How the cameras are stored as video (None: as JPEG images).
    pub video: Option<VideoSettings>,
    /// What alignment measured.
    pub report: AlignmentReport,
    /// `header.stamp` or `log_time`.
    pub time_source: String,
    /// Operator, label and verdict (see [`Recorded`]).
    pub recorded: Recorded,
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

/// Per tick: the state (per arm the TCP pose with unwrapped angles, or with
/// [`ActionSpace::Joints`] the joint positions, then the gripper opening) and the joint
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
    space: ActionSpace,
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
        let grip_joints = arm.gripper.as_ref().map_or(0, |g| g.joint_names.len());
        for (t, pose) in poses.iter().enumerate() {
            let width = match (grip_series, &arm.gripper) {
                (Some(g), Some(gr)) => {
                    let q = series[g].interpolate(aligned.samples[t][g]);
                    joint_ticks[t].extend(q.iter().map(|&x| x as f32));
                    gr.model.width_m(&q)
                }
                _ => 0.0,
            };
            match space {
                ActionSpace::Tcp => state_ticks[t].extend(pose.iter().map(|&v| v as f32)),
                ActionSpace::Joints => {
                    let n = arm.joint_names.len();
                    let q = &joint_ticks[t];
                    let at = q.len() - n - grip_joints;
                    state_ticks[t].extend_from_slice(&q[at..at + n]);
                }
            }
            state_ticks[t].push(width as f32);
        }
    }
    Ok(TickRows {
        state: state_ticks,
        joints: joint_ticks,
    })
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
    // Depth is aligned as one more camera: the same frame rule, its own staleness.
    let cam_streams: Vec<Stream> = cams.all().map(|c| c.stream.clone()).collect();
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
    let reordered = cams.all().map(|c| c.reordered);
    let reordered = reordered.chain(series.iter().map(|s| s.reordered));
    for (report, n) in aligned.report.streams.iter_mut().zip(reordered) {
        report.reordered = n;
    }

    let TickRows {
        state: state_ticks,
        joints: joint_ticks,
    } = tick_states(path, &rig, &series, &kin, &aligned, opts.action_space)?;
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
    let video = opts.video.map(|codec| VideoSettings::lerobot(codec, fps));
    let chosen = Chosen {
        streams: &cams,
        aligned: &aligned,
        frames,
        spec: &spec,
        video,
    };
    let cameras = camera_frames(path, &rig, rec, frames_store, &chosen, opts)?;
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
    let meta = crate::detect::episode_metadata(path, rec)?;
    let recorded = crate::recorded::recorded(&rec.metadata, meta.as_ref(), &aligned.report, fps);
    Ok(Episode {
        source: path.into(),
        task,
        fps,
        state_names: state_names(&rig, opts.action_space),
        action_space: opts.action_space,
        joint_names,
        rig,
        timestamps,
        state,
        action,
        joints,
        cameras,
        image_size: (spec.width, spec.height),
        jpeg_quality: spec.quality,
        video,
        report: aligned.report,
        time_source: if opts.use_log_time {
            "log_time".into()
        } else {
            "header.stamp".into()
        },
        recorded,
    })
}
