//! The ScaleDP denoiser: a DiT over the action chunk with adaLN-Zero conditioning on
//! `c = t_emb + cond_emb` and non-causal self-attention (every action token sees every other;
//! [`crate::Attention::Causal`] masks later tokens for the paper's ablation, nothing else
//! changes: same weights, same names). `pos_embed` is learned, or DiT's fixed sin-cos table
//! under the same name ([`crate::PosEmbed::SinCos`]).
//!
//! State-dict names as the reference PyTorch module: `x_embedder.*`, `pos_embed`,
//! `t_embedder.mlp.{0,2}.*`, `cond_obs_emb.*`, `blocks.{i}.attn.{qkv,proj}.*`,
//! `blocks.{i}.mlp.{fc1,fc2}.*`, `blocks.{i}.adaLN_modulation.1.*`,
//! `final_layer.{linear,adaLN_modulation.1}.*`.

use candle_core::{Device, Tensor, D};

use crate::config::PosEmbed;
use crate::error::Result;
use crate::model::params::{Builder, Init};

/// Width of the sinusoidal timestep embedding.
pub const FREQ_DIM: usize = 256;
/// LayerNorm epsilon (DiT's).
const LN_EPS: f64 = 1e-6;

/// A `Linear` with bias; `[.., in]` → `[.., out]`.
#[derive(Clone, Debug)]
pub(crate) struct Linear {
    weight: Tensor,
    bias: Tensor,
}

impl Linear {
    pub fn new(vb: &Builder, c_in: usize, c_out: usize, weight: Init) -> Result<Self> {
        Ok(Linear {
            weight: vb.get(&[c_out, c_in], "weight", weight, true)?,
            bias: vb.get(&[c_out], "bias", Init::Zeros, false)?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let dims = x.dims().to_vec();
        let c_in = dims[dims.len() - 1];
        let rows = x.elem_count() / c_in.max(1);
        let y = x
            .reshape((rows, c_in))?
            .matmul(&self.weight.t()?)?
            .broadcast_add(&self.bias)?;
        let mut out = dims;
        let last = out.len() - 1;
        out[last] = self.weight.dim(0)?;
        Ok(y.reshape(out)?)
    }
}

/// LayerNorm over the last axis without affine parameters, composed of differentiable
/// primitives (candle's fused `layer_norm` has no backward).
pub(crate) fn layer_norm(x: &Tensor) -> Result<Tensor> {
    let mean = x.mean_keepdim(D::Minus1)?;
    let xc = x.broadcast_sub(&mean)?;
    let var = xc.sqr()?.mean_keepdim(D::Minus1)?;
    Ok(xc.broadcast_div(&(var + LN_EPS)?.sqrt()?)?)
}

/// `x · (1 + scale) + shift` with `[B, d]` modulations broadcast over the tokens of `[B, T, d]`.
fn modulate(x: &Tensor, shift: &Tensor, scale: &Tensor) -> Result<Tensor> {
    Ok(x.broadcast_mul(&(scale.unsqueeze(1)? + 1.0)?)?
        .broadcast_add(&shift.unsqueeze(1)?)?)
}

/// DiT's sinusoidal embedding of timesteps `t`: `[cos(t·f), sin(t·f)]`, f_i = exp(−ln(10⁴)·i/128).
pub fn timestep_embedding(t: &[f32], device: &Device) -> Result<Tensor> {
    let half = FREQ_DIM / 2;
    let freqs: Vec<f32> = (0..half)
        .map(|i| (-(10_000f32).ln() * i as f32 / half as f32).exp())
        .collect();
    let mut v = Vec::with_capacity(t.len() * FREQ_DIM);
    for &ti in t {
        v.extend(freqs.iter().map(|f| (ti * f).cos()));
        v.extend(freqs.iter().map(|f| (ti * f).sin()));
    }
    Ok(Tensor::from_vec(v, (t.len(), FREQ_DIM), device)?)
}

/// `[t, t]`: 0 where key j ≤ query i, −∞ above the diagonal.
fn causal_mask(t: usize, device: &Device) -> Result<Tensor> {
    let m: Vec<f32> = (0..t)
        .flat_map(|i| (0..t).map(move |j| if j <= i { 0.0 } else { f32::NEG_INFINITY }))
        .collect();
    Ok(Tensor::from_vec(m, (t, t), device)?)
}

#[derive(Clone, Debug)]
struct Block {
    heads: usize,
    causal: bool,
    qkv: Linear,
    proj: Linear,
    fc1: Linear,
    fc2: Linear,
    ada: Linear,
}

impl Block {
    fn new(vb: &Builder, d: usize, heads: usize, mlp_ratio: usize, causal: bool) -> Result<Self> {
        let x = Init::XavierUniform;
        Ok(Block {
            heads,
            causal,
            qkv: Linear::new(&vb.pp("attn").pp("qkv"), d, 3 * d, x)?,
            proj: Linear::new(&vb.pp("attn").pp("proj"), d, d, x)?,
            fc1: Linear::new(&vb.pp("mlp").pp("fc1"), d, mlp_ratio * d, x)?,
            fc2: Linear::new(&vb.pp("mlp").pp("fc2"), mlp_ratio * d, d, x)?,
            ada: Linear::new(&vb.pp("adaLN_modulation").pp(1), d, 6 * d, Init::Zeros)?,
        })
    }

    fn attention(&self, x: &Tensor) -> Result<Tensor> {
        let (b, t, d) = x.dims3()?;
        let hd = d / self.heads;
        let qkv = self
            .qkv
            .forward(x)?
            .reshape((b, t, 3, self.heads, hd))?
            .permute((2, 0, 3, 1, 4))?;
        let q = (qkv.get(0)?.contiguous()? * (hd as f64).powf(-0.5))?;
        let k = qkv.get(1)?.contiguous()?;
        let v = qkv.get(2)?.contiguous()?;
        // ScaleDP: no mask, every token sees every other. The causal ablation hides later
        // tokens (−∞ above the diagonal; the diagonal keeps every row's softmax finite).
        let mut scores = q.matmul(&k.t()?)?;
        if self.causal {
            scores = scores.broadcast_add(&causal_mask(t, x.device())?)?;
        }
        let weights = candle_nn::ops::softmax(&scores, D::Minus1)?;
        let y = weights.matmul(&v)?.transpose(1, 2)?.reshape((b, t, d))?;
        self.proj.forward(&y)
    }

    fn forward(&self, x: &Tensor, c: &Tensor) -> Result<Tensor> {
        let m = self.ada.forward(&c.silu()?)?.chunk(6, 1)?;
        let h = modulate(&layer_norm(x)?, &m[0], &m[1])?;
        let x = (x + self.attention(&h)?.broadcast_mul(&m[2].unsqueeze(1)?)?)?;
        let h = modulate(&layer_norm(&x)?, &m[3], &m[4])?;
        let h = self.fc2.forward(&self.fc1.forward(&h)?.gelu()?)?;
        Ok((x + h.broadcast_mul(&m[5].unsqueeze(1)?)?)?)
    }
}

/// The denoiser's shape.
#[derive(Clone, Copy, Debug)]
pub(crate) struct DenoiserDims {
    pub depth: usize,
    pub hidden: usize,
    pub heads: usize,
    pub mlp_ratio: usize,
    pub action_dim: usize,
    pub action_chunk: usize,
    pub cond_dim: usize,
    /// The causal ablation (token i attends to tokens ≤ i only).
    pub causal: bool,
    /// Learned or fixed sin-cos `pos_embed`.
    pub pos_embed: PosEmbed,
}

/// ε-prediction network: noisy actions `[B, C, A]`, timesteps, condition `[B, cond]` → `[B, C, A]`.
#[derive(Clone, Debug)]
pub(crate) struct Denoiser {
    x_embedder: Linear,
    pos_embed: Tensor,
    t_mlp0: Linear,
    t_mlp2: Linear,
    cond_obs_emb: Linear,
    blocks: Vec<Block>,
    final_ada: Linear,
    final_linear: Linear,
}

impl Denoiser {
    pub fn new(vb: &Builder, p: DenoiserDims) -> Result<Self> {
        let d = p.hidden;
        let n02 = Init::Normal(0.02);
        let t = vb.pp("t_embedder").pp("mlp");
        let f = vb.pp("final_layer");
        let blocks = (0..p.depth)
            .map(|i| Block::new(&vb.pp("blocks").pp(i), d, p.heads, p.mlp_ratio, p.causal))
            .collect::<Result<_>>()?;
        Ok(Denoiser {
            x_embedder: Linear::new(&vb.pp("x_embedder"), p.action_dim, d, Init::XavierUniform)?,
            pos_embed: match p.pos_embed {
                PosEmbed::Learned => vb.get(&[1, p.action_chunk, d], "pos_embed", n02, false)?,
                PosEmbed::SinCos => {
                    vb.get_fixed(&[1, p.action_chunk, d], "pos_embed", Init::SinCos)?
                }
                PosEmbed::LearnedSinCos => {
                    vb.get(&[1, p.action_chunk, d], "pos_embed", Init::SinCos, false)?
                }
            },
            t_mlp0: Linear::new(&t.pp(0), FREQ_DIM, d, n02)?,
            t_mlp2: Linear::new(&t.pp(2), d, d, n02)?,
            cond_obs_emb: Linear::new(&vb.pp("cond_obs_emb"), p.cond_dim, d, n02)?,
            blocks,
            final_ada: Linear::new(&f.pp("adaLN_modulation").pp(1), d, 2 * d, Init::Zeros)?,
            final_linear: Linear::new(&f.pp("linear"), d, p.action_dim, Init::Zeros)?,
        })
    }

    /// The condition `c = t_emb + cond_emb`, `[B, d]`; `t_freq` is [`timestep_embedding`].
    pub fn condition(&self, t_freq: &Tensor, cond: &Tensor) -> Result<Tensor> {
        let t = self.t_mlp2.forward(&self.t_mlp0.forward(t_freq)?.silu()?)?;
        Ok((t + self.cond_obs_emb.forward(cond)?)?)
    }

    /// ε̂ for noisy actions `x` `[B, C, A]` under condition `c` (from [`Denoiser::condition`]).
    pub fn forward(&self, x: &Tensor, c: &Tensor) -> Result<Tensor> {
        let mut h = self.x_embedder.forward(x)?.broadcast_add(&self.pos_embed)?;
        for block in &self.blocks {
            h = block.forward(&h, c)?;
        }
        let m = self.final_ada.forward(&c.silu()?)?.chunk(2, 1)?;
        let h = modulate(&layer_norm(&h)?, &m[0], &m[1])?;
        self.final_linear.forward(&h)
    }
}
