//! The ScaleDP network: one image encoder per camera and the DiT denoiser, built under PyTorch
//! state-dict names so a checkpoint loads 1:1 into the reference module
//! (`scaledp_data.policy` in the wheel, `python/`).

pub(crate) mod conv;
pub(crate) mod cpu;
pub(crate) mod denoiser;
pub(crate) mod dpt;
pub(crate) mod dropout;
pub(crate) mod encoder;
pub(crate) mod fused;
pub(crate) mod geom;
pub(crate) mod params;
pub(crate) mod resnet;
pub(crate) mod taps;
pub(crate) mod winograd;

use candle_core::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use crate::config::{Architecture, Attention, ModelConfig};
use crate::error::{Error, Result};
pub use encoder::Crop;
use encoder::{crop_images, ObsEncoder};
use params::{Builder, Param};

pub use denoiser::timestep_embedding;
use denoiser::{Denoiser, DenoiserDims};
pub use dpt::sinusoidal_pos_emb;
use dpt::{DpT, DpTDims};
use dropout::Dropout;

/// Parameter counts of a model, encoders and denoiser apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamCounts {
    /// One camera's encoder (ResNet-18-GN + SpatialSoftmax + Linear).
    pub encoder_per_camera: usize,
    /// All encoders.
    pub encoders: usize,
    /// The denoiser (what Table 1 of the paper counts).
    pub denoiser: usize,
}

impl ParamCounts {
    /// Everything.
    pub fn total(&self) -> usize {
        self.encoders + self.denoiser
    }
}

/// The denoiser of either architecture.
#[derive(Clone, Debug)]
enum Net {
    ScaleDp(Denoiser),
    DpT(DpT),
}

impl Net {
    fn new(vb: &Builder, cfg: &ModelConfig) -> Result<Self> {
        Ok(match cfg.arch {
            Architecture::ScaleDp => Net::ScaleDp(Denoiser::new(vb, dims(cfg))?),
            Architecture::DpT => Net::DpT(DpT::new(vb, dpt_dims(cfg))?),
        })
    }
}

/// The network: encoders and denoiser (ScaleDP's DiT, or DP-T for the paper's baseline; the
/// encoders, condition and everything around them are the same).
#[derive(Clone, Debug)]
pub struct ScaleDp {
    cfg: ModelConfig,
    encoders: Vec<ObsEncoder>,
    denoiser: Net,
    device: Device,
    weights: Vec<(String, Tensor)>,
}

impl ScaleDp {
    fn build(vb: &Builder, cfg: &ModelConfig, device: &Device) -> Result<Self> {
        cfg.validate()?;
        if device.is_cpu() {
            cpu::init_threads();
        }
        let encoders = (0..cfg.cameras.len())
            .map(|i| {
                ObsEncoder::new(
                    &vb.pp(cfg.camera_prefix(i)),
                    cfg.resnet_width,
                    cfg.keypoints,
                    cfg.feature_dim,
                )
            })
            .collect::<Result<_>>()?;
        let denoiser = Net::new(vb, cfg)?;
        Ok(ScaleDp {
            cfg: cfg.clone(),
            encoders,
            denoiser,
            device: device.clone(),
            weights: Vec::new(),
        })
    }

    /// A freshly initialised model (DiT's adaLN-Zero init for the denoiser, torchvision's for
    /// the trunks), the same for the same seed, and its parameters in creation order.
    pub(crate) fn fresh(
        cfg: &ModelConfig,
        seed: u64,
        device: &Device,
    ) -> Result<(Self, Vec<Param>)> {
        let vb = Builder::fresh(seed, device);
        let mut model = Self::build(&vb, cfg, device)?;
        let params = vb.finish()?.0;
        model.weights = named(&params);
        Ok((model, params))
    }

    /// A freshly initialised model: the denoiser as DiT (adaLN-Zero: it outputs exactly 0 until
    /// trained), the trunks as torchvision; the same weights for the same seed.
    pub fn new(cfg: &ModelConfig, seed: u64, device: &Device) -> Result<Self> {
        Ok(Self::fresh(cfg, seed, device)?.0)
    }

    /// A model whose every weight is drawn from N(0, std²) (norm weights around 1): no zero
    /// anywhere, for tests and comparisons with reference implementations.
    pub fn random(cfg: &ModelConfig, seed: u64, std: f64, device: &Device) -> Result<Self> {
        let shapes = Self::fresh(cfg, seed, device)?.1;
        let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(seed ^ 0x5eed);
        let tensors = shapes
            .iter()
            .map(|p| {
                let t = p.var.as_tensor();
                let mut v = params::randn(&mut rng, t.elem_count());
                let norm = [".bn", "downsample.1", ".norm", "ln_f."]
                    .iter()
                    .any(|n| p.name.contains(n));
                for x in &mut v {
                    *x *= std as f32;
                    if norm && p.name.ends_with("weight") {
                        *x += 1.0;
                    }
                }
                Ok((p.name.clone(), Tensor::from_vec(v, t.dims(), device)?))
            })
            .collect::<Result<_>>()?;
        Ok(Self::from_tensors(cfg, tensors, "(random)", device)?.0)
    }

    /// Loads weights saved by [`ScaleDp::save`] (or a checkpoint's `model.safetensors`).
    pub fn load(cfg: &ModelConfig, path: &std::path::Path, device: &Device) -> Result<Self> {
        let tensors = crate::checkpoint::read_tensors(path, device)?;
        Ok(Self::from_tensors(cfg, tensors, &path.display().to_string(), device)?.0)
    }

    /// Writes the weights as safetensors under their PyTorch names.
    pub fn save(&self, path: &std::path::Path) -> Result<()> {
        crate::checkpoint::write_tensors(path, self.weights.clone())
    }

    /// The weights by PyTorch name, in creation order.
    pub fn weights(&self) -> &[(String, Tensor)] {
        &self.weights
    }

    /// The model with the given weights (every tensor of `cfg` present, no other).
    pub(crate) fn from_tensors(
        cfg: &ModelConfig,
        tensors: std::collections::HashMap<String, Tensor>,
        file: &str,
        device: &Device,
    ) -> Result<(Self, Vec<Param>)> {
        let vb = Builder::load(tensors, file, device);
        let mut model = Self::build(&vb, cfg, device)?;
        let params = vb.finish()?.0;
        model.weights = named(&params);
        Ok((model, params))
    }

    /// Parameter counts of `cfg`, computed from the shapes the builder hands out (nothing is
    /// allocated, so the 1 B-parameter size costs nothing).
    pub fn count(cfg: &ModelConfig) -> Result<ParamCounts> {
        cfg.validate()?;
        let vb = Builder::shapes();
        Net::new(&vb, cfg)?;
        let denoiser = vb.finish()?.1;
        let encoder_per_camera = if cfg.cameras.is_empty() {
            0
        } else {
            let vb = Builder::shapes();
            ObsEncoder::new(&vb, cfg.resnet_width, cfg.keypoints, cfg.feature_dim)?;
            vb.finish()?.1
        };
        Ok(ParamCounts {
            encoder_per_camera,
            encoders: encoder_per_camera * cfg.cameras.len(),
            denoiser,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ModelConfig {
        &self.cfg
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The condition vectors `[B, cond_dim]` of `b` samples: `images` uint8
    /// `[B, To, cams, 3, H, W]` (cropped as `crop` says, drawing from `rng`), `state`
    /// normalized `[B, To, S]`. Per observation step: each camera's features, then the state;
    /// flattened over To.
    pub fn encode(
        &self,
        images: &[u8],
        state: &[f32],
        b: usize,
        crop: Crop,
        rng: &mut ChaCha8Rng,
    ) -> Result<Tensor> {
        let c = &self.cfg;
        let (to, cams, s) = (c.obs_horizon, c.cameras.len(), c.state_dim);
        let (w, h) = (c.image_width as usize, c.image_height as usize);
        if images.len() != b * to * cams * 3 * w * h || state.len() != b * to * s {
            return Err(Error::Observation(format!(
                "{} image bytes and {} state values for {b} samples of {to} frames, {cams} cameras of {w}×{h} and {s} state values",
                images.len(),
                state.len()
            )));
        }
        let mut parts = Vec::with_capacity(cams + 1);
        for (i, enc) in self.encoders.iter().enumerate() {
            let x = crop_images(
                images,
                c.image_range,
                |n| n * cams + i,
                b * to,
                (w, h),
                c.crop_size(),
                crop,
                self.device.is_cpu(),
                rng,
                &self.device,
            )?;
            parts.push(enc.forward(&x)?);
        }
        parts.push(Tensor::from_slice(state, (b * to, s), &self.device)?);
        let feats = Tensor::cat(&parts, 1)?;
        Ok(feats.reshape((b, c.cond_dim()))?)
    }

    /// ε̂ for noisy actions `x` `[B, C, A]` at timesteps `t` (one per sample) under `cond`.
    pub fn predict_noise(&self, x: &Tensor, t: &[f32], cond: &Tensor) -> Result<Tensor> {
        let c = self.condition(t, cond)?;
        self.denoise(x, &c)
    }

    /// [`ScaleDp::predict_noise`] in training: with the model's dropout (DP-T), its masks
    /// drawn from `rng` in the order the CPU engine draws them.
    pub(crate) fn predict_noise_train(
        &self,
        x: &Tensor,
        t: &[f32],
        cond: &Tensor,
        rng: &mut ChaCha8Rng,
    ) -> Result<Tensor> {
        let c = self.condition(t, cond)?;
        match &self.denoiser {
            Net::ScaleDp(d) => d.forward(x, &c),
            Net::DpT(d) => d.forward(x, &c, &mut Dropout::new(rng, self.cfg.dropout)),
        }
    }

    /// What the denoiser computes once per DDIM step from the timesteps and the condition:
    /// ScaleDP's adaLN condition `t_emb + cond_emb` `[B, d]`, DP-T's memory `[B, 1 + To, d]`.
    pub(crate) fn condition(&self, t: &[f32], cond: &Tensor) -> Result<Tensor> {
        match &self.denoiser {
            Net::ScaleDp(d) => d.condition(&timestep_embedding(t, &self.device)?, cond),
            Net::DpT(d) => d.memory(t, cond),
        }
    }

    /// ε̂ under a precomputed condition (no dropout: inference).
    pub(crate) fn denoise(&self, x: &Tensor, c: &Tensor) -> Result<Tensor> {
        match &self.denoiser {
            Net::ScaleDp(d) => d.forward(x, c),
            Net::DpT(d) => d.forward(x, c, &mut None),
        }
    }
}

fn dpt_dims(cfg: &ModelConfig) -> DpTDims {
    DpTDims {
        layers: cfg.depth,
        d: cfg.hidden,
        heads: cfg.heads,
        action_dim: cfg.action_dim,
        horizon: cfg.action_chunk,
        obs_steps: cfg.obs_horizon,
        obs_dim: cfg.obs_feature_dim(),
        causal: cfg.attention == Attention::Causal,
    }
}

fn dims(cfg: &ModelConfig) -> DenoiserDims {
    DenoiserDims {
        depth: cfg.depth,
        hidden: cfg.hidden,
        heads: cfg.heads,
        mlp_ratio: cfg.mlp_ratio,
        action_dim: cfg.action_dim,
        action_chunk: cfg.action_chunk,
        cond_dim: cfg.cond_dim(),
        causal: cfg.attention == Attention::Causal,
        pos_embed: cfg.pos_embed,
    }
}

fn named(params: &[Param]) -> Vec<(String, Tensor)> {
    params
        .iter()
        .map(|p| (p.name.clone(), p.var.as_tensor().clone()))
        .collect()
}
