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
use scaledp_schema::Rig;
use scaledp_sim::Scene;

/// `franka_sim` made light for a 2-core machine: 80×45 cameras, a 250 Hz arm.
pub fn light_rig() -> Rig {
    let mut rig = Rig::builtin("franka_sim").unwrap();
    for c in &mut rig.cameras {
        c.width = 80;
        c.height = 45;
    }
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
            names: scaledp_converter::state_names(rig),
            centre: home_action(rig),
            spread: 100.0,
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
