//! Validation on held-out episodes with the EMA weights: the denoising loss, and the error of
//! full DDIM samples against the recorded chunks, normalized and in raw units per dimension.

use candle_core::Tensor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scaledp_datasets::Loader;
use serde::Serialize;

use crate::checkpoint::CheckpointConfig;
use crate::error::Result;
use crate::inference::ddim_sample;
use crate::model::params::randn;
use crate::model::{Crop, ScaleDp};
use crate::scheduler::NoiseScheduler;

/// One validation's figures (a `"kind": "val"` line of `metrics.jsonl`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ValRecord {
    /// Steps done when it ran.
    pub step: u64,
    /// Samples evaluated.
    pub samples: usize,
    /// Masked ε-MSE (centre crops, fixed noise).
    pub loss: f32,
    /// Mean squared error of DDIM samples vs the recorded chunks, normalized units.
    pub action_mse: f64,
    /// Mean absolute error of the same, normalized units.
    pub action_mae: f64,
    /// Mean absolute error per action dimension in raw units (metres, radians).
    pub action_mae_raw: Vec<f64>,
    /// The dimensions' names.
    pub action_names: Vec<String>,
}

/// Validates `model` on up to `batches` batches of `val` (always the same ones: epoch 0).
pub(super) fn run(
    model: &ScaleDp,
    cfg: &CheckpointConfig,
    val: &mut Loader,
    batches: usize,
    seed: u64,
    step: u64,
) -> Result<ValRecord> {
    let m = &cfg.model;
    let (ch, a) = (m.action_chunk, m.action_dim);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(u64::MAX);
    let train = NoiseScheduler::new(cfg.diffusion.train_steps)?;
    let mut ddim = train.clone();
    ddim.set_timesteps(cfg.diffusion.inference_steps)?;
    val.set_epoch(0);
    let (mut loss_sum, mut valid_total, mut samples) = (0f64, 0usize, 0usize);
    let (mut se, mut ae) = (0f64, 0f64);
    let mut ae_raw = vec![0f64; a];
    for _ in 0..batches.max(1) {
        let Some(batch) = val.next_batch() else {
            break;
        };
        let batch = batch?;
        let b = batch.len;
        let dev = model.device();
        let cond = model.encode(&batch.images, &batch.state, b, Crop::Center, &mut rng)?;
        // Denoising loss at random timesteps.
        let t: Vec<usize> = (0..b)
            .map(|_| rng.random_range(0..train.train_steps()))
            .collect();
        let noise = Tensor::from_vec(randn(&mut rng, b * ch * a), (b, ch, a), dev)?;
        let x0 = Tensor::from_slice(&batch.action, (b, ch, a), dev)?;
        let noisy = train.add_noise(&x0, &noise, &t)?;
        let tf: Vec<f32> = t.iter().map(|&v| v as f32).collect();
        let eps = model.predict_noise(&noisy, &tf, &cond)?;
        let err = (eps - noise)?
            .sqr()?
            .sum_keepdim(2)?
            .flatten_all()?
            .to_vec1::<f32>()?;
        // Full samples against the recorded chunks.
        let pred = ddim_sample(model, &ddim, &cond, &mut rng)?
            .flatten_all()?
            .to_vec1::<f32>()?;
        let (mut pred_raw, mut rec_raw) = (pred.clone(), batch.action.clone());
        cfg.normalizer.action.invert(&mut pred_raw);
        cfg.normalizer.action.invert(&mut rec_raw);
        for (k, &pad) in batch.action_is_pad.iter().enumerate() {
            if pad {
                continue;
            }
            loss_sum += f64::from(err[k]);
            valid_total += 1;
            for (d, acc) in ae_raw.iter_mut().enumerate() {
                let i = k * a + d;
                let e = f64::from(pred[i] - batch.action[i]);
                se += e * e;
                ae += e.abs();
                *acc += f64::from(pred_raw[i] - rec_raw[i]).abs();
            }
        }
        samples += b;
        val.recycle(batch);
    }
    let n = valid_total.max(1) as f64;
    Ok(ValRecord {
        step,
        samples,
        loss: (loss_sum / (n * a as f64)) as f32,
        action_mse: se / (n * a as f64),
        action_mae: ae / (n * a as f64),
        action_mae_raw: ae_raw.iter().map(|v| v / n).collect(),
        action_names: cfg.action_names.clone(),
    })
}
