//! One input → one training episode: aligned ticks, end-effector state and action per arm,
//! joint positions, and resized JPEG frames per camera.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use glam::DMat4;
use scaledp_schema::kinematics::{pose6_from_transform, rotation_from_rpy, unwrap_angles};
use scaledp_schema::rig::{Arm, Rig};

use crate::align::{align, AlignmentReport, Stream};
use crate::decode;
use crate::error::{Error, Result};
use crate::frames::FrameStore;
use crate::images::{ChannelHistogram, EncodeSpec};
use crate::source::{RawMessage, Recording};

/// How to convert. Defaults: the rig's control rate, 320×240 JPEG at quality 90, frames staler
/// than 1.5 periods invalidate a tick, at most 5 % invalid ticks, header stamps as time.
#[derive(Debug, Clone)]
pub struct ConvertOptions {
    /// Rig to map topics with (else the one stored in the recording, else detected).
    pub rig: Option<Rig>,
    /// Target rate (Hz); the rig's control rate when None.
    pub fps: Option<f64>,
    /// Output image width.
    pub width: u32,
    /// Output image height.
    pub height: u32,
    /// JPEG quality.
    pub jpeg_quality: u8,
    /// A camera frame older than this many of its periods invalidates a tick.
    pub stale_periods: f64,
    /// Largest fraction of invalid ticks an episode may keep.
    pub max_invalid_fraction: f64,
    /// Task when the recording stores none.
    pub task: Option<String>,
    /// Align on log (receive) times instead of header stamps.
    pub use_log_time: bool,
    /// Convert only messages logged in `[start, end)` (ns): one part of a split recording.
    pub window_ns: Option<(u64, u64)>,
    /// (name, topic): read camera / arm `name` (or `<arm>_gripper`, `<arm>_command`) from
    /// `topic` instead of the rig's.
    pub topic_overrides: Vec<(String, String)>,
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

/// An arm's forward kinematics to its TCP.
enum Kinematics {
    Builtin(scaledp_schema::RobotModel),
    Urdf(crate::urdf::UrdfChain),
}

fn kinematics(path: &Path, arm: &Arm) -> Result<(Kinematics, DMat4)> {
    let tcp = match arm.tcp_xyz_rpy {
        Some([x, y, z, r, p, yw]) => {
            DMat4::from_translation(glam::DVec3::new(x, y, z))
                * DMat4::from_mat3(rotation_from_rpy([r, p, yw]))
        }
        None if arm.urdf.is_some() => DMat4::IDENTITY,
        None => arm.model.default_flange_from_tcp(),
    };
    let k = match &arm.urdf {
        Some(u) => {
            let chain = crate::urdf::UrdfChain::from_file(&u.path, &u.base_link, &u.tip_link)?;
            if chain.joint_names() != arm.joint_names.as_slice() {
                return Err(Error::input(
                    path,
                    format!(
                        "arm '{}': URDF joints {:?} differ from the rig's {:?}",
                        arm.name,
                        chain.joint_names(),
                        arm.joint_names
                    ),
                ));
            }
            Kinematics::Urdf(chain)
        }
        None => Kinematics::Builtin(arm.model),
    };
    Ok((k, tcp))
}

fn fk(k: &Kinematics, q: &[f64]) -> std::result::Result<DMat4, String> {
    match k {
        Kinematics::Builtin(m) => m.base_from_flange(q).map_err(|e| e.to_string()),
        Kinematics::Urdf(c) => c.base_from_tip(q).map_err(|e| e.to_string()),
    }
}

/// A JointState topic as stamps plus positions of `names` (mapped by name, never by index).
struct JointSeries {
    stream: Stream,
    positions: Vec<Vec<f64>>,
}

fn stamp_of(m: &RawMessage, header_ns: u64, opts: &ConvertOptions) -> u64 {
    if opts.use_log_time || header_ns == 0 {
        m.log_time_ns
    } else {
        header_ns
    }
}

fn check_monotonic(path: &Path, topic: &str, stamps: &[u64]) -> Result<()> {
    if let Some(i) = stamps.windows(2).position(|w| w[1] < w[0]) {
        return Err(Error::Rejected {
            path: path.into(),
            reason: format!(
                "time runs backwards on {topic}: stamp {} ns after {} ns (message {})",
                stamps[i + 1],
                stamps[i],
                i + 1
            ),
        });
    }
    Ok(())
}

fn joint_series(
    path: &Path,
    msgs: &[&RawMessage],
    topic: &str,
    names: &[String],
    rate: f64,
    opts: &ConvertOptions,
) -> Result<JointSeries> {
    let mut stamps = Vec::with_capacity(msgs.len());
    let mut positions = Vec::with_capacity(msgs.len());
    // Where each wanted joint sits in the message; re-mapped whenever the name list changes.
    let mut seen_names: Vec<String> = Vec::new();
    let mut index: Vec<Option<usize>> = Vec::new();
    for m in msgs {
        let js = decode::joint_state(path, m)?;
        if js.name.len() != js.position.len() {
            return Err(Error::Message {
                path: path.into(),
                topic: topic.into(),
                log_time_ns: m.log_time_ns,
                reason: format!(
                    "{} names but {} positions",
                    js.name.len(),
                    js.position.len()
                ),
            });
        }
        if js.name != seen_names {
            index = names
                .iter()
                .map(|n| js.name.iter().position(|x| x == n))
                .collect();
            seen_names = js.name.clone();
        }
        let mut q = Vec::with_capacity(names.len());
        for (n, i) in names.iter().zip(&index) {
            let i = i.ok_or_else(|| Error::Rejected {
                path: path.into(),
                reason: format!("joint '{n}' is missing from {topic} (it has {:?})", js.name),
            })?;
            let v = js.position[i];
            if !v.is_finite() {
                return Err(Error::Rejected {
                    path: path.into(),
                    reason: format!("joint '{n}' on {topic} is {v} at {} ns", m.log_time_ns),
                });
            }
            q.push(v);
        }
        stamps.push(stamp_of(m, js.header.stamp.as_ns(), opts));
        positions.push(q);
    }
    check_monotonic(path, topic, &stamps)?;
    Ok(JointSeries {
        stream: Stream::new(topic, stamps, Some(rate)),
        positions,
    })
}

fn interpolate(series: &JointSeries, (i, j, w): (usize, usize, f64)) -> Vec<f64> {
    series.positions[i]
        .iter()
        .zip(&series.positions[j])
        .map(|(a, b)| a + w * (b - a))
        .collect()
}

/// Stamps and unwrapped TCP poses of a command topic: `PoseStamped` targets as they are, a
/// leader arm's `JointState` through this arm's kinematics.
fn command_poses(
    path: &Path,
    msgs: &[&RawMessage],
    arm: &Arm,
    k: &Kinematics,
    tcp: &DMat4,
    opts: &ConvertOptions,
) -> Result<(Vec<u64>, Vec<[f64; 6]>)> {
    let mut stamps = Vec::with_capacity(msgs.len());
    let mut poses = Vec::with_capacity(msgs.len());
    let topic = msgs.first().map(|m| m.topic.clone()).unwrap_or_default();
    if msgs
        .first()
        .is_some_and(|m| m.message_type.ends_with("/PoseStamped"))
    {
        for m in msgs {
            let p = decode::pose_stamped(path, m)?;
            let o = p.pose.orientation;
            let r = glam::DMat3::from_quat(glam::DQuat::from_xyzw(o.x, o.y, o.z, o.w).normalize());
            let [roll, pitch, yaw] = scaledp_schema::kinematics::rpy_from_rotation(r);
            stamps.push(stamp_of(m, p.header.stamp.as_ns(), opts));
            poses.push([
                p.pose.position.x,
                p.pose.position.y,
                p.pose.position.z,
                roll,
                pitch,
                yaw,
            ]);
        }
    } else {
        let series = joint_series(path, msgs, &topic, &arm.joint_names, arm.rate_hz, opts)?;
        for q in &series.positions {
            let flange = fk(k, q).map_err(|e| Error::Rejected {
                path: path.into(),
                reason: format!("{topic}: {e}"),
            })?;
            poses.push(pose6_from_transform(flange * *tcp));
        }
        stamps = series.stream.stamps_ns;
    }
    check_monotonic(path, &topic, &stamps)?;
    for axis in 3..6 {
        let mut col: Vec<f64> = poses.iter().map(|p| p[axis]).collect();
        unwrap_angles(&mut col);
        for (p, v) in poses.iter_mut().zip(col) {
            p[axis] = v;
        }
    }
    Ok((stamps, poses))
}

/// Converts one recording.
pub fn convert(
    path: &Path,
    rec: &Recording,
    frames_store: &dyn FrameStore,
    opts: &ConvertOptions,
) -> Result<Episode> {
    let frames = frames_store;
    let stored = crate::detect::from_metadata(path, rec)?;
    let mut rig = match (&opts.rig, stored) {
        (Some(r), _) => r.clone(),
        (None, Some(r)) => r,
        (None, None) => crate::detect::detect(path, rec, opts.fps.unwrap_or(10.0))?,
    };
    crate::detect::override_topics(path, &mut rig, &opts.topic_overrides)?;
    let fps = opts.fps.unwrap_or(rig.control_rate_hz);
    let task = crate::detect::task_from_metadata(path, rec)?
        .or_else(|| opts.task.clone())
        .ok_or_else(|| Error::Rejected {
            path: path.into(),
            reason: "no task instruction: the recording stores none; pass --task".into(),
        })?;
    let by_topic = |topic: &str| -> Vec<&RawMessage> {
        rec.messages
            .iter()
            .filter(|m| {
                m.topic == topic
                    && opts
                        .window_ns
                        .is_none_or(|(a, b)| (a..b).contains(&m.log_time_ns))
            })
            .collect()
    };
    let reject = |reason: String| Error::Rejected {
        path: path.into(),
        reason,
    };

    // Cameras: stamps only; pixels later, for the frames chosen.
    let in_window = |log_ns: u64| opts.window_ns.is_none_or(|(a, b)| (a..b).contains(&log_ns));
    let mut cam_streams = Vec::new();
    // Per camera: stored ordinal of each frame kept (all of them unless a window is set).
    let mut cam_ordinals: Vec<Vec<usize>> = Vec::new();
    for c in &rig.cameras {
        let (ordinals, stamps): (Vec<usize>, Vec<u64>) = frames
            .stamps(&c.topic)
            .into_iter()
            .enumerate()
            .filter(|(_, (_, log))| in_window(*log))
            .map(|(i, (header, log))| {
                (
                    i,
                    if opts.use_log_time || header == 0 {
                        log
                    } else {
                        header
                    },
                )
            })
            .unzip();
        if stamps.is_empty() {
            return Err(reject(format!(
                "camera '{}' ({}) has no messages",
                c.name, c.topic
            )));
        }
        check_monotonic(path, &c.topic, &stamps)?;
        cam_streams.push(Stream::new(&c.topic, stamps, Some(c.fps)));
        cam_ordinals.push(ordinals);
    }
    // Arms, grippers and command topics.
    let mut series = Vec::new();
    let mut kin = Vec::new();
    for arm in &rig.arms {
        let msgs = by_topic(&arm.joint_state_topic);
        if msgs.is_empty() {
            return Err(reject(format!(
                "arm '{}' ({}) has no messages",
                arm.name, arm.joint_state_topic
            )));
        }
        series.push(joint_series(
            path,
            &msgs,
            &arm.joint_state_topic,
            &arm.joint_names,
            arm.rate_hz,
            opts,
        )?);
        if let Some(g) = &arm.gripper {
            let gm = by_topic(&g.topic);
            if gm.is_empty() {
                return Err(reject(format!(
                    "gripper of '{}' ({}) has no messages",
                    arm.name, g.topic
                )));
            }
            series.push(joint_series(
                path,
                &gm,
                &g.topic,
                &g.joint_names,
                g.rate_hz,
                opts,
            )?);
        }
        kin.push(kinematics(path, arm)?);
    }
    let streams: Vec<Stream> = series.iter().map(|s| s.stream.clone()).collect();
    let aligned = align(
        &cam_streams,
        &streams,
        fps,
        opts.stale_periods,
        opts.max_invalid_fraction,
    )
    .map_err(reject)?;

    // State per tick, per arm: pose of the TCP, unwrapped angles, gripper width.
    let n_ticks = aligned.ticks_ns.len();
    let mut state_ticks = vec![Vec::new(); n_ticks];
    let mut joint_ticks = vec![Vec::new(); n_ticks];
    let mut s_idx = 0;
    for (arm, (k, tcp)) in rig.arms.iter().zip(&kin) {
        let arm_series = s_idx;
        let grip_series = arm.gripper.as_ref().map(|_| s_idx + 1);
        s_idx += 1 + usize::from(grip_series.is_some());
        let mut poses = Vec::with_capacity(n_ticks);
        for (t, brackets) in aligned.samples.iter().enumerate() {
            let q = interpolate(&series[arm_series], brackets[arm_series]);
            let flange = fk(k, &q).map_err(|e| reject(format!("arm '{}': {e}", arm.name)))?;
            poses.push(pose6_from_transform(flange * *tcp));
            joint_ticks[t].extend(q.iter().map(|&x| x as f32));
        }
        for axis in 3..6 {
            let mut col: Vec<f64> = poses.iter().map(|p| p[axis]).collect();
            unwrap_angles(&mut col);
            for (p, v) in poses.iter_mut().zip(col) {
                p[axis] = v;
            }
        }
        for (t, pose) in poses.iter().enumerate() {
            let width = match (grip_series, &arm.gripper) {
                (Some(g), Some(gr)) => {
                    let q = interpolate(&series[g], aligned.samples[t][g]);
                    joint_ticks[t].extend(q.iter().map(|&x| x as f32));
                    gr.model.width_m(&q)
                }
                _ => 0.0,
            };
            state_ticks[t].extend(pose.iter().map(|&v| v as f32));
            state_ticks[t].push(width as f32);
        }
    }
    // The action is the next tick's state: the last tick has none and is dropped. An arm with a
    // command topic takes its pose from the latest command at the tick instead (its gripper
    // from its gripper's command topic, if any, else still from the next tick).
    let frames = n_ticks - 1;
    let state: Vec<f32> = state_ticks[..frames].concat();
    let mut action: Vec<f32> = state_ticks[1..].concat();
    let dim = 7 * rig.arms.len();
    for (a, (arm, (k, tcp))) in rig.arms.iter().zip(&kin).enumerate() {
        // --- gripper command (scaledp-sim, issue 10): a gripper's `command_topic` (a leader
        // gripper's JointState, its joints mapped by name) gives the action's gripper opening:
        // the latest command at each tick.
        if let Some((g, topic)) = arm
            .gripper
            .as_ref()
            .and_then(|g| Some((g, g.command_topic.as_ref()?)))
        {
            let msgs = by_topic(topic);
            let rate = rig.control_rate_hz;
            let cmd = joint_series(path, &msgs, topic, &g.joint_names, rate, opts)?;
            if cmd.positions.is_empty() {
                return Err(reject(format!(
                    "gripper command topic {topic} of arm '{}' has no messages",
                    arm.name
                )));
            }
            for (t, tick) in aligned.ticks_ns[..frames].iter().enumerate() {
                let i = cmd.stream.latest_at(*tick).unwrap_or(0);
                action[t * dim + a * 7 + 6] = g.model.width_m(&cmd.positions[i]) as f32;
            }
        }
        // --- end gripper command
        let Some(topic) = &arm.command_topic else {
            continue;
        };
        let (stamps, poses) = command_poses(path, &by_topic(topic), arm, k, tcp, opts)?;
        if stamps.is_empty() {
            return Err(reject(format!(
                "command topic {topic} of arm '{}' has no messages",
                arm.name
            )));
        }
        let stream = Stream::new(topic, stamps, None);
        let chosen: Vec<usize> = aligned.ticks_ns[..frames]
            .iter()
            .map(|tick| stream.latest_at(*tick).unwrap_or(0))
            .collect();
        // Put the command's angles on the state's branch (within π of it at the first tick),
        // so action − state never carries a spurious full turn.
        let mut turn = [0.0; 6];
        if let Some(&first) = chosen.first() {
            for (d, shift) in turn.iter_mut().enumerate().skip(3) {
                let gap = f64::from(state_ticks[0][a * 7 + d]) - poses[first][d];
                *shift = std::f64::consts::TAU * (gap / std::f64::consts::TAU).round();
            }
        }
        for (t, &i) in chosen.iter().enumerate() {
            for (d, v) in poses[i].iter().enumerate() {
                action[t * dim + a * 7 + d] = (*v + turn[d]) as f32;
            }
        }
    }
    let joints: Vec<f32> = joint_ticks[..frames].concat();
    let t0 = aligned.ticks_ns[0];
    let timestamps = aligned.ticks_ns[..frames]
        .iter()
        .map(|t| ((t - t0) as f64 * 1e-9) as f32)
        .collect();

    // Images: each chosen frame decoded once, resized and encoded, in parallel.
    let (w, h) = (opts.width, opts.height);
    let mut wanted: BTreeMap<String, BTreeSet<usize>> = BTreeMap::new();
    for (ci, cam) in rig.cameras.iter().enumerate() {
        wanted.entry(cam.topic.clone()).or_default().extend(
            aligned.frames[..frames]
                .iter()
                .map(|f| cam_ordinals[ci][f[ci]]),
        );
    }
    let spec = EncodeSpec {
        width: w,
        height: h,
        quality: opts.jpeg_quality,
    };
    let done = frames_store.encode(path, &wanted, &spec)?;
    let mut cameras = Vec::with_capacity(rig.cameras.len());
    for (ci, cam) in rig.cameras.iter().enumerate() {
        let mut histogram = ChannelHistogram::default();
        let mut jpeg = Vec::with_capacity(frames);
        for f in &aligned.frames[..frames] {
            let ordinal = cam_ordinals[ci][f[ci]];
            let e = done.get(&(cam.topic.clone(), ordinal)).ok_or_else(|| {
                reject(format!(
                    "frame {} of {} was not found on the second read",
                    ordinal, cam.topic
                ))
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
        image_size: (w, h),
        report: aligned.report,
        time_source: if opts.use_log_time {
            "log_time".into()
        } else {
            "header.stamp".into()
        },
    })
}
