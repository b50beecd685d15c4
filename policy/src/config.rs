//! What a model is: its size preset, horizons, inputs (cameras, image size, crop, state and
//! action widths) and encoder shape. Stored in a checkpoint's `config.json`.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The paper's five sizes (Table 1): depth / width / heads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ModelSize {
    /// 8 layers, d 256, 4 heads: ≈ 10 M denoiser parameters.
    Ti,
    /// 12 layers, d 384, 6 heads: ≈ 33 M.
    S,
    /// 12 layers, d 768, 12 heads: ≈ 130 M.
    B,
    /// 24 layers, d 1024, 16 heads: ≈ 457 M.
    L,
    /// 32 layers, d 1280, 16 heads: ≈ 0.95 B ("1B" in Table 1).
    H,
}

impl ModelSize {
    /// Every size, smallest first.
    pub const ALL: [ModelSize; 5] = [
        ModelSize::Ti,
        ModelSize::S,
        ModelSize::B,
        ModelSize::L,
        ModelSize::H,
    ];

    /// (depth, hidden width, heads).
    pub fn dims(self) -> (usize, usize, usize) {
        match self {
            ModelSize::Ti => (8, 256, 4),
            ModelSize::S => (12, 384, 6),
            ModelSize::B => (12, 768, 12),
            ModelSize::L => (24, 1024, 16),
            ModelSize::H => (32, 1280, 16),
        }
    }

    /// The denoiser's parameter count in Table 1 (A = 14, C = 16).
    pub fn paper_params(self) -> f64 {
        match self {
            ModelSize::Ti => 10e6,
            ModelSize::S => 33e6,
            ModelSize::B => 130e6,
            ModelSize::L => 457e6,
            ModelSize::H => 1e9,
        }
    }

    /// `ti`, `s`, `b`, `l` or `h`.
    pub fn name(self) -> &'static str {
        match self {
            ModelSize::Ti => "ti",
            ModelSize::S => "s",
            ModelSize::B => "b",
            ModelSize::L => "l",
            ModelSize::H => "h",
        }
    }
}

impl std::fmt::Display for ModelSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ModelSize {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        ModelSize::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| Error::Config(format!("model size {s:?}: one of ti, s, b, l, h")))
    }
}

/// The whole model: denoiser shape, horizons, inputs and encoders.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelConfig {
    /// The preset the denoiser's shape came from (`None`: set by hand, as tests do).
    pub size: Option<ModelSize>,
    /// Transformer blocks.
    pub depth: usize,
    /// Token width d.
    pub hidden: usize,
    /// Attention heads.
    pub heads: usize,
    /// MLP width / d (4).
    pub mlp_ratio: usize,
    /// Observation frames per sample, To.
    pub obs_horizon: usize,
    /// Actions per chunk, C.
    pub action_chunk: usize,
    /// State width, S.
    pub state_dim: usize,
    /// Action width, A.
    pub action_dim: usize,
    /// Camera keys (`observation.images.front`), in the order images arrive.
    pub cameras: Vec<String>,
    /// Image width as it arrives, before the crop.
    pub image_width: u32,
    /// Image height as it arrives, before the crop.
    pub image_height: u32,
    /// Crop side / image side (0.9: 84 → 76 as diffusion_policy; 1.0: no crop).
    pub crop: f64,
    /// Channels of the trunk's first stage (64 for ResNet-18).
    pub resnet_width: usize,
    /// SpatialSoftmax keypoints (32 → 64 values).
    pub keypoints: usize,
    /// Per-camera feature width after the encoder's Linear (64).
    pub feature_dim: usize,
    /// What the encoders see of a pixel: [-1, 1] (diffusion_policy's image range normalizer,
    /// the default) or [0, 1] (checkpoints written before this field existed).
    #[serde(default = "ImageRange::legacy")]
    pub image_range: ImageRange,
    /// Which action tokens each token attends to: all of them (ScaleDP) or only earlier ones
    /// and itself (the causal ablation, DP-T style).
    #[serde(default)]
    pub attention: Attention,
    /// Where the denoiser learns the action tokens' order from: a learned `pos_embed` (ScaleDP's,
    /// N(0, 0.02) at the start) or DiT's fixed 1-D sin-cos table, never trained (ScaleDP only).
    #[serde(default)]
    pub pos_embed: PosEmbed,
    /// Which denoiser: ScaleDP's DiT (the default) or diffusion_policy's DP-T, the paper's
    /// baseline.
    #[serde(default)]
    pub arch: Architecture,
    /// Dropout while training: DP-T's `p_drop_attn` (its attention weights, residual branches
    /// and FFN; 0.3 by default); ScaleDP has none (0). Never applied at inference.
    #[serde(default)]
    pub dropout: f64,
}

/// The denoiser's architecture.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Architecture {
    /// ScaleDP: a DiT over the action tokens, adaLN-Zero conditioning on `t_emb + cond_emb`.
    #[default]
    ScaleDp,
    /// DP-T: diffusion_policy's `TransformerForDiffusion`, pre-LN decoder layers with self-
    /// attention over the action tokens and cross-attention to the diffusion step and each
    /// observation step as condition tokens.
    DpT,
}

impl Architecture {
    /// `scaledp` or `dp-t`.
    pub fn name(self) -> &'static str {
        match self {
            Architecture::ScaleDp => "scaledp",
            Architecture::DpT => "dp-t",
        }
    }
}

impl std::fmt::Display for Architecture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Architecture {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().replace(['-', '_'], "").as_str() {
            "scaledp" => Ok(Architecture::ScaleDp),
            "dpt" => Ok(Architecture::DpT),
            _ => Err(Error::Config(format!(
                "architecture {s:?}: scaledp or dp-t"
            ))),
        }
    }
}

/// DP-T's defaults (diffusion_policy's hybrid image policy): 8 layers, 4 heads, width 256,
/// attention dropout 0.3, causal masks.
pub const DPT_DIMS: (usize, usize, usize) = (8, 256, 4);
/// DP-T's `p_drop_attn`.
pub const DPT_DROPOUT: f64 = 0.3;

/// How uint8 pixels are scaled before the encoders.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageRange {
    /// `p / 255 · 2 − 1` ∈ [−1, 1]: diffusion_policy's `get_image_range_normalizer`.
    #[default]
    Symmetric,
    /// `p / 255` ∈ [0, 1].
    Unit,
}

impl ImageRange {
    /// What a checkpoint without the field used.
    fn legacy() -> Self {
        ImageRange::Unit
    }

    /// (scale, offset): the encoder input is `p · scale + offset` for a pixel value p.
    pub fn affine(self) -> (f32, f32) {
        match self {
            ImageRange::Symmetric => (2.0 / 255.0, -1.0),
            ImageRange::Unit => (1.0 / 255.0, 0.0),
        }
    }
}

/// The denoiser's attention pattern over the action chunk.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Attention {
    /// Every action token attends to every other (ScaleDP).
    #[default]
    NonCausal,
    /// Token i attends to tokens 0 … i only (the ablation the paper compares against).
    Causal,
}

impl std::str::FromStr for Attention {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().replace('-', "_").as_str() {
            "non_causal" | "noncausal" | "full" => Ok(Attention::NonCausal),
            "causal" => Ok(Attention::Causal),
            _ => Err(Error::Config(format!(
                "attention {s:?}: non-causal or causal"
            ))),
        }
    }
}

impl std::fmt::Display for Attention {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Attention::NonCausal => "non-causal",
            Attention::Causal => "causal",
        })
    }
}

/// The denoiser's positional embedding of the action tokens (`pos_embed`, `[1, C, d]` either way,
/// under the same state-dict name).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PosEmbed {
    /// Trained from N(0, 0.02), as the ScaleDP authors' code has it.
    #[default]
    Learned,
    /// DiT's `get_1d_sincos_pos_embed`: `[sin(p·ω), cos(p·ω)]` with ω_i = 10000^(−2i/d), fixed
    /// (rows of norm √(d/2), where a learned one starts near 0.02·√d).
    SinCos,
    /// Learned as [`PosEmbed::Learned`] (same optimizer group: no weight decay, the run's
    /// learning rate), but starting from the sin-cos table instead of N(0, 0.02): AdamW moves
    /// each value by about the learning rate a step, so a table that starts at 0.02 stays faint
    /// over a short run; this one starts at the scale of the tokens it is added to.
    LearnedSinCos,
}

impl std::str::FromStr for PosEmbed {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().replace(['-', '_'], "").as_str() {
            "learned" => Ok(PosEmbed::Learned),
            "sincos" => Ok(PosEmbed::SinCos),
            "learnedsincos" => Ok(PosEmbed::LearnedSinCos),
            _ => Err(Error::Config(format!(
                "pos_embed {s:?}: learned, sin-cos or learned-sin-cos"
            ))),
        }
    }
}

impl std::fmt::Display for PosEmbed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PosEmbed::Learned => "learned",
            PosEmbed::SinCos => "sin-cos",
            PosEmbed::LearnedSinCos => "learned-sin-cos",
        })
    }
}

impl ModelConfig {
    /// A preset with the paper's defaults (To 2, C 16, crop 0.9, ResNet-18 with 32 keypoints →
    /// 64 features per camera) for the given inputs.
    pub fn new(
        size: ModelSize,
        cameras: Vec<String>,
        (image_width, image_height): (u32, u32),
        state_dim: usize,
        action_dim: usize,
    ) -> Self {
        let (depth, hidden, heads) = size.dims();
        ModelConfig {
            size: Some(size),
            depth,
            hidden,
            heads,
            mlp_ratio: 4,
            obs_horizon: 2,
            action_chunk: 16,
            state_dim,
            action_dim,
            cameras,
            image_width,
            image_height,
            crop: 0.9,
            resnet_width: 64,
            keypoints: 32,
            feature_dim: 64,
            image_range: ImageRange::Symmetric,
            attention: Attention::NonCausal,
            pos_embed: PosEmbed::Learned,
            arch: Architecture::ScaleDp,
            dropout: 0.0,
        }
    }

    /// DP-T at its defaults ([`DPT_DIMS`], causal, dropout [`DPT_DROPOUT`]) on the same inputs
    /// and encoders as [`ModelConfig::new`].
    pub fn dp_t(
        cameras: Vec<String>,
        image: (u32, u32),
        state_dim: usize,
        action_dim: usize,
    ) -> Self {
        let (depth, hidden, heads) = DPT_DIMS;
        ModelConfig {
            size: None,
            depth,
            hidden,
            heads,
            attention: Attention::Causal,
            arch: Architecture::DpT,
            dropout: DPT_DROPOUT,
            ..ModelConfig::new(ModelSize::Ti, cameras, image, state_dim, action_dim)
        }
    }

    /// A name for the denoiser: `ScaleDP-ti`, `ScaleDP-custom`, `DP-T`.
    pub fn denoiser_name(&self) -> String {
        match self.arch {
            Architecture::DpT => "DP-T".into(),
            Architecture::ScaleDp => format!(
                "ScaleDP-{}",
                self.size.map_or("custom".into(), |s| s.to_string())
            ),
        }
    }

    /// The paper's bimanual setup: 3 cameras of 320×240, 14-D state and action, To 2, C 16.
    pub fn paper(size: ModelSize) -> Self {
        let cams = ["cam_high", "cam_left_wrist", "cam_right_wrist"]
            .iter()
            .map(|c| format!("observation.images.{c}"))
            .collect();
        ModelConfig::new(size, cams, (320, 240), 14, 14)
    }

    /// The cropped image size (width, height): `round(side · crop)`.
    pub fn crop_size(&self) -> (usize, usize) {
        let side = |s: u32| ((f64::from(s) * self.crop).round() as usize).clamp(1, s as usize);
        (side(self.image_width), side(self.image_height))
    }

    /// Condition width: (features · cameras + S) · To.
    pub fn cond_dim(&self) -> usize {
        self.obs_feature_dim() * self.obs_horizon
    }

    /// One observation step's features: features · cameras + S (DP-T's `cond_dim`, one
    /// condition token per observation step).
    pub fn obs_feature_dim(&self) -> usize {
        self.feature_dim * self.cameras.len() + self.state_dim
    }

    /// The weight-name prefix of camera `i`'s encoder: `obs_encoder.<short name>`, the short name
    /// being the key without `observation.images.` and with dots as underscores.
    pub fn camera_prefix(&self, i: usize) -> String {
        let key = &self.cameras[i];
        let short = key.strip_prefix("observation.images.").unwrap_or(key);
        format!("obs_encoder.{}", short.replace('.', "_"))
    }

    /// Checks the numbers fit together.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Config(m));
        if self.depth == 0 || self.hidden == 0 || self.heads == 0 || self.hidden % self.heads != 0 {
            return bad(format!(
                "hidden width {} must be a positive multiple of the {} heads (depth {})",
                self.hidden, self.heads, self.depth
            ));
        }
        if self.obs_horizon == 0 || self.action_chunk == 0 || self.action_dim == 0 {
            return bad("obs_horizon, action_chunk and the action width must be at least 1".into());
        }
        if self.pos_embed != PosEmbed::Learned {
            if self.arch == Architecture::DpT {
                return bad(format!(
                    "a {} pos_embed is a ScaleDP option; DP-T learns its own from N(0, 0.02)",
                    self.pos_embed
                ));
            }
            if self.hidden % 2 != 0 {
                return bad(format!(
                    "a sin-cos pos_embed needs an even width, not {}",
                    self.hidden
                ));
            }
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return bad(format!("dropout {} outside [0, 1)", self.dropout));
        }
        if !(self.crop > 0.0 && self.crop <= 1.0) {
            return bad(format!("crop ratio {} outside (0, 1]", self.crop));
        }
        if !self.cameras.is_empty() {
            let (cw, ch) = self.crop_size();
            if cw < 8 || ch < 8 {
                return bad(format!(
                    "images of {}×{} cropped to {cw}×{ch}: the ResNet trunk needs at least 8×8",
                    self.image_width, self.image_height
                ));
            }
            if self.resnet_width == 0 || self.keypoints == 0 || self.feature_dim == 0 {
                return bad("resnet_width, keypoints and feature_dim must be at least 1".into());
            }
        }
        let mut prefixes: Vec<String> = (0..self.cameras.len())
            .map(|i| self.camera_prefix(i))
            .collect();
        prefixes.sort();
        prefixes.dedup();
        if prefixes.len() != self.cameras.len() {
            return bad(format!("cameras {:?} share a weight prefix", self.cameras));
        }
        Ok(())
    }
}

/// The diffusion schedule a model was trained with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DiffusionConfig {
    /// DDPM training steps (100).
    pub train_steps: usize,
    /// DDIM sampling steps (10).
    pub inference_steps: usize,
}

impl Default for DiffusionConfig {
    fn default() -> Self {
        DiffusionConfig {
            train_steps: 100,
            inference_steps: 10,
        }
    }
}

#[cfg(test)]
mod tests;
