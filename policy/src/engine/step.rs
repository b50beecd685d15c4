//! A whole training step and a whole DDIM sample on the CPU engine: crops (the same draws, in
//! the same order, as the candle path), the encoders, the condition, the noise, the
//! denoiser, the loss and every gradient.

use std::time::Instant;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use scaledp_datasets::Batch;

use super::{denoiser, dpt, encoder, Grads, InOut, WeightView};
use crate::config::{Architecture, Attention, ModelConfig};
use crate::error::{Error, Result};
use crate::model::cpu::on_pool;
use crate::model::dropout::Dropout;
use crate::model::encoder::crop_values;
use crate::model::params::randn;
use crate::model::{Crop, ScaleDp};
use crate::scheduler::NoiseScheduler;
use crate::trainer::{LossSpec, Phases};

/// The engine's buffers for one model, kept between calls.
#[derive(Default)]
pub(crate) struct Engine {
    encoders: Vec<encoder::Work>,
    denoiser: denoiser::Work,
    dpt: dpt::Work,
    /// The last condition `[b, cond_dim]` (its rows' camera features then state, per frame).
    cond: Vec<f32>,
    /// `[in, out]` copies of the Linear weights of the model [`Engine::sample`] last sampled.
    in_out: std::sync::Arc<InOut>,
    /// How long the last [`Engine::sample`] spent in the encoders (s).
    encode_s: f64,
}

impl std::fmt::Debug for Engine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Engine")
    }
}

/// Sampling, for inference (the engine behind a lock, as `Policy::predict` takes `&self`).
pub(crate) type Sampler = std::sync::Mutex<Engine>;

fn shape(c: &ModelConfig) -> denoiser::Shape {
    denoiser::Shape {
        depth: c.depth,
        d: c.hidden,
        heads: c.heads,
        mlp: c.mlp_ratio,
        action: c.action_dim,
        tokens: c.action_chunk,
        cond: c.cond_dim(),
        causal: c.attention == Attention::Causal,
    }
}

fn dpt_shape(c: &ModelConfig) -> dpt::Shape {
    dpt::Shape {
        layers: c.depth,
        d: c.hidden,
        heads: c.heads,
        action: c.action_dim,
        tokens: c.action_chunk,
        obs_steps: c.obs_horizon,
        obs_dim: c.obs_feature_dim(),
        causal: c.attention == Attention::Causal,
    }
}

impl Engine {
    /// How long the last [`Engine::sample`] spent in the encoders (s).
    pub fn last_encode_s(&self) -> f64 {
        self.encode_s
    }

    /// The condition of `b` samples (`images` `[b, To, cams, 3, H, W]`, `state` normalized
    /// `[b, To, S]`), crops drawn from `rng` as [`ScaleDp::encode`] draws them; the encoders'
    /// activations are kept for [`Engine::encode_backward`].
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &mut self,
        model: &ScaleDp,
        wv: &WeightView,
        images: &[u8],
        state: &[f32],
        b: usize,
        crop: Crop,
        rng: &mut ChaCha8Rng,
    ) -> Result<()> {
        let c = model.config();
        let (to, cams, s) = (c.obs_horizon, c.cameras.len(), c.state_dim);
        let (w, h) = (c.image_width as usize, c.image_height as usize);
        if images.len() != b * to * cams * 3 * w * h || state.len() != b * to * s {
            return Err(Error::Observation(format!(
                "{} image bytes and {} state values for {b} samples of {to} frames, {cams} cameras of {w}×{h} and {s} state values",
                images.len(),
                state.len()
            )));
        }
        let (cw, ch) = c.crop_size();
        self.encoders.resize_with(cams, encoder::Work::default);
        for (i, enc) in self.encoders.iter_mut().enumerate() {
            let x = crop_values(
                images,
                c.image_range,
                |n| n * cams + i,
                b * to,
                (w, h),
                (cw, ch),
                crop,
                true,
                rng,
            );
            enc.forward(wv, &c.camera_prefix(i), x, (b * to, ch, cw))?;
        }
        let f = c.feature_dim;
        let row = f * cams + s;
        self.cond.resize(b * to * row, 0.0);
        for (r, dst) in self.cond.chunks_exact_mut(row).enumerate() {
            for (i, enc) in self.encoders.iter().enumerate() {
                dst[i * f..(i + 1) * f].copy_from_slice(&enc.out[r * f..(r + 1) * f]);
            }
            dst[cams * f..].copy_from_slice(&state[r * s..(r + 1) * s]);
        }
        Ok(())
    }

    /// The encoders' backward from ∂loss/∂cond.
    fn encode_backward(
        &mut self,
        model: &ScaleDp,
        wv: &WeightView,
        dcond: &[f32],
        grads: &mut Grads,
    ) -> Result<()> {
        let c = model.config();
        let (cams, s, f) = (c.cameras.len(), c.state_dim, c.feature_dim);
        let row = f * cams + s;
        let rows = dcond.len() / row.max(1);
        for (i, enc) in self.encoders.iter_mut().enumerate() {
            let mut dfeat = vec![0f32; rows * f];
            for (r, d) in dfeat.chunks_exact_mut(f).enumerate() {
                d.copy_from_slice(&dcond[r * row + i * f..r * row + (i + 1) * f]);
            }
            enc.backward(wv, grads, &dfeat)?;
        }
        Ok(())
    }

    /// The batch's loss and every parameter's gradient, as [`crate::trainer::loss_and_grads`]
    /// computes them with candle (same draws, same order, same micro-batches).
    #[allow(clippy::too_many_arguments)]
    pub fn loss_and_grads(
        &mut self,
        model: &ScaleDp,
        scheduler: &NoiseScheduler,
        batch: &Batch,
        spec: LossSpec,
        micro: Option<usize>,
        rng: &mut ChaCha8Rng,
        phases: &mut Phases,
    ) -> Result<(f32, Grads)> {
        on_pool(|| {
            let c = model.config().clone();
            let (sh, ds) = (shape(&c), dpt_shape(&c));
            let (b, a, ch, to, s) = (
                batch.len,
                c.action_dim,
                c.action_chunk,
                c.obs_horizon,
                c.state_dim,
            );
            let k = spec.noise_samples.max(1);
            let denom = spec.denominator(batch, a);
            let per_img =
                to * c.cameras.len() * 3 * c.image_width as usize * c.image_height as usize;
            let step = micro.unwrap_or(b).clamp(1, b.max(1));
            let weights = model.weights();
            let wv = WeightView::new(weights);
            let mut grads = Grads::default();
            let mut total = 0f64;
            for s0 in (0..b).step_by(step) {
                let n = step.min(b - s0);
                let t0 = Instant::now();
                let images = &batch.images[s0 * per_img..(s0 + n) * per_img];
                let state = &batch.state[s0 * to * s..(s0 + n) * to * s];
                self.encode(model, &wv, images, state, n, Crop::Random, rng)?;
                let t1 = Instant::now();
                let m = n * k;
                let t: Vec<usize> = (0..m)
                    .map(|_| rng.random_range(0..scheduler.train_steps()))
                    .collect();
                let noise = randn(rng, m * ch * a);
                let alphas = scheduler.alphas_cumprod();
                let x0 = &batch.action[s0 * ch * a..(s0 + n) * ch * a];
                let mut noisy = vec![0f32; m * ch * a];
                for (j, (dst, nz)) in noisy
                    .chunks_exact_mut(ch * a)
                    .zip(noise.chunks_exact(ch * a))
                    .enumerate()
                {
                    let al = alphas[t[j]];
                    let (sa, sb) = (al.sqrt(), (1.0 - al).sqrt());
                    let src = &x0[(j / k) * ch * a..(j / k + 1) * ch * a];
                    for ((o, x), e) in dst.iter_mut().zip(src).zip(nz) {
                        *o = x * sa + e * sb;
                    }
                }
                let tf: Vec<f32> = t.iter().map(|&v| v as f32).collect();
                let out = match c.arch {
                    Architecture::ScaleDp => {
                        denoiser::forward(
                            &sh,
                            &wv,
                            &noisy,
                            &tf,
                            &self.cond,
                            k,
                            &mut self.denoiser,
                        )?;
                        &self.denoiser.out
                    }
                    Architecture::DpT => {
                        // Dropout masks come after the noise, as the candle path draws them.
                        let mut drop = Dropout::new(rng, c.dropout);
                        dpt::forward(
                            &ds,
                            &wv,
                            &noisy,
                            &tf,
                            &self.cond,
                            k,
                            &mut self.dpt,
                            &mut drop,
                        )?;
                        &self.dpt.out
                    }
                };
                // loss = Σ w (ε̂ − ε)² / denom; ∂loss/∂ε̂ = 2 w (ε̂ − ε) / denom.
                let mut dout = vec![0f32; out.len()];
                let mut sum = 0f64;
                for (j, ((d, o), e)) in dout.iter_mut().zip(out).zip(&noise).enumerate() {
                    let row = j / a;
                    let (sample, tick) = (row / ch / k, row % ch);
                    if spec.mask_padding && batch.action_is_pad[(s0 + sample) * ch + tick] {
                        continue;
                    }
                    let diff = o - e;
                    sum += f64::from(diff * diff);
                    *d = (2.0 * f64::from(diff) / denom) as f32;
                }
                total += sum / denom;
                let t2 = Instant::now();
                phases.encode_s += (t1 - t0).as_secs_f64();
                phases.denoise_s += (t2 - t1).as_secs_f64();
                let dcond = match c.arch {
                    Architecture::ScaleDp => denoiser::backward::backward(
                        &sh,
                        &wv,
                        &self.cond,
                        k,
                        &dout,
                        &mut self.denoiser,
                        &mut grads,
                    )?,
                    Architecture::DpT => dpt::backward::backward(
                        &ds,
                        &wv,
                        &self.cond,
                        &dout,
                        &mut self.dpt,
                        &mut grads,
                    )?,
                };
                self.encode_backward(model, &wv, &dcond, &mut grads)?;
                phases.backward_s += t2.elapsed().as_secs_f64();
            }
            Ok((total as f32, grads))
        })
    }

    /// Normalized action chunks `[b, C, A]` by DDIM for `b` observations laid out as a batch,
    /// centre-cropped: the noise drawn from `rng` after the (draw-free) encoding, as
    /// [`crate::ddim_sample`] does. The denoiser multiplies by `[in, out]` copies of its Linear
    /// weights, made on the first call for a model and reused while the model's tensors are the
    /// same: an engine samples a model whose weights do not change in place (a loaded policy).
    pub fn sample(
        &mut self,
        model: &ScaleDp,
        scheduler: &NoiseScheduler,
        images: &[u8],
        state: &[f32],
        b: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<f32>> {
        on_pool(|| {
            let c = model.config().clone();
            let sh = shape(&c);
            let weights = model.weights();
            if !self.in_out.is_of(weights) {
                self.in_out = std::sync::Arc::new(InOut::of(weights)?);
            }
            // A handle of its own, so the view does not borrow the engine the passes write into.
            let in_out = self.in_out.clone();
            let wv = WeightView::new(weights).with_in_out(&in_out);
            let t0 = Instant::now();
            self.encode(model, &wv, images, state, b, Crop::Center, rng)?;
            self.encode_s = t0.elapsed().as_secs_f64();
            let n = c.action_chunk * c.action_dim;
            let mut x = randn(rng, b * n);
            // Everything that depends on (t, observation) and not on x — the embeddings and every
            // adaLN modulation — for all the steps at once: one product per layer over
            // `b · steps` rows instead of a matrix-vector product per layer and step.
            let ts = scheduler.timesteps();
            let steps = ts.len();
            let t_all: Vec<f32> = (0..b).flat_map(|_| ts.iter().map(|&t| t as f32)).collect();
            let rows = |j: usize| -> Vec<usize> { (0..b).map(|i| i * steps + j).collect() };
            match c.arch {
                Architecture::ScaleDp => {
                    denoiser::condition(&sh, &wv, &t_all, &self.cond, steps, &mut self.denoiser)?;
                    let all = self.denoiser.take_modulation();
                    for (j, &t) in ts.iter().enumerate() {
                        self.denoiser.set_modulation(&all, &rows(j));
                        denoiser::trunk(&sh, &wv, &x, &mut self.denoiser)?;
                        scheduler.step_values(&self.denoiser.out, t, &mut x)?;
                    }
                }
                Architecture::DpT => {
                    let ds = dpt_shape(&c);
                    dpt::condition(&ds, &wv, &t_all, &self.cond, steps, &mut self.dpt)?;
                    let all = self.dpt.take_memory();
                    for (j, &t) in ts.iter().enumerate() {
                        self.dpt.set_memory(&all, &rows(j));
                        dpt::trunk(&ds, &wv, &x, &mut self.dpt, &mut None)?;
                        scheduler.step_values(&self.dpt.out, t, &mut x)?;
                    }
                }
            }
            Ok(x)
        })
    }
}
