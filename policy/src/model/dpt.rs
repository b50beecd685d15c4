//! DP-T, the ScaleDP paper's baseline: diffusion_policy's `TransformerForDiffusion` as its hybrid
//! image policy builds it (`time_as_cond`, `obs_as_cond`, `n_cond_layers: 0`), in candle.
//!
//! - Condition tokens (the decoder's memory): the diffusion step as diffusion_policy's
//!   `SinusoidalPosEmb` (sin first, then cos; no MLP), then each observation step's features
//!   through `cond_obs_emb`; plus `cond_pos_emb`; then the per-token MLP `encoder` (Linear d→4d,
//!   Mish, Linear 4d→d).
//! - Action tokens: `input_emb` + `pos_emb`, then `n_layer` pre-LN `nn.TransformerDecoderLayer`s
//!   (self-attention, cross-attention to the memory, FFN 4d with exact GELU; LayerNorm eps 1e-5;
//!   dropout on the attention weights, after each attention and in and after the FFN), then
//!   `ln_f` and `head`.
//! - Masks ([`crate::Attention::Causal`], DP-T's default): action t sees actions ≤ t, and
//!   condition token s when t ≥ s − 1 (token 0 is the step). Non-causal drops both.
//!
//! State-dict names follow diffusion_policy's policy module (`model.` is its
//! `TransformerForDiffusion`): `model.input_emb.*`, `model.pos_emb`, `model.cond_obs_emb.*`,
//! `model.cond_pos_emb`, `model.encoder.{0,2}.*`,
//! `model.decoder.layers.{i}.{self_attn,multihead_attn}.{in_proj_weight,in_proj_bias,out_proj.*}`,
//! `model.decoder.layers.{i}.{linear1,linear2,norm1,norm2,norm3}.*`, `model.ln_f.*`,
//! `model.head.*`. The mask buffers (`model.mask`, `model.memory_mask`) are not stored: they
//! follow from the configuration.

use candle_core::{Device, Tensor, D};

use crate::error::Result;
use crate::model::denoiser::Linear;
use crate::model::dropout::Dropout;
use crate::model::params::{Builder, Init};

/// PyTorch's LayerNorm epsilon (`nn.LayerNorm`, `nn.TransformerDecoderLayer`).
pub(crate) const LN_EPS: f64 = 1e-5;

/// The shape of a DP-T denoiser.
#[derive(Clone, Copy, Debug)]
pub(crate) struct DpTDims {
    pub layers: usize,
    pub d: usize,
    pub heads: usize,
    /// Action width A.
    pub action_dim: usize,
    /// Action tokens T.
    pub horizon: usize,
    /// Observation steps To (condition tokens 1 ..= To).
    pub obs_steps: usize,
    /// One observation step's feature width.
    pub obs_dim: usize,
    /// Both masks on (DP-T's default).
    pub causal: bool,
}

/// diffusion_policy's `SinusoidalPosEmb(dim)` of timesteps `t`: `[sin(t·f), cos(t·f)]`,
/// f_i = exp(−i · ln(10⁴) / (dim/2 − 1)), in float32.
pub fn sinusoidal_pos_emb(t: &[f32], dim: usize) -> Vec<f32> {
    let half = dim / 2;
    let e = ((10_000f64).ln() / (half.max(2) - 1) as f64) as f32;
    let freqs: Vec<f32> = (0..half).map(|i| (-e * i as f32).exp()).collect();
    let mut v = Vec::with_capacity(t.len() * dim);
    for &ti in t {
        v.extend(freqs.iter().map(|f| (ti * f).sin()));
        v.extend(freqs.iter().map(|f| (ti * f).cos()));
        v.extend(std::iter::repeat_n(0.0, dim - 2 * half));
    }
    v
}

/// The additive masks: self-attention `[T, T]` and memory `[T, 1 + To]` (0 or −∞).
pub(crate) fn masks(horizon: usize, obs_steps: usize) -> (Vec<f32>, Vec<f32>) {
    let inf = f32::NEG_INFINITY;
    let tgt = (0..horizon)
        .flat_map(|t| (0..horizon).map(move |s| if s <= t { 0.0 } else { inf }))
        .collect();
    let mem = (0..horizon)
        .flat_map(|t| (0..=obs_steps).map(move |s| if t + 1 >= s { 0.0 } else { inf }))
        .collect();
    (tgt, mem)
}

/// LayerNorm with affine parameters over the last axis (composed of primitives for autograd).
#[derive(Clone, Debug)]
struct LayerNorm {
    weight: Tensor,
    bias: Tensor,
}

impl LayerNorm {
    fn new(vb: &Builder, d: usize) -> Result<Self> {
        Ok(LayerNorm {
            weight: vb.get(&[d], "weight", Init::Ones, false)?,
            bias: vb.get(&[d], "bias", Init::Zeros, false)?,
        })
    }

    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mean = x.mean_keepdim(D::Minus1)?;
        let xc = x.broadcast_sub(&mean)?;
        let var = xc.sqr()?.mean_keepdim(D::Minus1)?;
        let n = xc.broadcast_div(&(var + LN_EPS)?.sqrt()?)?;
        Ok(n.broadcast_mul(&self.weight)?.broadcast_add(&self.bias)?)
    }
}

/// `nn.MultiheadAttention` (batch first): `in_proj_weight` `[3d, d]` (q, k, v stacked),
/// `in_proj_bias`, `out_proj`.
#[derive(Clone, Debug)]
struct Mha {
    heads: usize,
    w_in: Tensor,
    b_in: Tensor,
    out: Linear,
}

impl Mha {
    fn new(vb: &Builder, d: usize, heads: usize) -> Result<Self> {
        let n02 = Init::Normal(0.02);
        Ok(Mha {
            heads,
            w_in: vb.get(&[3 * d, d], "in_proj_weight", n02, true)?,
            b_in: vb.get(&[3 * d], "in_proj_bias", Init::Zeros, false)?,
            out: Linear::new(&vb.pp("out_proj"), d, d, n02)?,
        })
    }

    /// `x · W[rows]ᵀ + b[rows]` for the projection rows `from .. from + n`.
    fn project(&self, x: &Tensor, from: usize, n: usize) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        let w = self.w_in.narrow(0, from, n)?;
        let bias = self.b_in.narrow(0, from, n)?;
        Ok(x.reshape((b * t, d))?
            .matmul(&w.t()?)?
            .broadcast_add(&bias)?
            .reshape((b, t, n))?)
    }

    /// `[B, T, n·hd]` → `[B, H, T, hd]`.
    fn split(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        Ok(x.reshape((b, t, self.heads, d / self.heads))?
            .transpose(1, 2)?
            .contiguous()?)
    }

    /// Attention of queries `x` `[B, T, d]` to `kv` `[B, S, d]` (the memory, or `x` itself for
    /// self-attention), with an additive `[T, S]` mask and dropout on the weights.
    fn forward(
        &self,
        x: &Tensor,
        kv: &Tensor,
        mask: Option<&Tensor>,
        drop: &mut Option<Dropout>,
    ) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        let hd = d / self.heads;
        let q = (self.split(&self.project(x, 0, d)?)? * (hd as f64).powf(-0.5))?;
        let k = self.split(&self.project(kv, d, d)?)?;
        let v = self.split(&self.project(kv, 2 * d, d)?)?;
        let mut scores = q.matmul(&k.t()?)?;
        if let Some(m) = mask {
            scores = scores.broadcast_add(m)?;
        }
        let mut p = candle_nn::ops::softmax(&scores, D::Minus1)?;
        if let Some(dr) = drop {
            p = apply(&p, dr)?;
        }
        let y = p.matmul(&v)?.transpose(1, 2)?.reshape((b, t, d))?;
        self.out.forward(&y)
    }
}

/// `x` times a fresh dropout mask of its shape.
fn apply(x: &Tensor, drop: &mut Dropout) -> Result<Tensor> {
    let m = Tensor::from_vec(drop.mask(x.elem_count()), x.dims(), x.device())?;
    Ok((x * m)?)
}

/// `x` with dropout when training.
fn dropped(x: Tensor, drop: &mut Option<Dropout>) -> Result<Tensor> {
    match drop {
        Some(d) => apply(&x, d),
        None => Ok(x),
    }
}

/// One `nn.TransformerDecoderLayer(norm_first=True, activation="gelu")`.
#[derive(Clone, Debug)]
struct DecoderLayer {
    self_attn: Mha,
    cross_attn: Mha,
    linear1: Linear,
    linear2: Linear,
    norm1: LayerNorm,
    norm2: LayerNorm,
    norm3: LayerNorm,
}

impl DecoderLayer {
    fn new(vb: &Builder, d: usize, heads: usize) -> Result<Self> {
        let n02 = Init::Normal(0.02);
        Ok(DecoderLayer {
            self_attn: Mha::new(&vb.pp("self_attn"), d, heads)?,
            cross_attn: Mha::new(&vb.pp("multihead_attn"), d, heads)?,
            linear1: Linear::new(&vb.pp("linear1"), d, 4 * d, n02)?,
            linear2: Linear::new(&vb.pp("linear2"), 4 * d, d, n02)?,
            norm1: LayerNorm::new(&vb.pp("norm1"), d)?,
            norm2: LayerNorm::new(&vb.pp("norm2"), d)?,
            norm3: LayerNorm::new(&vb.pp("norm3"), d)?,
        })
    }

    fn forward(
        &self,
        x: &Tensor,
        memory: &Tensor,
        masks: Option<&(Tensor, Tensor)>,
        drop: &mut Option<Dropout>,
    ) -> Result<Tensor> {
        let h = self.norm1.forward(x)?;
        let a = self.self_attn.forward(&h, &h, masks.map(|m| &m.0), drop)?;
        let x = (x + dropped(a, drop)?)?;
        let h = self.norm2.forward(&x)?;
        let a = self
            .cross_attn
            .forward(&h, memory, masks.map(|m| &m.1), drop)?;
        let x = (x + dropped(a, drop)?)?;
        let h = self.linear1.forward(&self.norm3.forward(&x)?)?.gelu_erf()?;
        let h = self.linear2.forward(&dropped(h, drop)?)?;
        Ok((x + dropped(h, drop)?)?)
    }
}

/// The DP-T denoiser: noisy actions `[B, T, A]`, timesteps, observation features → ε̂.
#[derive(Clone, Debug)]
pub(crate) struct DpT {
    dims: DpTDims,
    input_emb: Linear,
    pos_emb: Tensor,
    cond_obs_emb: Linear,
    cond_pos_emb: Tensor,
    enc0: Linear,
    enc2: Linear,
    layers: Vec<DecoderLayer>,
    ln_f: LayerNorm,
    head: Linear,
}

impl DpT {
    /// Built under `vb` (the model's root builder: names get the `model.` prefix here).
    pub fn new(vb: &Builder, p: DpTDims) -> Result<Self> {
        let vb = vb.pp("model");
        let (d, n02) = (p.d, Init::Normal(0.02));
        let layers = (0..p.layers)
            .map(|i| DecoderLayer::new(&vb.pp("decoder").pp("layers").pp(i), d, p.heads))
            .collect::<Result<_>>()?;
        Ok(DpT {
            dims: p,
            input_emb: Linear::new(&vb.pp("input_emb"), p.action_dim, d, n02)?,
            pos_emb: vb.get(&[1, p.horizon, d], "pos_emb", n02, false)?,
            cond_obs_emb: Linear::new(&vb.pp("cond_obs_emb"), p.obs_dim, d, n02)?,
            cond_pos_emb: vb.get(&[1, 1 + p.obs_steps, d], "cond_pos_emb", n02, false)?,
            enc0: Linear::new(&vb.pp("encoder").pp(0), d, 4 * d, n02)?,
            enc2: Linear::new(&vb.pp("encoder").pp(2), 4 * d, d, n02)?,
            layers,
            ln_f: LayerNorm::new(&vb.pp("ln_f"), d)?,
            head: Linear::new(&vb.pp("head"), d, p.action_dim, n02)?,
        })
    }

    /// The memory `[B, 1 + To, d]`: the step token and one token per observation step of
    /// `cond` `[B, To · obs_dim]`, through the condition MLP.
    pub fn memory(&self, t: &[f32], cond: &Tensor) -> Result<Tensor> {
        let p = &self.dims;
        let b = t.len();
        let dev = cond.device();
        let temb = Tensor::from_vec(sinusoidal_pos_emb(t, p.d), (b, 1, p.d), dev)?;
        let obs = self
            .cond_obs_emb
            .forward(&cond.reshape((b, p.obs_steps, p.obs_dim))?)?;
        let x = Tensor::cat(&[temb, obs], 1)?.broadcast_add(&self.cond_pos_emb)?;
        let h = self.enc0.forward(&x)?;
        // Mish: x · tanh(softplus(x)).
        let h = (&h * h.exp()?.affine(1.0, 1.0)?.log()?.tanh()?)?;
        self.enc2.forward(&h)
    }

    /// ε̂ for noisy actions `x` `[B, T, A]` under `memory` (from [`DpT::memory`]), with dropout
    /// when `drop` is given (training).
    pub fn forward(
        &self,
        x: &Tensor,
        memory: &Tensor,
        drop: &mut Option<Dropout>,
    ) -> Result<Tensor> {
        let p = &self.dims;
        let masks = if p.causal {
            let (tgt, mem) = masks(p.horizon, p.obs_steps);
            let dev: &Device = x.device();
            Some((
                Tensor::from_vec(tgt, (p.horizon, p.horizon), dev)?,
                Tensor::from_vec(mem, (p.horizon, 1 + p.obs_steps), dev)?,
            ))
        } else {
            None
        };
        let mut h = self.input_emb.forward(x)?.broadcast_add(&self.pos_emb)?;
        for layer in &self.layers {
            h = layer.forward(&h, memory, masks.as_ref(), drop)?;
        }
        self.head.forward(&self.ln_f.forward(&h)?)
    }
}
