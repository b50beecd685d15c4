//! Acting with a trained policy: the DDIM sampling loop and [`Policy`], which loads a
//! checkpoint and turns raw observations into un-normalized action chunks.

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::checkpoint::{self, CheckpointConfig};
use crate::engine::Sampler;
use crate::error::{Error, Result};
use crate::model::params::randn;
use crate::model::{Crop, ScaleDp};
use crate::scheduler::NoiseScheduler;

/// Samples `b` normalized action chunks `[b, C, A]` under conditions `cond` (`[b, cond_dim]`):
/// Gaussian noise from `rng`, then one DDIM step per timestep of `scheduler` (whose
/// [`NoiseScheduler::set_timesteps`] chose them); the last step leaves values in [−1, 1].
pub fn ddim_sample(
    model: &ScaleDp,
    scheduler: &NoiseScheduler,
    cond: &Tensor,
    rng: &mut ChaCha8Rng,
) -> Result<Tensor> {
    let cfg = model.config();
    let b = cond.dim(0)?;
    let shape = (b, cfg.action_chunk, cfg.action_dim);
    let noise = randn(rng, b * cfg.action_chunk * cfg.action_dim);
    let mut x = Tensor::from_vec(noise, shape, model.device())?;
    for &t in scheduler.timesteps() {
        let c = model.condition(&vec![t as f32; b], cond)?;
        let eps = model.denoise(&x, &c)?;
        x = scheduler.step(&eps, t, &x)?;
    }
    Ok(x)
}

/// One observation window as a robot produces it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Observation {
    /// uint8 RGB, channel-first, `[To, cams, 3, H, W]` in the checkpoint's camera order and
    /// image size (before the crop), oldest frame first.
    pub images: Vec<u8>,
    /// `[To, S]` in raw units (metres, radians), oldest first.
    pub state: Vec<f32>,
}

/// Predicted actions, un-normalized: `[C, A]` row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct ActionChunk {
    /// `chunk · dim` values.
    pub actions: Vec<f32>,
    /// C.
    pub chunk: usize,
    /// A.
    pub dim: usize,
}

impl ActionChunk {
    /// Action `k` of the chunk.
    pub fn step(&self, k: usize) -> &[f32] {
        &self.actions[k * self.dim..(k + 1) * self.dim]
    }
}

/// A checkpoint ready to act: EMA weights, schedule and normalizer.
#[derive(Debug)]
pub struct Policy {
    model: ScaleDp,
    cfg: CheckpointConfig,
    scheduler: NoiseScheduler,
    dir: PathBuf,
    /// The CPU engine (sampling on the CPU; candle's modules elsewhere).
    sampler: Sampler,
}

impl Policy {
    /// Loads the checkpoint in `checkpoint_dir` (or the latest one of a run directory):
    /// `config.json` and the EMA weights of `model.safetensors`, onto `device`.
    pub fn load(checkpoint_dir: &Path, device: &Device) -> Result<Policy> {
        let dir = checkpoint::resolve(checkpoint_dir)?;
        let cfg = CheckpointConfig::read(&dir)?;
        let path = dir.join(checkpoint::MODEL_FILE);
        let tensors = checkpoint::read_tensors(&path, device)?;
        let (model, _) =
            ScaleDp::from_tensors(&cfg.model, tensors, &path.display().to_string(), device)?;
        Self::new(model, cfg, dir)
    }

    pub(crate) fn new(model: ScaleDp, cfg: CheckpointConfig, dir: PathBuf) -> Result<Policy> {
        let mut scheduler = NoiseScheduler::new(cfg.diffusion.train_steps)?;
        scheduler.set_timesteps(cfg.diffusion.inference_steps)?;
        Ok(Policy {
            model,
            cfg,
            scheduler,
            dir,
            sampler: Sampler::default(),
        })
    }

    /// Everything the checkpoint says about itself: cameras, image size (before the crop),
    /// `obs_horizon`, `action_chunk`, state and action names, fps, rig / robot type.
    pub fn config(&self) -> &CheckpointConfig {
        &self.cfg
    }

    /// The checkpoint directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The network (EMA weights).
    pub fn model(&self) -> &ScaleDp {
        &self.model
    }

    /// The sampling schedule.
    pub fn scheduler(&self) -> &NoiseScheduler {
        &self.scheduler
    }

    /// One action chunk for one observation; `seed` fixes the sampling noise.
    pub fn predict(&self, obs: &Observation, seed: u64) -> Result<ActionChunk> {
        let mut out = self.predict_batch(std::slice::from_ref(obs), seed)?;
        out.pop()
            .ok_or_else(|| Error::Observation("no chunk came back".into()))
    }

    /// Action chunks for several observations at once (one forward pass per DDIM step).
    pub fn predict_batch(&self, obs: &[Observation], seed: u64) -> Result<Vec<ActionChunk>> {
        let m = &self.cfg.model;
        let (to, cams, s) = (m.obs_horizon, m.cameras.len(), m.state_dim);
        let per_image = 3 * m.image_width as usize * m.image_height as usize;
        let mut images = Vec::with_capacity(obs.len() * to * cams * per_image);
        let mut state = Vec::with_capacity(obs.len() * to * s);
        for (i, o) in obs.iter().enumerate() {
            if o.images.len() != to * cams * per_image {
                return Err(Error::Observation(format!(
                    "observation {i}: {} image bytes, the checkpoint {} takes {to} frames × {cams} cameras {:?} × 3 × {}×{} = {}",
                    o.images.len(),
                    self.dir.display(),
                    m.cameras,
                    m.image_width,
                    m.image_height,
                    to * cams * per_image
                )));
            }
            if o.state.len() != to * s {
                return Err(Error::Observation(format!(
                    "observation {i}: {} state values, the checkpoint {} takes {to} frames × {s} ({:?})",
                    o.state.len(),
                    self.dir.display(),
                    self.cfg.state_names
                )));
            }
            if let Some(k) = o.state.iter().position(|v| !v.is_finite()) {
                return Err(Error::Observation(format!(
                    "observation {i}: state value {k} is {}",
                    o.state[k]
                )));
            }
            images.extend_from_slice(&o.images);
            state.extend_from_slice(&o.state);
        }
        self.cfg.normalizer.state.apply(&mut state);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x = self.sample_normalized(&images, &state, obs.len(), &mut rng)?;
        let mut actions = x.flatten_all()?.to_vec1::<f32>()?;
        self.cfg.normalizer.action.invert(&mut actions);
        let (c, a) = (m.action_chunk, m.action_dim);
        Ok(actions
            .chunks(c * a)
            .map(|v| ActionChunk {
                actions: v.to_vec(),
                chunk: c,
                dim: a,
            })
            .collect())
    }

    /// Normalized chunks `[b, C, A]` for `b` observations already laid out as a batch
    /// (`images` `[b, To, cams, 3, H, W]`, `state` normalized `[b, To, S]`), centre-cropped.
    pub fn sample_normalized(
        &self,
        images: &[u8],
        state: &[f32],
        b: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<Tensor> {
        if self.model.device().is_cpu() {
            let mut engine = self.sampler.lock().map_err(|_| {
                Error::Config("the policy's sampler was poisoned by a panic".into())
            })?;
            let x = engine.sample(&self.model, &self.scheduler, images, state, b, rng)?;
            let c = &self.cfg.model;
            return Ok(Tensor::from_vec(
                x,
                (b, c.action_chunk, c.action_dim),
                &Device::Cpu,
            )?);
        }
        let cond = self.model.encode(images, state, b, Crop::Center, rng)?;
        ddim_sample(&self.model, &self.scheduler, &cond, rng)
    }
}
