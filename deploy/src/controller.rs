//! The controller core, pure and clock-free: feed it stamped camera frames and joint states;
//! at each control tick it builds the observation window exactly as `scaledp convert` built the
//! training data ([`scaledp_converter::live`]: latest frame at or before the tick, interpolated
//! joints, FK to the same TCP, the same resize and JPEG path, decoded as the loader decodes),
//! asks for a chunk when the receding horizon needs one, and turns the chunk's action for the
//! tick into clamped per-arm commands.
//!
//! Call order per tick: [`Controller::tick`] (maybe a [`Request`] to run the policy on),
//! [`Controller::install`] when a chunk comes back (at once when acting synchronously, ticks
//! later when inference overlaps execution), [`Controller::command`] for what to publish.
//!
//! Receding horizon: a chunk predicted from the window ending at tick k holds the actions of
//! ticks k … k + C − 1; ticks k … k + `action_steps` − 1 are executed, and the next chunk is
//! asked for at tick k + `action_steps` − `lead` (`lead` = expected inference latency in ticks,
//! 0 when acting synchronously), so it arrives as the current one runs out. Actions for ticks
//! already past when a chunk arrives are skipped.

use std::collections::{BTreeMap, VecDeque};

use glam::DMat4;
use scaledp_converter::live::{self, ArmKinematics, EncodeSpec};
use scaledp_converter::Serialization;
use scaledp_policy::{ActionChunk, CheckpointConfig, ImageChain, Observation};
use scaledp_schema::msg::JointState;
use scaledp_schema::rig::Gripper;
use scaledp_schema::{ActionSpace, Rig};

use crate::command::{arm_target, Previous};
use crate::error::{Error, Result};
use crate::inputs::Inputs;
pub use crate::options::ControlOptions;
use crate::safety::{Clamped, Limits, Workspace};
pub use crate::tick::{Command, Request, Tick};

/// The controller core; see the module documentation.
#[derive(Debug)]
pub struct Controller {
    cfg: CheckpointConfig,
    chain: ImageChain,
    rig: Rig,
    opts: ControlOptions,
    limits: Limits,
    kin: Vec<ArmKinematics>,
    grippers: Vec<Option<Gripper>>,
    inputs: Inputs,
    period_ns: f64,
    origin_ns: Option<u64>,
    index: u64,
    history: VecDeque<(Vec<u8>, Vec<f32>)>,
    /// The first tick's images, with [`ControlOptions::freeze_cameras`].
    frozen: Option<Vec<u8>>,
    prev_pose: Vec<Option<[f64; 6]>>,
    plan: BTreeMap<u64, Vec<f32>>,
    pending: Option<u64>,
    next_request: u64,
    lead_ticks: u64,
    last_command: Vec<Option<(DMat4, Vec<f64>)>>,
    measured: Vec<DMat4>,
    measured_q: Vec<Vec<f64>>,
    halted: Option<String>,
    obs_lag_ns: u64,
}

impl Controller {
    /// A controller for checkpoint config `cfg` (named `ckpt` in messages) on `rig`; fails
    /// with one line when they do not fit ([`crate::check`]).
    pub fn new(
        cfg: &CheckpointConfig,
        ckpt: &str,
        rig: &Rig,
        opts: ControlOptions,
    ) -> Result<Self> {
        let cams = crate::check::check(cfg, ckpt, rig)?;
        let chain = cfg.image_chain();
        if !chain.exact() {
            tracing::warn!(
                "{ckpt}: trained on images scaledp convert did not write ({}); camera frames are \
                 brought to them the converter's way, which may differ from how they were made",
                chain.describe()
            );
        }
        if opts.action_steps == 0 || opts.action_steps > cfg.model.action_chunk {
            return Err(Error::Options(format!(
                "--action-steps {}: between 1 and the checkpoint's chunk of {}",
                opts.action_steps, cfg.model.action_chunk
            )));
        }
        let workspace = opts
            .workspace
            .clone()
            .unwrap_or_else(|| Workspace::for_rig(rig));
        if workspace.len() != rig.arms.len() {
            return Err(Error::Options(format!(
                "{} workspace boxes for {} arms",
                workspace.len(),
                rig.arms.len()
            )));
        }
        let kin = rig
            .arms
            .iter()
            .map(|a| ArmKinematics::new(a).map_err(|e| Error::Incompatible(e.to_string())))
            .collect::<Result<Vec<_>>>()?;
        // Joints are interpolated between the samples around the tick: the tick must trail the
        // clock by more than the slowest joint stream's period.
        let slowest_s = rig
            .arms
            .iter()
            .flat_map(|a| std::iter::once(a.rate_hz).chain(a.gripper.as_ref().map(|g| g.rate_hz)))
            .map(|hz| 1.0 / hz)
            .fold(0.0, f64::max);
        let obs_lag_s = if opts.lockstep {
            0.0
        } else {
            opts.obs_lag_s.max(1.5 * slowest_s)
        };
        // Keep the frames a tick can still pick: the observation lag plus a few frame periods.
        let inputs = Inputs::new(rig, cams, obs_lag_s + 0.15);
        let n = rig.arms.len();
        Ok(Controller {
            limits: Limits {
                workspace,
                max_step_m: opts.max_step_m,
                max_step_rad: opts.max_step_rad,
            },
            chain,
            cfg: cfg.clone(),
            rig: rig.clone(),
            kin,
            grippers: rig.arms.iter().map(|a| a.gripper.clone()).collect(),
            inputs,
            period_ns: 1e9 / cfg.fps,
            origin_ns: None,
            index: 0,
            history: VecDeque::new(),
            frozen: None,
            prev_pose: vec![None; n],
            plan: BTreeMap::new(),
            pending: None,
            next_request: 0,
            lead_ticks: 0,
            last_command: vec![None; n],
            measured: vec![DMat4::IDENTITY; n],
            measured_q: rig
                .arms
                .iter()
                .map(|a| vec![0.0; a.joint_names.len()])
                .collect(),
            halted: None,
            obs_lag_ns: (obs_lag_s * 1e9).round() as u64,
            opts,
        })
    }

    /// The rig.
    pub fn rig(&self) -> &Rig {
        &self.rig
    }

    /// The limits in force.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// The control period (ns): 1 / the checkpoint's fps.
    pub fn period_ns(&self) -> u64 {
        self.period_ns.round() as u64
    }

    /// Rig camera index of each checkpoint camera, in the checkpoint's order.
    pub fn cameras(&self) -> &[usize] {
        &self.inputs.cams
    }

    /// How far the observation instant trails a tick's clock (ns): `obs_lag_s`, or 1.5 periods
    /// of the slowest joint or gripper stream when that is longer.
    pub fn obs_lag_ns(&self) -> u64 {
        self.obs_lag_ns
    }

    /// When the newest camera frame was received (receive clock), if any.
    pub fn newest_frame_ns(&self) -> Option<u64> {
        self.inputs.newest_frame_ns()
    }

    /// Expected inference latency in ticks: the next chunk is asked for this many ticks before
    /// the current one runs out (clamped below `action_steps`).
    pub fn set_lead_ticks(&mut self, ticks: u64) {
        self.lead_ticks = ticks.min(self.opts.action_steps as u64 - 1);
    }

    /// Forgets everything (a new episode): buffers, window, plan, the last commands.
    pub fn reset(&mut self) {
        self.inputs.clear();
        self.origin_ns = None;
        self.index = 0;
        self.prev_pose.iter_mut().for_each(|p| *p = None);
        self.last_command.iter_mut().for_each(|p| *p = None);
        self.stop("reset");
        self.frozen = None;
        self.halted = None;
    }

    /// A camera message (CDR `sensor_msgs/msg/Image` or `CompressedImage`) of rig camera
    /// `camera`, captured at `stamp_ns`, received at `recv_ns`. Cameras the checkpoint does not
    /// read are ignored.
    pub fn on_image(
        &mut self,
        camera: usize,
        stamp_ns: u64,
        recv_ns: u64,
        message_type: &str,
        cdr: Vec<u8>,
    ) {
        self.inputs
            .on_image(camera, stamp_ns, recv_ns, message_type, cdr);
    }

    /// Joint positions of arm `arm` (rig joint order).
    pub fn on_arm_joints(&mut self, arm: usize, stamp_ns: u64, recv_ns: u64, q: Vec<f64>) {
        self.inputs.on_arm_joints(arm, stamp_ns, recv_ns, q);
    }

    /// Finger joint positions of arm `arm`'s gripper (its joint order).
    pub fn on_gripper_joints(&mut self, arm: usize, stamp_ns: u64, recv_ns: u64, q: Vec<f64>) {
        self.inputs.on_gripper_joints(arm, stamp_ns, recv_ns, q);
    }

    /// An arm's (`gripper` false) or gripper's `JointState`, joints mapped by name as the
    /// converter maps them; a message lacking one of them is ignored.
    pub fn on_joint_state(&mut self, arm: usize, gripper: bool, recv_ns: u64, js: &JointState) {
        self.inputs
            .on_joint_state(&self.rig, arm, gripper, recv_ns, js);
    }

    fn stop(&mut self, why: &str) {
        self.history.clear();
        self.plan.clear();
        self.pending = None;
        self.next_request = 0;
        self.halted = Some(why.to_string());
    }

    /// The next control tick, at `now_ns` on the receive clock; the observation instant is
    /// [`Controller::obs_lag_ns`] earlier. Ticks are counted: call once per control period.
    pub fn tick(&mut self, now_ns: u64) -> Tick {
        let index = self.index;
        self.index += 1;
        self.origin_ns.get_or_insert(now_ns);
        let obs_ns = now_ns.saturating_sub(self.obs_lag_ns);
        let mut tick = Tick {
            index,
            obs_ns,
            halted: None,
            request: None,
        };
        match self.observe(now_ns, obs_ns) {
            Ok(()) => self.halted = None,
            Err(why) => {
                self.stop(&why);
                tick.halted = Some(why);
                return tick;
            }
        }
        self.plan.retain(|&k, _| k >= index);
        let to = self.cfg.model.obs_horizon;
        if self.pending.is_none() && index >= self.next_request && self.history.len() == to {
            let mut observation = Observation::default();
            for (img, state) in &self.history {
                observation.images.extend_from_slice(img);
                observation.state.extend_from_slice(state);
            }
            self.pending = Some(index);
            tick.request = Some(Request { index, observation });
        }
        tick
    }

    /// Builds this tick's frames and state and pushes them onto the window.
    fn observe(&mut self, now_ns: u64, obs_ns: u64) -> std::result::Result<(), String> {
        let opts = self.opts.clone();
        if let Some(why) = self.inputs.silence(now_ns, &opts) {
            return Err(why);
        }
        // The checkpoint's image chain: the camera frame as the converter stored it (its
        // size, Lanczos3, JPEG quality), decoded and resized to the model's input as the
        // loader did in training.
        let m = &self.cfg.model;
        let (w, h) = (m.image_width, m.image_height);
        let (sw, sh) = self.chain.stored_size();
        let spec = EncodeSpec {
            width: sw,
            height: sh,
            quality: self.chain.jpeg_quality(),
            raw: false,
        };
        let per = 3 * w as usize * h as usize;
        let mut images = vec![0u8; per * self.inputs.frames.len()];
        for (k, (series, msgs)) in self.inputs.frames.iter_mut().enumerate() {
            let stamps = series.stamps.make_contiguous();
            let picked = live::frame_at(stamps, series.period_s, obs_ns, opts.frame_stale_periods);
            let i = match picked {
                Some((i, true)) => i,
                _ => {
                    return Err(format!(
                        "{}: no frame within {} periods of the tick",
                        series.name, opts.frame_stale_periods
                    ))
                }
            };
            let (ty, data) = &msgs[i];
            let jpeg = live::encode_frame(ty, Serialization::Cdr, data, &spec)
                .map_err(|e| format!("{}: {e}", series.name))?;
            scaledp_datasets::decode_image(&jpeg, w, h, &mut images[k * per..(k + 1) * per])
                .map_err(|e| format!("{}: {}", series.name, String::from(e)))?;
        }
        let space = self.cfg.action_space;
        let mut state = Vec::with_capacity(space.dim(&self.rig));
        let tick_s = self.period_ns * 1e-9;
        for a in 0..self.inputs.arms.len() {
            let q = self.inputs.arms[a].at(obs_ns, tick_s).ok_or_else(|| {
                format!("{}: no samples around the tick", self.inputs.arms[a].name)
            })?;
            let base_from_tcp = self.kin[a]
                .base_from_tcp(&q)
                .map_err(|e| format!("{}: {e}", self.inputs.arms[a].name))?;
            self.measured[a] = base_from_tcp;
            self.measured_q[a].clone_from(&q);
            let mut pose = scaledp_schema::kinematics::pose6_from_transform(base_from_tcp);
            if let Some(prev) = self.prev_pose[a] {
                for d in 3..6 {
                    let mut pair = [prev[d], pose[d]];
                    live::unwrap_angles(&mut pair);
                    pose[d] = pair[1];
                }
            }
            self.prev_pose[a] = Some(pose);
            let width = match (&mut self.inputs.fingers[a], &self.grippers[a]) {
                (Some(s), Some(g)) => {
                    let f = s
                        .at(obs_ns, tick_s)
                        .ok_or_else(|| format!("{}: no samples around the tick", s.name))?;
                    g.model.width_m(&f)
                }
                _ => 0.0,
            };
            match space {
                ActionSpace::Tcp => state.extend(pose.iter().map(|&v| v as f32)),
                ActionSpace::Joints => state.extend(q.iter().map(|&v| v as f32)),
            }
            state.push(width as f32);
        }
        // The frozen-cameras control: every window shows the episode's first frames.
        let images = if self.opts.freeze_cameras {
            self.frozen.get_or_insert(images).clone()
        } else {
            images
        };
        self.history.push_back((images, state));
        while self.history.len() > self.cfg.model.obs_horizon {
            self.history.pop_front();
        }
        Ok(())
    }

    /// A chunk computed for the window of tick `index`: its first `action_steps` actions
    /// become the plan of ticks `index …`. A chunk nobody asked for (after a stop) is dropped.
    pub fn install(&mut self, index: u64, chunk: &ActionChunk) {
        if self.pending != Some(index) {
            return;
        }
        self.pending = None;
        let steps = self.opts.action_steps.min(chunk.chunk);
        for k in 0..steps {
            self.plan.insert(index + k as u64, chunk.step(k).to_vec());
        }
        self.next_request = index + (steps as u64).saturating_sub(self.lead_ticks).max(1);
    }

    /// The commands for the current tick (the one [`Controller::tick`] last returned), or why
    /// there are none.
    pub fn command(&mut self) -> std::result::Result<Vec<Command>, String> {
        if let Some(why) = &self.halted {
            return Err(why.clone());
        }
        let index = self.index.saturating_sub(1);
        let Some(action) = self.plan.get(&index).cloned() else {
            return Err(if self.history.len() < self.cfg.model.obs_horizon {
                "filling the observation window".into()
            } else {
                "waiting for the policy".into()
            });
        };
        if let Some(k) = action.iter().position(|v| !v.is_finite()) {
            self.stop("non-finite action");
            return Err(format!("the policy's action value {k} is {}", action[k]));
        }
        let space = self.cfg.action_space;
        let mut out = Vec::with_capacity(self.inputs.arms.len());
        for a in 0..self.inputs.arms.len() {
            let v: Vec<f64> = action[space.arm_range(&self.rig, a)]
                .iter()
                .map(|&x| f64::from(x))
                .collect();
            let (tcp, joints) = match &self.last_command[a] {
                Some((t, q)) => (*t, q.as_slice()),
                None => (self.measured[a], self.measured_q[a].as_slice()),
            };
            let previous = Previous { tcp, joints };
            let mut clamped = Clamped::default();
            let (arm, ws) = (&self.rig.arms[a], &self.limits.workspace[a]);
            let target = arm_target(
                arm,
                &self.kin[a],
                space,
                &v[..v.len() - 1],
                &previous,
                ws,
                &self.limits,
                &mut clamped,
            );
            let grip = v[v.len() - 1];
            let gripper_width_m = self.grippers[a].as_ref().map(|g| {
                let max = g.model.max_width_m();
                clamped.gripper |= !(0.0..=max).contains(&grip);
                grip.clamp(0.0, max)
            });
            // The joints this command leaves the arm at: its own, or (a TCP command) where
            // the last ones were, for the next command's inverse kinematics to start from.
            let q = target.joints.clone().unwrap_or_else(|| joints.to_vec());
            self.last_command[a] = Some((target.base_from_tcp, q));
            out.push(Command {
                arm: a,
                base_from_tcp: target.base_from_tcp,
                joints: target.joints,
                gripper_width_m,
                clamped,
            });
        }
        Ok(out)
    }
}
