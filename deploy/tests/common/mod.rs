//! Tiny checkpoints written at test time (a 1-block, 32-wide ScaleDP on 24×24 images; the
//! untrained adaLN-Zero denoiser predicts zero noise, so DDIM's chunk is its clipped start
//! noise), the normalizer chosen so that actions land where a test wants them.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};

use candle_core::Device;
use scaledp_policy::model::ScaleDp;
use scaledp_policy::{
    CheckpointConfig, DiffusionConfig, ModelConfig, ModelSize, Normalization, NormalizerConfig,
};
use scaledp_schema::{ActionSpace, Rig};
use scaledp_sim::Scene;

/// `franka_sim` made light for a 2-core machine: 80×45 cameras, a 250 Hz arm.
pub fn light_rig() -> Rig {
    let mut rig = Rig::builtin("franka_sim").unwrap().with_image_size(80, 45);
    rig.arms[0].rate_hz = 250.0;
    rig
}

/// The rig's resting TCP poses `[x, y, z, roll, pitch, yaw, gripper]` per arm (base frame).
pub fn home_action(rig: &Rig) -> Vec<f64> {
    let scene = Scene::new(rig);
    scene
        .arms()
        .iter()
        .flat_map(|a| {
            let t = a.base_from_flange(&a.home_q) * a.flange_from_tcp;
            let mut v = scaledp_schema::kinematics::pose6_from_transform(t).to_vec();
            v.push(0.04);
            v
        })
        .collect()
}

/// What to write.
pub struct Spec {
    /// The rig named in the config (`None`: none).
    pub rig: Option<String>,
    /// Camera keys.
    pub cameras: Vec<String>,
    /// Per-arm dims × arms.
    pub dim: usize,
    /// State and action names (used when there are `dim` of them).
    pub names: Vec<String>,
    /// Actions are `centre + noise / spread` (noise in [−1, 1]).
    pub centre: Vec<f64>,
    /// See `centre`.
    pub spread: f64,
    /// The space of the state and action.
    pub space: ActionSpace,
}

impl Spec {
    /// Acting around the rig's rest pose (±1 cm) with both sim cameras.
    pub fn at_home(rig: &Rig) -> Self {
        Spec {
            rig: Some(rig.name.clone()),
            cameras: rig
                .cameras
                .iter()
                .map(|c| format!("observation.images.{}", c.name))
                .collect(),
            dim: 7 * rig.arms.len(),
            names: scaledp_converter::state_names(rig, ActionSpace::Tcp),
            centre: home_action(rig),
            spread: 100.0,
            space: ActionSpace::Tcp,
        }
    }
}

/// Writes a checkpoint directory under `root` and returns it.
pub fn write(root: &Path, spec: &Spec) -> PathBuf {
    let dir = root.join("ckpt");
    std::fs::create_dir_all(&dir).unwrap();
    let mut model = ModelConfig::new(
        ModelSize::Ti,
        spec.cameras.clone(),
        (24, 24),
        spec.dim,
        spec.dim,
    );
    model.size = None;
    model.depth = 1;
    model.hidden = 32;
    model.heads = 4;
    model.resnet_width = 8;
    model.keypoints = 8;
    model.feature_dim = 16;
    model.action_chunk = 8;
    ScaleDp::new(&model, 0, &Device::Cpu)
        .unwrap()
        .save(&dir.join("model.safetensors"))
        .unwrap();
    let names: Vec<String> = if spec.names.len() == spec.dim {
        spec.names.clone()
    } else {
        (0..spec.dim).map(|i| format!("d{i}")).collect()
    };
    // normalized = raw · scale + offset, so raw = (normalized − offset) / scale.
    let action = Normalization {
        norm: "min_max".into(),
        scale: vec![spec.spread; spec.dim],
        offset: spec.centre.iter().map(|c| -c * spec.spread).collect(),
    };
    let cfg = CheckpointConfig {
        format: "scaledp-policy".into(),
        version: 1,
        model,
        diffusion: DiffusionConfig::default(),
        normalizer: NormalizerConfig {
            state: Normalization::identity(spec.dim),
            action,
        },
        state_names: names.clone(),
        action_names: names,
        action_space: spec.space,
        fps: 10.0,
        robot_type: None,
        rig: spec.rig.clone(),
        dataset: "(test)".into(),
        step: 0,
        seed: 0,
        loader: None,
        train: serde_json::Value::Null,
        images: None,
    };
    std::fs::write(
        dir.join("config.json"),
        serde_json::to_vec_pretty(&cfg).unwrap(),
    )
    .unwrap();
    dir
}

/// Replays a recording message by message into `ctl`, ticking on the converter's grid (a
/// quarter frame period after the first frame, one control period apart) for `ticks` ticks,
/// each called once the clock is the controller's lag past it with every message stamped until
/// then in (receive = capture, as in simulated time); a chunk of zeros is installed after every
/// tick, so that every tick asks for one and shows its window. Returns (tick, window).
pub fn replay(
    ctl: &mut scaledp_deploy::Controller,
    rig: &Rig,
    rec: &scaledp_converter::Recording,
    ticks: u64,
) -> Vec<(u64, scaledp_policy::Observation)> {
    use scaledp_schema::msg::{Image, JointState};
    use scaledp_schema::RosMessage;
    let mut msgs: Vec<(u64, &scaledp_converter::RawMessage)> = rec
        .messages
        .iter()
        .filter_map(|m| {
            let stamp = if m.message_type.ends_with("Image") {
                Image::from_cdr(&m.data).ok()?.header.stamp.as_ns()
            } else if m.message_type.ends_with("JointState") {
                JointState::from_cdr(&m.data).ok()?.header.stamp.as_ns()
            } else {
                return None;
            };
            Some((stamp, m))
        })
        .collect();
    msgs.sort_by_key(|m| m.0);
    let first_frame = msgs
        .iter()
        .find(|m| m.1.message_type.ends_with("Image"))
        .unwrap()
        .0;
    let origin = first_frame + (1e9 / 30.0 / 4.0_f64).round() as u64;
    let step = (1e9 / 10.0) as u64;
    let dim = 7 * rig.arms.len();
    let mut next = 0;
    let mut windows = Vec::new();
    for k in 0..ticks {
        let t = origin + k * step;
        while next < msgs.len() && msgs[next].0 <= t + ctl.obs_lag_ns() {
            let (stamp, m) = msgs[next];
            next += 1;
            if let Some(c) = rig.cameras.iter().position(|c| c.topic == m.topic) {
                ctl.on_image(c, stamp, stamp, &m.message_type, m.data.clone());
            } else if let Some(a) = rig.arms.iter().position(|a| a.joint_state_topic == m.topic) {
                ctl.on_joint_state(a, false, stamp, &JointState::from_cdr(&m.data).unwrap());
            } else if let Some(a) = rig
                .arms
                .iter()
                .position(|a| a.gripper.as_ref().is_some_and(|g| g.topic == m.topic))
            {
                ctl.on_joint_state(a, true, stamp, &JointState::from_cdr(&m.data).unwrap());
            }
        }
        let tick = ctl.tick(t + ctl.obs_lag_ns());
        if let Some(req) = tick.request {
            windows.push((k, req.observation.clone()));
            let chunk = scaledp_policy::ActionChunk {
                actions: vec![0.0; 16 * dim],
                chunk: 16,
                dim,
            };
            ctl.install(req.index, &chunk);
        }
    }
    windows
}
