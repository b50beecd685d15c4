//! DP-T's forward and backward passes written out by hand, as [`crate::engine::denoiser`] does
//! for ScaleDP: every matrix product one parallel GEMM, activations kept in buffers reused from
//! step to step. The arithmetic is the candle module's ([`crate::model::dpt`]), which the tests
//! hold it to, dropout masks included (drawn in the same order from the same generator).
//!
//! The pass splits where ScaleDP's does: [`condition`] computes everything that depends on the
//! timestep and the observation and not on the noisy actions — the memory (condition tokens
//! through the condition MLP) and every layer's cross-attention keys and values — so DDIM
//! computes it for all its steps at once; [`trunk`] runs the decoder layers.

mod attn;
pub(crate) mod backward;
pub(crate) mod rows;

use super::ops::{self, linear};
use super::WeightView;
use crate::error::Result;
use crate::model::dpt::{sinusoidal_pos_emb, LN_EPS};
use crate::model::dropout::Dropout;
use attn::{Layout, Mask};

/// The denoiser's shape.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Shape {
    pub layers: usize,
    pub d: usize,
    pub heads: usize,
    /// Action width A.
    pub action: usize,
    /// Action tokens T.
    pub tokens: usize,
    /// Observation steps To.
    pub obs_steps: usize,
    /// One observation step's features.
    pub obs_dim: usize,
    pub causal: bool,
}

impl Shape {
    /// Condition tokens: the step and one per observation step.
    fn tc(&self) -> usize {
        1 + self.obs_steps
    }

    fn self_attn(&self) -> Layout {
        Layout {
            tq: self.tokens,
            tk: self.tokens,
            d: self.d,
            heads: self.heads,
            q_stride: 3 * self.d,
            q_off: 0,
            kv_stride: 3 * self.d,
            k_off: self.d,
            v_off: 2 * self.d,
            mask: if self.causal {
                Mask::Causal
            } else {
                Mask::None
            },
        }
    }

    fn cross_attn(&self) -> Layout {
        Layout {
            tq: self.tokens,
            tk: self.tc(),
            d: self.d,
            heads: self.heads,
            q_stride: self.d,
            q_off: 0,
            kv_stride: 2 * self.d,
            k_off: 0,
            v_off: self.d,
            mask: if self.causal {
                Mask::Memory
            } else {
                Mask::None
            },
        }
    }
}

/// One decoder layer's activations (dropout masks empty without dropout).
#[derive(Default)]
struct LayerActs {
    /// Cross-attention keys and values of the memory `[M, Tc, 2d]`.
    kv: Vec<f32>,
    n1: Vec<f32>,
    r1: Vec<f32>,
    u1: Vec<f32>,
    qkv: Vec<f32>,
    p1: Vec<f32>,
    drop_p1: Vec<f32>,
    o1: Vec<f32>,
    a1: Vec<f32>,
    drop1: Vec<f32>,
    n2: Vec<f32>,
    r2: Vec<f32>,
    u2: Vec<f32>,
    q2: Vec<f32>,
    p2: Vec<f32>,
    drop_p2: Vec<f32>,
    o2: Vec<f32>,
    a2: Vec<f32>,
    drop2: Vec<f32>,
    n3: Vec<f32>,
    r3: Vec<f32>,
    u3: Vec<f32>,
    f1: Vec<f32>,
    /// GELU(f1) through the FFN's dropout: linear2's input.
    gd: Vec<f32>,
    drop_f: Vec<f32>,
    f2: Vec<f32>,
    drop3: Vec<f32>,
}

/// Activations of the last forward pass, kept between calls.
#[derive(Default)]
pub(crate) struct Work {
    samples: usize,
    conds: usize,
    repeat: usize,
    /// Condition tokens before the MLP `[M, Tc, d]`.
    mx: Vec<f32>,
    e1: Vec<f32>,
    e1m: Vec<f32>,
    /// The memory `[M, Tc, d]`.
    mem: Vec<f32>,
    x: Vec<f32>,
    h: Vec<f32>,
    layers: Vec<LayerActs>,
    nf: Vec<f32>,
    rf: Vec<f32>,
    uf: Vec<f32>,
    /// ε̂ `[M, T, A]`.
    pub out: Vec<f32>,
}

/// Every layer's cross-attention keys and values of a [`condition`] call, taken out of a
/// [`Work`] (DDIM computes them for all its steps at once).
pub(crate) struct Memory {
    rows: usize,
    kv: Vec<Vec<f32>>,
}

impl Work {
    /// Moves the keys and values of the last [`condition`] out of the buffers.
    pub fn take_memory(&mut self) -> Memory {
        Memory {
            rows: self.samples,
            kv: self
                .layers
                .iter_mut()
                .map(|l| std::mem::take(&mut l.kv))
                .collect(),
        }
    }

    /// Puts rows `rows` of `all` in place for a [`trunk`] pass over `rows.len()` samples.
    pub fn set_memory(&mut self, all: &Memory, rows: &[usize]) {
        for (l, src) in self.layers.iter_mut().zip(&all.kv) {
            let width = src.len() / all.rows.max(1);
            l.kv.clear();
            for &r in rows {
                l.kv.extend_from_slice(&src[r * width..(r + 1) * width]);
            }
        }
        self.samples = rows.len();
    }
}

/// `v` with exactly `n` values (contents unspecified where it grew).
fn sized(v: &mut Vec<f32>, n: usize) -> &mut Vec<f32> {
    v.resize(n, 0.0);
    v
}

/// The name of decoder layer `i`'s tensor `rest`.
fn layer(i: usize, rest: &str) -> String {
    format!("model.decoder.layers.{i}.{rest}")
}

/// A fresh dropout mask of `n` units, or none.
fn draw(drop: &mut Option<Dropout>, n: usize) -> Vec<f32> {
    drop.as_mut().map_or_else(Vec::new, |d| d.mask(n))
}

/// ε̂ for `x` `[M, T, A]` at timesteps `t` (M values) under `cond` `[N, To · F]`, sample m using
/// condition row `m / repeat`, with dropout when `drop` is given. Keeps the activations in `w`
/// for [`backward`].
#[allow(clippy::too_many_arguments)]
pub(crate) fn forward(
    s: &Shape,
    wv: &WeightView,
    x: &[f32],
    t: &[f32],
    cond: &[f32],
    repeat: usize,
    w: &mut Work,
    drop: &mut Option<Dropout>,
) -> Result<()> {
    condition(s, wv, t, cond, repeat, w)?;
    trunk(s, wv, x, w, drop)
}

/// The condition half of [`forward`]: the step token and the observation tokens, the
/// condition MLP (the memory), and every layer's cross-attention keys and values.
pub(crate) fn condition(
    s: &Shape,
    wv: &WeightView,
    t: &[f32],
    cond: &[f32],
    repeat: usize,
    w: &mut Work,
) -> Result<()> {
    let (d, tc, to) = (s.d, s.tc(), s.obs_steps);
    let m = t.len();
    let n = cond.len() / (to * s.obs_dim).max(1);
    let repeat = repeat.max(1);
    (w.samples, w.conds, w.repeat) = (m, n, repeat);
    let mut cemb = vec![0f32; n * to * d];
    linear(
        cond,
        wv.linear("model.cond_obs_emb.weight")?,
        Some(wv.get("model.cond_obs_emb.bias")?),
        n * to,
        s.obs_dim,
        d,
        &mut cemb,
    );
    let tf = sinusoidal_pos_emb(t, d);
    let cpos = wv.get("model.cond_pos_emb")?;
    let mx = sized(&mut w.mx, m * tc * d);
    for (i, sample) in mx.chunks_exact_mut(tc * d).enumerate() {
        sample[..d].copy_from_slice(&tf[i * d..(i + 1) * d]);
        let obs = &cemb[(i / repeat) * to * d..][..to * d];
        sample[d..].copy_from_slice(obs);
        ops::add_into(sample, &cpos[..tc * d]);
    }
    let rows = m * tc;
    linear(
        &w.mx,
        wv.linear("model.encoder.0.weight")?,
        Some(wv.get("model.encoder.0.bias")?),
        rows,
        d,
        4 * d,
        sized(&mut w.e1, rows * 4 * d),
    );
    ops::map(&w.e1, sized(&mut w.e1m, rows * 4 * d), rows::mish);
    linear(
        &w.e1m,
        wv.linear("model.encoder.2.weight")?,
        Some(wv.get("model.encoder.2.bias")?),
        rows,
        4 * d,
        d,
        sized(&mut w.mem, rows * d),
    );
    if w.layers.len() != s.layers {
        w.layers = (0..s.layers).map(|_| LayerActs::default()).collect();
    }
    for (i, l) in w.layers.iter_mut().enumerate() {
        let name = layer(i, "multihead_attn.in_proj_weight");
        let bias = &wv.get(&layer(i, "multihead_attn.in_proj_bias"))?[d..3 * d];
        linear(
            &w.mem,
            wv.linear_rows(&name, d, 2 * d)?,
            Some(bias),
            rows,
            d,
            2 * d,
            sized(&mut l.kv, rows * 2 * d),
        );
    }
    Ok(())
}

/// LayerNorm with affine parameters `prefix.{weight,bias}`: `x` → normalized `n`, `rstd`, `u`.
fn norm(
    wv: &WeightView,
    prefix: &str,
    x: &[f32],
    d: usize,
    (n, r, u): (&mut Vec<f32>, &mut Vec<f32>, &mut Vec<f32>),
) -> Result<()> {
    let rows = x.len() / d;
    ops::layer_norm(x, d, LN_EPS, sized(n, rows * d), sized(r, rows));
    let (wt, b) = (
        wv.get(&format!("{prefix}.weight"))?,
        wv.get(&format!("{prefix}.bias"))?,
    );
    rows::affine(n, wt, b, d, sized(u, rows * d));
    Ok(())
}

/// The decoder on `x` `[M, T, A]` with the memory [`condition`] left in `w` (or
/// [`Work::set_memory`] put there), with dropout when `drop` is given.
pub(crate) fn trunk(
    s: &Shape,
    wv: &WeightView,
    x: &[f32],
    w: &mut Work,
    drop: &mut Option<Dropout>,
) -> Result<()> {
    let (d, tk, a, h) = (s.d, s.tokens, s.action, s.heads);
    let m = w.samples;
    let rows = m * tk;
    sized(&mut w.x, rows * a).copy_from_slice(&x[..rows * a]);
    linear(
        &w.x,
        wv.linear("model.input_emb.weight")?,
        Some(wv.get("model.input_emb.bias")?),
        rows,
        a,
        d,
        sized(&mut w.h, rows * d),
    );
    let pos = wv.get("model.pos_emb")?;
    for sample in w.h.chunks_exact_mut(tk * d) {
        ops::add_into(sample, &pos[..tk * d]);
    }
    let (sa, ca) = (s.self_attn(), s.cross_attn());
    for (i, l) in w.layers.iter_mut().enumerate() {
        // x += drop(self_attn(norm1(x)))
        norm(
            wv,
            &layer(i, "norm1"),
            &w.h,
            d,
            (&mut l.n1, &mut l.r1, &mut l.u1),
        )?;
        linear(
            &l.u1,
            wv.linear(&layer(i, "self_attn.in_proj_weight"))?,
            Some(wv.get(&layer(i, "self_attn.in_proj_bias"))?),
            rows,
            d,
            3 * d,
            sized(&mut l.qkv, rows * 3 * d),
        );
        l.drop_p1 = draw(drop, m * h * tk * tk);
        attn::forward(
            sa,
            &l.qkv,
            &l.qkv,
            sized(&mut l.o1, rows * d),
            sized(&mut l.p1, m * sa.probs_per_sample()),
            &l.drop_p1,
        );
        linear(
            &l.o1,
            wv.linear(&layer(i, "self_attn.out_proj.weight"))?,
            Some(wv.get(&layer(i, "self_attn.out_proj.bias"))?),
            rows,
            d,
            d,
            sized(&mut l.a1, rows * d),
        );
        l.drop1 = draw(drop, rows * d);
        rows::residual(&mut w.h, &l.a1, &l.drop1);
        // x += drop(cross_attn(norm2(x), memory))
        norm(
            wv,
            &layer(i, "norm2"),
            &w.h,
            d,
            (&mut l.n2, &mut l.r2, &mut l.u2),
        )?;
        linear(
            &l.u2,
            wv.linear_rows(&layer(i, "multihead_attn.in_proj_weight"), 0, d)?,
            Some(&wv.get(&layer(i, "multihead_attn.in_proj_bias"))?[..d]),
            rows,
            d,
            d,
            sized(&mut l.q2, rows * d),
        );
        l.drop_p2 = draw(drop, m * ca.probs_per_sample());
        attn::forward(
            ca,
            &l.q2,
            &l.kv,
            sized(&mut l.o2, rows * d),
            sized(&mut l.p2, m * ca.probs_per_sample()),
            &l.drop_p2,
        );
        linear(
            &l.o2,
            wv.linear(&layer(i, "multihead_attn.out_proj.weight"))?,
            Some(wv.get(&layer(i, "multihead_attn.out_proj.bias"))?),
            rows,
            d,
            d,
            sized(&mut l.a2, rows * d),
        );
        l.drop2 = draw(drop, rows * d);
        rows::residual(&mut w.h, &l.a2, &l.drop2);
        // x += drop(linear2(drop(gelu(linear1(norm3(x))))))
        norm(
            wv,
            &layer(i, "norm3"),
            &w.h,
            d,
            (&mut l.n3, &mut l.r3, &mut l.u3),
        )?;
        linear(
            &l.u3,
            wv.linear(&layer(i, "linear1.weight"))?,
            Some(wv.get(&layer(i, "linear1.bias"))?),
            rows,
            d,
            4 * d,
            sized(&mut l.f1, rows * 4 * d),
        );
        ops::map(&l.f1, sized(&mut l.gd, rows * 4 * d), rows::gelu_erf);
        l.drop_f = draw(drop, rows * 4 * d);
        rows::mask_in_place(&mut l.gd, &l.drop_f);
        linear(
            &l.gd,
            wv.linear(&layer(i, "linear2.weight"))?,
            Some(wv.get(&layer(i, "linear2.bias"))?),
            rows,
            4 * d,
            d,
            sized(&mut l.f2, rows * d),
        );
        l.drop3 = draw(drop, rows * d);
        rows::residual(&mut w.h, &l.f2, &l.drop3);
    }
    norm(wv, "model.ln_f", &w.h, d, (&mut w.nf, &mut w.rf, &mut w.uf))?;
    linear(
        &w.uf,
        wv.linear("model.head.weight")?,
        Some(wv.get("model.head.bias")?),
        rows,
        d,
        a,
        sized(&mut w.out, rows * a),
    );
    Ok(())
}
