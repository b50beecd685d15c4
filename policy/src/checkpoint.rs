//! A checkpoint is a directory a PyTorch user can open:
//!
//! - `model.safetensors`: the EMA weights under the reference module's state-dict names (what
//!   evaluation and deployment use);
//! - `train_state.safetensors`: the raw weights (`params.<name>`), AdamW's moments
//!   (`optim.<name>.exp_avg`, `optim.<name>.exp_avg_sq`) — everything `--resume` needs besides
//!   the config;
//! - `config.json`: [`CheckpointConfig`] — model, schedule, inputs, normalizer, loader position,
//!   step, seed and training settings.
//!
//! A directory is written under a temporary name and renamed when complete, so a crash never
//! leaves a half-written checkpoint under its final name.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::config::{DiffusionConfig, ModelConfig};
use crate::error::{Error, Result};

/// `format` of a policy checkpoint's `config.json`.
pub const FORMAT: &str = "scaledp-policy";
/// `version` this crate writes and reads.
pub const VERSION: u32 = 1;
/// The EMA weights.
pub const MODEL_FILE: &str = "model.safetensors";
/// Raw weights and optimizer state.
pub const TRAIN_STATE_FILE: &str = "train_state.safetensors";
/// The configuration.
pub const CONFIG_FILE: &str = "config.json";

/// One feature's normalization, `normalized = raw · scale + offset` per dimension (what the
/// loader applied in training, so deployment applies the same numbers).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalization {
    /// `min_max`, `mean_std` or `none` (informative).
    pub norm: String,
    /// Per-dimension scale.
    pub scale: Vec<f64>,
    /// Per-dimension offset.
    pub offset: Vec<f64>,
}

impl Normalization {
    /// From the loader's transform.
    pub fn from_affine(a: &scaledp_datasets::Affine) -> Self {
        let norm = match a.norm {
            scaledp_datasets::Norm::MinMax => "min_max",
            scaledp_datasets::Norm::MeanStd => "mean_std",
            scaledp_datasets::Norm::None => "none",
        };
        Normalization {
            norm: norm.into(),
            scale: a.scale().to_vec(),
            offset: a.offset().to_vec(),
        }
    }

    /// The identity of `dim` dimensions.
    pub fn identity(dim: usize) -> Self {
        Normalization {
            norm: "none".into(),
            scale: vec![1.0; dim],
            offset: vec![0.0; dim],
        }
    }

    /// Normalizes rows of `dim` values in place.
    pub fn apply(&self, x: &mut [f32]) {
        for row in x.chunks_mut(self.scale.len().max(1)) {
            for ((v, s), o) in row.iter_mut().zip(&self.scale).zip(&self.offset) {
                *v = (f64::from(*v) * s + o) as f32;
            }
        }
    }

    /// Undoes [`Normalization::apply`].
    pub fn invert(&self, x: &mut [f32]) {
        for row in x.chunks_mut(self.scale.len().max(1)) {
            for ((v, s), o) in row.iter_mut().zip(&self.scale).zip(&self.offset) {
                *v = ((f64::from(*v) - o) / s) as f32;
            }
        }
    }
}

/// The state and action normalizations.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NormalizerConfig {
    /// Of the state.
    pub state: Normalization,
    /// Of the actions.
    pub action: Normalization,
}

/// `config.json` of a checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointConfig {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`] of the writer.
    pub version: u32,
    /// The network.
    pub model: ModelConfig,
    /// The diffusion schedule.
    pub diffusion: DiffusionConfig,
    /// State and action normalization.
    pub normalizer: NormalizerConfig,
    /// Names of the state dimensions.
    pub state_names: Vec<String>,
    /// Names of the action dimensions.
    pub action_names: Vec<String>,
    /// The space of the state and action (the dataset's `scaledp.action_space`; absent in
    /// checkpoints written before joint space: TCP poses).
    #[serde(default)]
    pub action_space: scaledp_schema::ActionSpace,
    /// Control rate of the dataset (actions per second).
    pub fps: f64,
    /// `robot_type` of the dataset's `meta/info.json`, when it has one.
    pub robot_type: Option<String>,
    /// The rig named by the dataset's `scaledp` metadata, when it has one.
    pub rig: Option<String>,
    /// Where the training data came from.
    pub dataset: String,
    /// Optimizer steps taken.
    pub step: u64,
    /// The run's seed.
    pub seed: u64,
    /// The training loader's position after `step` steps.
    pub loader: Option<scaledp_datasets::LoaderState>,
    /// The training settings (free-form, for `--resume` and for the record).
    pub train: serde_json::Value,
    /// Camera frame → encoder input, as trained (absent in checkpoints written before it was
    /// recorded: see [`CheckpointConfig::image_chain`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub images: Option<crate::image_chain::ImageChain>,
}

impl CheckpointConfig {
    /// Reads and checks `dir/config.json`.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join(CONFIG_FILE);
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        let v: serde_json::Value =
            serde_json::from_slice(&bytes).map_err(|e| Error::checkpoint(path.display(), e))?;
        let format = v.get("format").and_then(|f| f.as_str()).unwrap_or("");
        let version = v.get("version").and_then(serde_json::Value::as_u64);
        if format != FORMAT {
            return Err(Error::checkpoint(
                path.display(),
                format!("format {format:?}, not a {FORMAT} checkpoint"),
            ));
        }
        if version != Some(u64::from(VERSION)) {
            return Err(Error::checkpoint(
                path.display(),
                format!("version {version:?}: this build reads version {VERSION}"),
            ));
        }
        let cfg: CheckpointConfig =
            serde_json::from_value(v).map_err(|e| Error::checkpoint(path.display(), e))?;
        cfg.model
            .validate()
            .map_err(|e| Error::checkpoint(path.display(), e))?;
        let (s, a) = (cfg.model.state_dim, cfg.model.action_dim);
        let n = &cfg.normalizer;
        if n.state.scale.len() != s
            || n.state.offset.len() != s
            || n.action.scale.len() != a
            || n.action.offset.len() != a
        {
            return Err(Error::checkpoint(
                path.display(),
                format!("normalizer sizes do not match the {s}-D state and {a}-D action"),
            ));
        }
        Ok(cfg)
    }

    /// The image chain the model was trained on (the recorded one, else the legacy
    /// assumption: stored at the model's size by the converter at JPEG quality 90).
    pub fn image_chain(&self) -> crate::image_chain::ImageChain {
        self.images
            .clone()
            .unwrap_or_else(|| crate::image_chain::ImageChain::legacy(&self.model))
    }

    /// Writes `dir/config.json`.
    pub(crate) fn write(&self, dir: &Path) -> Result<()> {
        let path = dir.join(CONFIG_FILE);
        let bytes =
            serde_json::to_vec_pretty(self).map_err(|e| Error::checkpoint(path.display(), e))?;
        std::fs::write(&path, bytes).map_err(|e| Error::io(&path, e))
    }
}

/// Reads every tensor of a safetensors file.
pub(crate) fn read_tensors(path: &Path, device: &Device) -> Result<HashMap<String, Tensor>> {
    if !path.exists() {
        return Err(Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ));
    }
    candle_core::safetensors::load(path, device).map_err(|e| Error::checkpoint(path.display(), e))
}

/// Writes tensors to a safetensors file.
pub(crate) fn write_tensors(path: &Path, tensors: Vec<(String, Tensor)>) -> Result<()> {
    let map: HashMap<String, Tensor> = tensors.into_iter().collect();
    candle_core::safetensors::save(&map, path).map_err(|e| Error::checkpoint(path.display(), e))
}

/// The checkpoint directories under `run/checkpoints/`, by step, ascending.
pub fn list(run: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let dir = run.join("checkpoints");
    let mut out = Vec::new();
    let entries = match std::fs::read_dir(&dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(Error::io(&dir, e)),
    };
    for e in entries {
        let e = e.map_err(|err| Error::io(&dir, err))?;
        let name = e.file_name().to_string_lossy().to_string();
        if let Some(step) = name
            .strip_prefix("step_")
            .and_then(|s| s.parse::<u64>().ok())
        {
            if e.path().join(CONFIG_FILE).exists() {
                out.push((step, e.path()));
            }
        }
    }
    out.sort();
    Ok(out)
}

/// A checkpoint directory from what a user names: the directory itself (it has
/// `config.json`), or a run directory (its latest checkpoint).
pub fn resolve(path: &Path) -> Result<PathBuf> {
    if path.join(CONFIG_FILE).exists() {
        return Ok(path.to_path_buf());
    }
    if !path.exists() {
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no such checkpoint or run directory",
            ),
        ));
    }
    list(path)?.pop().map(|(_, p)| p).ok_or_else(|| {
        Error::checkpoint(
            path.display(),
            format!("neither a checkpoint ({CONFIG_FILE}) nor a run with checkpoints/step_*"),
        )
    })
}

/// The directory name of the checkpoint after `step` steps.
pub(crate) fn dir_name(step: u64) -> String {
    format!("step_{step:08}")
}
