//! Hooks for reference implementations (the PyTorch module of the `scaledp_data` wheel): the
//! random draws of a training step, the loss and gradients the trainer computes from them, and
//! the noise a prediction starts from — so another implementation can be fed the same numbers
//! and held to the same results.
//!
//! [`step_draws`] replays the step's generator in the order the trainer consumes it (per
//! micro-batch: each camera's crop windows, then the timesteps, then the noise); a change of
//! that order shows up as a loss mismatch in the parity tests (`tests/tests/torch_parity.rs`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_datasets::Batch;

use crate::config::ModelConfig;
use crate::error::{Error, Result};
use crate::model::params::randn;
use crate::model::ScaleDp;
use crate::scheduler::NoiseScheduler;
use crate::trainer::{loss_and_grads, step_rng, LossSpec, Phases};

/// The random numbers of one training step of `b` samples.
#[derive(Clone, Debug, PartialEq)]
pub struct StepDraws {
    /// (top, left) of each image's crop window, `[cams, b, To]` row-major.
    pub crops: Vec<[usize; 2]>,
    /// The timesteps, `[b, K]`.
    pub timesteps: Vec<usize>,
    /// The noise, `[b, K, C, A]`.
    pub noise: Vec<f32>,
}

/// The draws step `step` of a run seeded `seed` makes for a batch of `b` samples of model `cfg`
/// (with `train_steps` diffusion steps, the loss `spec` and micro-batches of at most `micro`).
pub fn step_draws(
    cfg: &ModelConfig,
    train_steps: usize,
    b: usize,
    spec: LossSpec,
    micro: Option<usize>,
    seed: u64,
    step: u64,
) -> StepDraws {
    let mut rng = step_rng(seed, step);
    let (to, cams, ch, a) = (
        cfg.obs_horizon,
        cfg.cameras.len(),
        cfg.action_chunk,
        cfg.action_dim,
    );
    let (w, h) = (cfg.image_width as usize, cfg.image_height as usize);
    let (cw, crh) = cfg.crop_size();
    let k = spec.noise_samples.max(1);
    let chunk = micro.unwrap_or(b).clamp(1, b.max(1));
    let mut d = StepDraws {
        crops: vec![[0; 2]; cams * b * to],
        timesteps: vec![0; b * k],
        noise: vec![0.0; b * k * ch * a],
    };
    for s0 in (0..b).step_by(chunk) {
        let n = chunk.min(b - s0);
        for i in 0..cams {
            for img in 0..n * to {
                let y0 = rng.random_range(0..=h - crh);
                let x0 = rng.random_range(0..=w - cw);
                d.crops[(i * b + s0) * to + img] = [y0, x0];
            }
        }
        for j in 0..n * k {
            d.timesteps[s0 * k + j] = rng.random_range(0..train_steps);
        }
        let noise = randn(&mut rng, n * k * ch * a);
        d.noise[s0 * k * ch * a..(s0 + n) * k * ch * a].copy_from_slice(&noise);
    }
    d
}

/// Gradients by weight name, in the model's order.
pub type NamedGrads = Vec<(String, Vec<f32>)>;

/// The loss and the gradient of every weight (by name, in the model's order) that training
/// step `step` of a run seeded `seed` computes on `batch` — the trainer's own function and
/// generator (on the CPU: the CPU engine).
pub fn step_loss_and_grads(
    model: &ScaleDp,
    train_steps: usize,
    batch: &Batch,
    spec: LossSpec,
    micro: Option<usize>,
    seed: u64,
    step: u64,
) -> Result<(f32, NamedGrads)> {
    let tensors = model
        .weights()
        .iter()
        .map(|(n, t)| (n.clone(), t.clone()))
        .collect();
    let (m, params) = ScaleDp::from_tensors(model.config(), tensors, "(parity)", model.device())?;
    let scheduler = NoiseScheduler::new(train_steps)?;
    let mut rng = step_rng(seed, step);
    let (loss, grads) = loss_and_grads(
        &m,
        &mut crate::engine::Engine::default(),
        &scheduler,
        &params,
        batch,
        spec,
        micro,
        &mut rng,
        &mut Phases::default(),
    )?;
    let out = params
        .iter()
        .zip(grads)
        .map(|(p, g)| {
            let g = g.ok_or_else(|| Error::Config(format!("no gradient reaches {}", p.name)))?;
            Ok((p.name.clone(), g.flatten_all()?.to_vec1::<f32>()?))
        })
        .collect::<Result<_>>()?;
    Ok((loss, out))
}

/// The Gaussian noise `[b, C, A]` that `Policy::predict_batch(observations, seed)` starts DDIM
/// from for `b` observations (centre crops draw nothing before it).
pub fn sampling_noise(cfg: &ModelConfig, b: usize, seed: u64) -> Vec<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    randn(&mut rng, b * cfg.action_chunk * cfg.action_dim)
}
