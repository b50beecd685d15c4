//! The noise schedule, shaped like diffusers' schedulers: DDPM noising for training
//! ([`NoiseScheduler::add_noise`]) and DDIM steps for sampling ([`NoiseScheduler::set_timesteps`],
//! [`NoiseScheduler::step`]), with the settings diffusion_policy and ScaleDP use —
//! `squaredcos_cap_v2` betas over 100 steps, ε-prediction, η = 0, "leading" timestep spacing
//! (90, 80, …, 0 for 10 steps), `set_alpha_to_one`, predicted x₀ clipped to [−1, 1].
//!
//! Numbers follow diffusers: betas are computed in f64 and stored as f32, α = 1 − β in f32, and
//! ᾱ is their running product accumulated in f64 and rounded to f32 (`torch.cumprod` of a
//! float32 tensor on the CPU).

use candle_core::Tensor;

use crate::error::{Error, Result};

/// ᾱ(t) of the cosine schedule (Nichol & Dhariwal), s = 0.008.
fn alpha_bar(t: f64) -> f64 {
    ((t + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2)
        .cos()
        .powi(2)
}

/// Largest beta (`max_beta` of diffusers' `betas_for_alpha_bar`).
const MAX_BETA: f64 = 0.999;

/// DDPM training noise and DDIM sampling steps over one cosine schedule.
#[derive(Clone, Debug)]
pub struct NoiseScheduler {
    betas: Vec<f32>,
    alphas_cumprod: Vec<f32>,
    timesteps: Vec<usize>,
}

impl NoiseScheduler {
    /// The `squaredcos_cap_v2` schedule over `train_steps` steps; sampling timesteps are all
    /// of them, descending, until [`NoiseScheduler::set_timesteps`].
    pub fn new(train_steps: usize) -> Result<Self> {
        if train_steps == 0 {
            return Err(Error::Config(
                "the diffusion needs at least 1 training step".into(),
            ));
        }
        let n = train_steps as f64;
        let betas: Vec<f32> = (0..train_steps)
            .map(|i| {
                let b = 1.0 - alpha_bar((i + 1) as f64 / n) / alpha_bar(i as f64 / n);
                b.min(MAX_BETA) as f32
            })
            .collect();
        // torch.cumprod on the CPU accumulates float32 in double and rounds each output.
        let mut acc = 1f64;
        let alphas_cumprod = betas
            .iter()
            .map(|b| {
                acc *= f64::from(1.0 - b);
                acc as f32
            })
            .collect();
        Ok(NoiseScheduler {
            betas,
            alphas_cumprod,
            timesteps: (0..train_steps).rev().collect(),
        })
    }

    /// Training steps T.
    pub fn train_steps(&self) -> usize {
        self.betas.len()
    }

    /// β_t, t = 0 … T−1.
    pub fn betas(&self) -> &[f32] {
        &self.betas
    }

    /// ᾱ_t = ∏_{s ≤ t} (1 − β_s), t = 0 … T−1.
    pub fn alphas_cumprod(&self) -> &[f32] {
        &self.alphas_cumprod
    }

    /// Chooses `n` sampling steps with "leading" spacing: t = i · ⌊T / n⌋, i = n−1 … 0.
    pub fn set_timesteps(&mut self, n: usize) -> Result<()> {
        let t = self.train_steps();
        if n == 0 || n > t {
            return Err(Error::Config(format!(
                "{n} sampling steps: must be 1 ..= {t} (the training steps)"
            )));
        }
        let ratio = t / n;
        self.timesteps = (0..n).rev().map(|i| i * ratio).collect();
        Ok(())
    }

    /// The sampling timesteps, descending.
    pub fn timesteps(&self) -> &[usize] {
        &self.timesteps
    }

    /// `√ᾱ_t · x₀ + √(1 − ᾱ_t) · ε`, with one timestep per sample (the first axis).
    pub fn add_noise(&self, x0: &Tensor, noise: &Tensor, t: &[usize]) -> Result<Tensor> {
        let b = x0.dim(0)?;
        if t.len() != b {
            return Err(Error::Config(format!(
                "{} timesteps for {b} samples",
                t.len()
            )));
        }
        let mut shape = vec![1usize; x0.rank()];
        shape[0] = b;
        let a = self.gather(t)?;
        let sa: Vec<f32> = a.iter().map(|a| a.sqrt()).collect();
        let sb: Vec<f32> = a.iter().map(|a| (1.0 - a).sqrt()).collect();
        let sa = Tensor::from_vec(sa, shape.clone(), x0.device())?;
        let sb = Tensor::from_vec(sb, shape, x0.device())?;
        Ok((x0.broadcast_mul(&sa)? + noise.broadcast_mul(&sb)?)?)
    }

    fn gather(&self, t: &[usize]) -> Result<Vec<f32>> {
        t.iter()
            .map(|&i| {
                self.alphas_cumprod.get(i).copied().ok_or_else(|| {
                    Error::Config(format!("timestep {i} outside 0 .. {}", self.train_steps()))
                })
            })
            .collect()
    }

    /// One DDIM step (η = 0) from `sample` at timestep `t` given the predicted noise `eps`:
    /// x̂₀ = (x_t − √(1 − ᾱ_t) ε) / √ᾱ_t clipped to [−1, 1], then
    /// x_prev = √ᾱ_prev x̂₀ + √(1 − ᾱ_prev) ε, where prev = t − ⌊T / n⌋ and ᾱ_prev = 1 below 0.
    pub fn step(&self, eps: &Tensor, t: usize, sample: &Tensor) -> Result<Tensor> {
        let n = self.timesteps.len().max(1);
        let a_t = f64::from(self.gather(&[t])?[0]);
        let a_prev = match t.checked_sub(self.train_steps() / n) {
            Some(p) => f64::from(self.gather(&[p])?[0]),
            None => 1.0,
        };
        let x0 = ((sample - (eps * (1.0 - a_t).sqrt())?)? / a_t.sqrt())?.clamp(-1f32, 1f32)?;
        Ok(((x0 * a_prev.sqrt())? + (eps * (1.0 - a_prev).sqrt())?)?)
    }
}

impl NoiseScheduler {
    /// [`NoiseScheduler::step`] on plain values: `sample` (any number of values) becomes x_prev
    /// in place, `eps` the predicted noise of the same length.
    pub fn step_values(&self, eps: &[f32], t: usize, sample: &mut [f32]) -> Result<()> {
        let n = self.timesteps.len().max(1);
        let a_t = f64::from(self.gather(&[t])?[0]);
        let a_prev = match t.checked_sub(self.train_steps() / n) {
            Some(p) => f64::from(self.gather(&[p])?[0]),
            None => 1.0,
        };
        let (s1, s0) = ((1.0 - a_t).sqrt() as f32, a_t.sqrt() as f32);
        let (p1, p0) = ((1.0 - a_prev).sqrt() as f32, a_prev.sqrt() as f32);
        for (x, e) in sample.iter_mut().zip(eps) {
            let x0 = ((*x - e * s1) / s0).clamp(-1.0, 1.0);
            *x = x0 * p0 + e * p1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn ddim_steps_from_pure_noise_end_inside_the_clip_range() -> Result<()> {
        let mut s = NoiseScheduler::new(100)?;
        s.set_timesteps(10)?;
        let dev = Device::Cpu;
        let mut x = (Tensor::randn(0f32, 1., (4, 8), &dev)? * 3.0)?;
        for &t in s.timesteps() {
            let eps = Tensor::randn(0f32, 1., (4, 8), &dev)?;
            x = s.step(&eps, t, &x)?;
        }
        // The last step (t = 0, ᾱ_prev = 1) returns the clipped x̂₀ itself.
        let max = x.abs()?.max_all()?.to_scalar::<f32>()?;
        assert!(max <= 1.0, "{max}");
        assert!(s.set_timesteps(0).is_err() && s.set_timesteps(101).is_err());
        Ok(())
    }
}
