//! The training loss: ε-prediction MSE of the denoiser, with the observation encoded once and
//! `noise_samples` (timestep, noise) draws per sample, over every action step (padded steps
//! repeat the episode's last action, as diffusion_policy and LeRobot train) or only the
//! unpadded ones.

use std::time::Instant;

use candle_core::Tensor;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use scaledp_datasets::Batch;

use crate::engine::Engine;
use crate::error::Result;
use crate::model::params::{randn, Param};
use crate::model::{Crop, ScaleDp};
use crate::scheduler::NoiseScheduler;
use crate::trainer::spec::{LossSpec, Phases};

/// The batch's loss and the gradients of every parameter in `params` (`None` for one the loss
/// does not reach), summed over micro-batches of at most `micro` samples; the draws (crops,
/// timesteps, noise) come from `rng`. On the CPU the hand-written engine computes them
/// ([`crate::engine`]); elsewhere candle's autograd ([`candle_loss_and_grads`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn loss_and_grads(
    model: &ScaleDp,
    engine: &mut Engine,
    scheduler: &NoiseScheduler,
    params: &[Param],
    batch: &Batch,
    spec: LossSpec,
    micro: Option<usize>,
    rng: &mut ChaCha8Rng,
    phases: &mut Phases,
) -> Result<(f32, Vec<Option<Tensor>>)> {
    if !model.device().is_cpu() {
        return candle_loss_and_grads(model, scheduler, params, batch, spec, micro, rng, phases);
    }
    let (loss, mut g) = engine.loss_and_grads(model, scheduler, batch, spec, micro, rng, phases)?;
    let grads = params
        .iter()
        .map(|p| {
            g.take(&p.name)
                .map(|v| Tensor::from_vec(v, p.var.shape(), model.device()))
                .transpose()
        })
        .collect::<candle_core::Result<_>>()?;
    Ok((loss, grads))
}

/// [`loss_and_grads`] by candle's autograd on the candle modules (any device; the definition
/// the CPU engine is tested against).
#[allow(clippy::too_many_arguments)]
pub(crate) fn candle_loss_and_grads(
    model: &ScaleDp,
    scheduler: &NoiseScheduler,
    params: &[Param],
    batch: &Batch,
    spec: LossSpec,
    micro: Option<usize>,
    rng: &mut ChaCha8Rng,
    phases: &mut Phases,
) -> Result<(f32, Vec<Option<Tensor>>)> {
    let c = model.config();
    let (b, a) = (batch.len, c.action_dim);
    let denom = spec.denominator(batch, a);
    let step = micro.unwrap_or(b).clamp(1, b.max(1));
    let mut total = 0f32;
    let mut grads: Vec<Option<Tensor>> = vec![None; params.len()];
    for s0 in (0..b).step_by(step) {
        let n = step.min(b - s0);
        let loss = micro_loss(
            model,
            scheduler,
            batch,
            s0..s0 + n,
            spec,
            denom,
            rng,
            phases,
        )?;
        total += loss.to_scalar::<f32>()?;
        let t0 = Instant::now();
        let mut g = loss.backward()?;
        for (acc, p) in grads.iter_mut().zip(params) {
            if let Some(gi) = g.remove(p.var.as_tensor()) {
                *acc = Some(match acc.take() {
                    None => gi,
                    Some(prev) => (prev + gi)?,
                });
            }
        }
        phases.backward_s += t0.elapsed().as_secs_f64();
    }
    Ok((total, grads))
}

/// The summed squared error of the samples in `range` (each with `spec.noise_samples` draws),
/// divided by `denom`.
#[allow(clippy::too_many_arguments)]
fn micro_loss(
    model: &ScaleDp,
    scheduler: &NoiseScheduler,
    batch: &Batch,
    range: std::ops::Range<usize>,
    spec: LossSpec,
    denom: f64,
    rng: &mut ChaCha8Rng,
    phases: &mut Phases,
) -> Result<Tensor> {
    let c = model.config();
    let (to, ch, a, s) = (c.obs_horizon, c.action_chunk, c.action_dim, c.state_dim);
    let per_img = to * c.cameras.len() * 3 * c.image_width as usize * c.image_height as usize;
    let (s0, n) = (range.start, range.len());
    let k = spec.noise_samples.max(1);
    let dev = model.device();
    let t0 = Instant::now();
    let images = &batch.images[s0 * per_img..(s0 + n) * per_img];
    let state = &batch.state[s0 * to * s..(s0 + n) * to * s];
    let mut cond = model.encode(images, state, n, Crop::Random, rng)?;
    let t1 = Instant::now();
    let x0 = Tensor::from_slice(
        &batch.action[s0 * ch * a..(s0 + n) * ch * a],
        (n, ch, a),
        dev,
    )?;
    let mut x0 = x0;
    if k > 1 {
        // Sample i's rows i·k … i·k + k − 1 share its encoding (the gradient of the broadcast
        // sums the k draws' contributions).
        let d = cond.dim(1)?;
        cond = cond
            .unsqueeze(1)?
            .broadcast_as((n, k, d))?
            .reshape((n * k, d))?;
        x0 = x0
            .unsqueeze(1)?
            .broadcast_as((n, k, ch, a))?
            .reshape((n * k, ch, a))?;
    }
    let m = n * k;
    let t: Vec<usize> = (0..m)
        .map(|_| rng.random_range(0..scheduler.train_steps()))
        .collect();
    let noise = Tensor::from_vec(randn(rng, m * ch * a), (m, ch, a), dev)?;
    let noisy = scheduler.add_noise(&x0, &noise, &t)?;
    let tf: Vec<f32> = t.iter().map(|&v| v as f32).collect();
    let eps = model.predict_noise_train(&noisy, &tf, &cond, rng)?;
    let mut se = (eps - noise)?.sqr()?;
    if spec.mask_padding {
        let mask: Vec<f32> = batch.action_is_pad[s0 * ch..(s0 + n) * ch]
            .chunks(ch)
            .flat_map(|row| std::iter::repeat_n(row, k).flatten())
            .map(|&p| if p { 0.0 } else { 1.0 })
            .collect();
        se = se.broadcast_mul(&Tensor::from_vec(mask, (m, ch, 1), dev)?)?;
    }
    let loss = (se.sum_all()? / denom)?;
    phases.encode_s += (t1 - t0).as_secs_f64();
    phases.denoise_s += t1.elapsed().as_secs_f64();
    Ok(loss)
}
