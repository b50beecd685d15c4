//! AdamW with PyTorch's arithmetic and two parameter groups by a decay mask (weight decay on
//! Linear and Conv weights only), optional clipping of the global gradient norm, and the EMA
//! of the weights. On the CPU each parameter is updated in place by one fused pass (a chain of
//! tensor ops allocates ~9 temporaries per parameter and per step: ~1 s a step for ScaleDP-Ti
//! with two encoders on two cores); other devices use tensor ops.

use std::cell::RefCell;

use candle_core::{CpuStorage, InplaceOp2, Layout, Tensor};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::model::cpu::vectorized;
use crate::model::params::Param;

/// AdamW's hyper-parameters (diffusion_policy / ScaleDP defaults).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdamWConfig {
    /// β₁ (0.9).
    pub beta1: f64,
    /// β₂ (0.95).
    pub beta2: f64,
    /// ε (1e-8).
    pub eps: f64,
    /// Decoupled weight decay on the denoiser's Linear weights (1e-3, diffusion_policy's
    /// `transformer_weight_decay`).
    pub weight_decay: f64,
    /// Decoupled weight decay on every encoder parameter (1e-6, diffusion_policy's
    /// `obs_encoder_weight_decay`, which its DP-T policy applies to the whole
    /// `obs_encoder.parameters()` group).
    #[serde(default = "legacy_encoder_decay")]
    pub encoder_weight_decay: f64,
}

/// Runs saved before the encoders had their own group decayed their Linear/Conv weights at
/// `weight_decay` and nothing else; `NaN` marks that.
fn legacy_encoder_decay() -> f64 {
    f64::NAN
}

impl Default for AdamWConfig {
    fn default() -> Self {
        AdamWConfig {
            beta1: 0.9,
            beta2: 0.95,
            eps: 1e-8,
            weight_decay: 1e-3,
            encoder_weight_decay: 1e-6,
        }
    }
}

/// The weight decay of parameter `p`: the encoders' group (every `obs_encoder.*` tensor) or
/// the denoiser's (Linear weights only).
fn decay_of(p: &Param, c: &AdamWConfig) -> f64 {
    let encoder = p.name.starts_with("obs_encoder.");
    if encoder && !c.encoder_weight_decay.is_nan() {
        c.encoder_weight_decay
    } else if p.decay {
        c.weight_decay
    } else {
        0.0
    }
}

/// First and second moments of one parameter.
enum Moments {
    /// CPU: plain buffers updated in place.
    Host { m: Vec<f32>, v: Vec<f32> },
    /// Other devices: tensors replaced each step.
    Device { m: Tensor, v: Tensor },
}

/// AdamW over a model's parameters.
pub(crate) struct AdamW {
    cfg: AdamWConfig,
    params: Vec<Param>,
    moments: Vec<Moments>,
    /// Steps taken.
    step: u64,
}

impl AdamW {
    pub fn new(params: Vec<Param>, cfg: AdamWConfig) -> Result<Self> {
        let moments = params
            .iter()
            .map(|p| -> Result<Moments> {
                let t = p.var.as_tensor();
                Ok(if t.device().is_cpu() {
                    let n = t.elem_count();
                    Moments::Host {
                        m: vec![0.0; n],
                        v: vec![0.0; n],
                    }
                } else {
                    Moments::Device {
                        m: t.zeros_like()?,
                        v: t.zeros_like()?,
                    }
                })
            })
            .collect::<Result<_>>()?;
        Ok(AdamW {
            cfg,
            params,
            moments,
            step: 0,
        })
    }

    pub fn params(&self) -> &[Param] {
        &self.params
    }

    /// The global L2 norm of the gradients (PyTorch's `clip_grad_norm_` total norm);
    /// `grads[i]` belongs to `params()[i]`.
    pub fn grad_norm(grads: &[Option<Tensor>]) -> Result<f64> {
        let mut total = 0f64;
        for g in grads.iter().flatten() {
            total += f64::from(g.sqr()?.sum_all()?.to_scalar::<f32>()?);
        }
        Ok(total.sqrt())
    }

    /// One update at learning rate `lr`, gradients (aligned with `params()`, `None` for an
    /// unused parameter) multiplied by `grad_scale` (clipping).
    pub fn step(&mut self, grads: &[Option<Tensor>], lr: f64, grad_scale: f64) -> Result<()> {
        self.step += 1;
        let c = self.cfg;
        let bc1 = 1.0 - c.beta1.powi(self.step as i32);
        let bc2 = 1.0 - c.beta2.powi(self.step as i32);
        for ((p, mom), g) in self.params.iter().zip(self.moments.iter_mut()).zip(grads) {
            let (Some(g), false) = (g, p.frozen) else {
                continue;
            };
            let wd = decay_of(p, &c);
            match mom {
                Moments::Host { m, v } => {
                    let op = FusedAdamW {
                        m: RefCell::new(m),
                        v: RefCell::new(v),
                        lr,
                        wd,
                        beta1: c.beta1,
                        beta2: c.beta2,
                        eps: c.eps,
                        bc1,
                        bc2,
                        grad_scale,
                    };
                    p.var.as_tensor().inplace_op2(&g.contiguous()?, &op)?;
                }
                Moments::Device { m, v } => {
                    let g = (g * grad_scale)?;
                    *m = ((&*m * c.beta1)? + (&g * (1.0 - c.beta1))?)?;
                    *v = ((&*v * c.beta2)? + (g.sqr()? * (1.0 - c.beta2))?)?;
                    let denom = ((v.sqrt()? / bc2.sqrt())? + c.eps)?;
                    let w = (p.var.as_tensor() * (1.0 - lr * wd))?;
                    let w = (w - ((&*m / denom)? * (lr / bc1))?)?;
                    p.var.set(&w)?;
                }
            }
        }
        Ok(())
    }

    /// The moments as tensors named `<param>.exp_avg` / `<param>.exp_avg_sq` (PyTorch's state
    /// names), for a checkpoint.
    pub fn state_tensors(&self) -> Result<Vec<(String, Tensor)>> {
        let mut out = Vec::with_capacity(2 * self.params.len());
        for (p, mom) in self.params.iter().zip(&self.moments) {
            let t = p.var.as_tensor();
            let (m, v) = match mom {
                Moments::Host { m, v } => (
                    Tensor::from_slice(m, t.dims(), t.device())?,
                    Tensor::from_slice(v, t.dims(), t.device())?,
                ),
                Moments::Device { m, v } => (m.clone(), v.clone()),
            };
            out.push((format!("{}.exp_avg", p.name), m));
            out.push((format!("{}.exp_avg_sq", p.name), v));
        }
        Ok(out)
    }

    /// Restores moments and the step count saved by [`AdamW::state_tensors`].
    pub fn load_state(
        &mut self,
        tensors: &std::collections::HashMap<String, Tensor>,
        step: u64,
        file: &str,
    ) -> Result<()> {
        for (p, mom) in self.params.iter().zip(self.moments.iter_mut()) {
            let get = |suffix: &str| -> Result<Tensor> {
                let name = format!("{}.{suffix}", p.name);
                let t = tensors
                    .get(&name)
                    .ok_or_else(|| Error::checkpoint(file, format!("no tensor {name}")))?;
                if t.dims() != p.var.as_tensor().dims() {
                    return Err(Error::checkpoint(
                        file,
                        format!(
                            "{name} has shape {:?}, the parameter {:?}",
                            t.dims(),
                            p.var.dims()
                        ),
                    ));
                }
                Ok(t.to_device(p.var.device())?)
            };
            let (m, v) = (get("exp_avg")?, get("exp_avg_sq")?);
            *mom = match mom {
                Moments::Host { .. } => Moments::Host {
                    m: m.flatten_all()?.to_vec1()?,
                    v: v.flatten_all()?.to_vec1()?,
                },
                Moments::Device { .. } => Moments::Device { m, v },
            };
        }
        self.step = step;
        Ok(())
    }
}

/// The contiguous f32 values of a storage.
fn slice<'a>(s: &'a CpuStorage, l: &Layout) -> candle_core::Result<&'a [f32]> {
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&s.as_slice::<f32>()?[a..b]),
        None => candle_core::bail!("optimizer: non-contiguous operand"),
    }
}

/// PyTorch's AdamW update of one parameter (arg 1, in place) from its gradient (arg 2):
/// `p ← p·(1 − lr·wd) − lr/bc1 · m / (√v / √bc2 + ε)`.
struct FusedAdamW<'a> {
    m: RefCell<&'a mut Vec<f32>>,
    v: RefCell<&'a mut Vec<f32>>,
    lr: f64,
    wd: f64,
    beta1: f64,
    beta2: f64,
    eps: f64,
    bc1: f64,
    bc2: f64,
    grad_scale: f64,
}

impl InplaceOp2 for FusedAdamW<'_> {
    fn name(&self) -> &'static str {
        "scaledp-adamw"
    }

    fn cpu_fwd(
        &self,
        s1: &mut CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<()> {
        let g = slice(s2, l2)?;
        let Some((a, b)) = l1.contiguous_offsets() else {
            candle_core::bail!("optimizer: non-contiguous parameter");
        };
        let CpuStorage::F32(p) = s1 else {
            candle_core::bail!("optimizer: parameters must be f32");
        };
        let p = &mut p[a..b];
        let (mut m, mut v) = (self.m.borrow_mut(), self.v.borrow_mut());
        if g.len() != p.len() || m.len() != p.len() || v.len() != p.len() {
            candle_core::bail!("optimizer: gradient of {} values for {}", g.len(), p.len());
        }
        let (b1, b2) = (self.beta1 as f32, self.beta2 as f32);
        let decay = (1.0 - self.lr * self.wd) as f32;
        let step = (self.lr / self.bc1) as f32;
        let inv_sqrt_bc2 = (1.0 / self.bc2.sqrt()) as f32;
        let (eps, gs) = (self.eps as f32, self.grad_scale as f32);
        const CHUNK: usize = 1 << 14;
        p.par_chunks_mut(CHUNK)
            .zip(m.par_chunks_mut(CHUNK))
            .zip(v.par_chunks_mut(CHUNK))
            .zip(g.par_chunks(CHUNK))
            .for_each(|(((p, m), v), g)| {
                let n = p.len();
                let (m, v, g) = (&mut m[..n], &mut v[..n], &g[..n]);
                vectorized(|| {
                    for i in 0..n {
                        let gi = g[i] * gs;
                        m[i] = b1 * m[i] + (1.0 - b1) * gi;
                        v[i] = b2 * v[i] + (1.0 - b2) * gi * gi;
                        let denom = v[i].sqrt() * inv_sqrt_bc2 + eps;
                        p[i] = p[i] * decay - step * m[i] / denom;
                    }
                });
            });
        Ok(())
    }
}

/// diffusion_policy's `EMAModel`: `decay = 1 − (1 + k / inv_gamma)^−power` clamped to
/// [min, max], with k = max(0, step − update_after − 1) and decay 0 while k = 0 (so the first
/// two updates copy the weights).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EmaConfig {
    /// 1.0.
    pub inv_gamma: f64,
    /// 0.75.
    pub power: f64,
    /// 0.0.
    pub min_value: f64,
    /// 0.9999.
    pub max_value: f64,
    /// 0.
    pub update_after_step: u64,
}

impl Default for EmaConfig {
    fn default() -> Self {
        EmaConfig {
            inv_gamma: 1.0,
            power: 0.75,
            min_value: 0.0,
            max_value: 0.9999,
            update_after_step: 0,
        }
    }
}

impl EmaConfig {
    /// The decay of the update made after `optimization_step` earlier updates.
    pub fn decay(&self, optimization_step: u64) -> f64 {
        let k = optimization_step.saturating_sub(self.update_after_step + 1);
        if k == 0 {
            return 0.0;
        }
        let value = 1.0 - (1.0 + k as f64 / self.inv_gamma).powf(-self.power);
        value.min(self.max_value).max(self.min_value)
    }
}

/// `ema ← decay · ema + (1 − decay) · param` for every pair (same order, same shapes).
pub(crate) fn ema_update(ema: &[Param], params: &[Param], decay: f64) -> Result<()> {
    for (e, p) in ema.iter().zip(params) {
        if p.frozen {
            // d·x + (1 − d)·x is not always x in floats: a fixed table stays bit for bit.
            continue;
        }
        let (et, pt) = (e.var.as_tensor(), p.var.as_tensor());
        if et.device().is_cpu() {
            et.inplace_op2(pt, &EmaOp(decay as f32))?;
        } else {
            e.var.set(&((et * decay)? + (pt * (1.0 - decay))?)?)?;
        }
    }
    Ok(())
}

struct EmaOp(f32);

impl InplaceOp2 for EmaOp {
    fn name(&self) -> &'static str {
        "scaledp-ema"
    }

    fn cpu_fwd(
        &self,
        s1: &mut CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<()> {
        let src = slice(s2, l2)?;
        let Some((a, b)) = l1.contiguous_offsets() else {
            candle_core::bail!("ema: non-contiguous parameter");
        };
        let CpuStorage::F32(dst) = s1 else {
            candle_core::bail!("ema: parameters must be f32");
        };
        let d = self.0;
        dst[a..b]
            .par_chunks_mut(1 << 14)
            .zip(src.par_chunks(1 << 14))
            .for_each(|(e, p)| {
                vectorized(|| {
                    for (e, p) in e.iter_mut().zip(p) {
                        *e = d * *e + (1.0 - d) * p;
                    }
                })
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn param(name: &str, decay: bool) -> Param {
        Param {
            name: name.into(),
            var: Var::zeros(1, candle_core::DType::F32, &Device::Cpu).unwrap(),
            decay,
            frozen: false,
        }
    }

    /// diffusion_policy's groups: every encoder tensor at the encoder decay, the denoiser's
    /// Linear weights at the transformer decay, nothing else; runs saved before the encoder
    /// group (NaN) keep the old single group.
    #[test]
    fn decay_groups_follow_diffusion_policy() {
        let c = AdamWConfig::default();
        assert_eq!(
            decay_of(&param("obs_encoder.front.backbone.conv1.weight", true), &c),
            1e-6
        );
        assert_eq!(
            decay_of(&param("obs_encoder.front.backbone.bn1.bias", false), &c),
            1e-6
        );
        assert_eq!(decay_of(&param("blocks.0.attn.qkv.weight", true), &c), 1e-3);
        assert_eq!(decay_of(&param("blocks.0.attn.qkv.bias", false), &c), 0.0);
        assert_eq!(decay_of(&param("pos_embed", false), &c), 0.0);
        let old = AdamWConfig {
            encoder_weight_decay: f64::NAN,
            ..c
        };
        assert_eq!(
            decay_of(&param("obs_encoder.front.linear.weight", true), &old),
            1e-3
        );
        assert_eq!(
            decay_of(&param("obs_encoder.front.linear.bias", false), &old),
            0.0
        );
    }
}
