//! The ScaleDP denoiser's forward and backward passes written out by hand (no autograd graph):
//! every matrix product one parallel GEMM, every row op one parallel pass, activations kept in
//! buffers reused from step to step. The arithmetic is the candle module's
//! ([`crate::model::denoiser`]), which the tests hold it to.

use super::attention::{self, AttnDims};
use super::ops::{self, linear};
use super::WeightView;
use crate::error::Result;
use crate::model::denoiser::FREQ_DIM;

pub(crate) mod backward;

/// LayerNorm epsilon (DiT's).
const LN_EPS: f64 = 1e-6;

/// The denoiser's shape.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Shape {
    pub depth: usize,
    pub d: usize,
    pub heads: usize,
    pub mlp: usize,
    /// Action width A.
    pub action: usize,
    /// Action tokens T (the chunk).
    pub tokens: usize,
    /// Condition width.
    pub cond: usize,
    pub causal: bool,
}

impl Shape {
    fn attn(&self) -> AttnDims {
        AttnDims {
            tokens: self.tokens,
            d: self.d,
            heads: self.heads,
            causal: self.causal,
        }
    }
}

/// One block's activations.
#[derive(Default)]
struct BlockActs {
    m6: Vec<f32>,
    n1: Vec<f32>,
    r1: Vec<f32>,
    u1: Vec<f32>,
    qkv: Vec<f32>,
    p: Vec<f32>,
    o: Vec<f32>,
    a: Vec<f32>,
    n2: Vec<f32>,
    r2: Vec<f32>,
    u2: Vec<f32>,
    f1: Vec<f32>,
    g: Vec<f32>,
    f2: Vec<f32>,
}

/// Activations of the last forward pass and scratch for the backward, kept between calls.
#[derive(Default)]
pub(crate) struct Work {
    samples: usize,
    conds: usize,
    tf: Vec<f32>,
    t1: Vec<f32>,
    ts: Vec<f32>,
    cemb: Vec<f32>,
    c: Vec<f32>,
    cs: Vec<f32>,
    x: Vec<f32>,
    h: Vec<f32>,
    blocks: Vec<BlockActs>,
    fm: Vec<f32>,
    nf: Vec<f32>,
    rf: Vec<f32>,
    uf: Vec<f32>,
    /// ε̂ `[M, T, A]`.
    pub out: Vec<f32>,
}

/// The adaLN modulations of a [`condition`] call, taken out of a [`Work`]: each block's
/// `[M, 6d]`, then the final layer's `[M, 2d]`.
pub(crate) struct Modulation {
    rows: usize,
    blocks: Vec<Vec<f32>>,
    last: Vec<f32>,
}

impl Work {
    /// Moves the modulations of the last [`condition`] out of the buffers.
    pub fn take_modulation(&mut self) -> Modulation {
        Modulation {
            rows: self.samples,
            blocks: self
                .blocks
                .iter_mut()
                .map(|b| std::mem::take(&mut b.m6))
                .collect(),
            last: std::mem::take(&mut self.fm),
        }
    }

    /// Puts rows `rows` of `all` in place for a [`trunk`] pass over `rows.len()` samples.
    pub fn set_modulation(&mut self, all: &Modulation, rows: &[usize]) {
        let gather = |src: &[f32], dst: &mut Vec<f32>| {
            let width = src.len() / all.rows.max(1);
            dst.clear();
            for &r in rows {
                dst.extend_from_slice(&src[r * width..(r + 1) * width]);
            }
        };
        for (b, src) in self.blocks.iter_mut().zip(&all.blocks) {
            gather(src, &mut b.m6);
        }
        gather(&all.last, &mut self.fm);
        self.samples = rows.len();
    }
}

/// `v` with exactly `n` values (contents unspecified where it grew).
fn sized(v: &mut Vec<f32>, n: usize) -> &mut Vec<f32> {
    v.resize(n, 0.0);
    v
}

/// The sinusoidal timestep embedding `[cos(t·f), sin(t·f)]` of [`crate::model::timestep_embedding`].
fn timestep_embedding(t: &[f32], out: &mut [f32]) {
    let half = FREQ_DIM / 2;
    let freqs: Vec<f32> = (0..half)
        .map(|i| (-(10_000f32).ln() * i as f32 / half as f32).exp())
        .collect();
    for (row, &ti) in out.chunks_exact_mut(FREQ_DIM).zip(t) {
        for (i, f) in freqs.iter().enumerate() {
            row[i] = (ti * f).cos();
            row[half + i] = (ti * f).sin();
        }
    }
}

fn blk(i: usize, rest: &str) -> String {
    format!("blocks.{i}.{rest}")
}

/// ε̂ for `x` `[M, T, A]` at timesteps `t` (M values) under `cond` `[N, cond]`, sample m using
/// condition row `m / repeat` (N · repeat = M). Keeps the activations in `w` for [`backward`].
pub(crate) fn forward(
    s: &Shape,
    wv: &WeightView,
    x: &[f32],
    t: &[f32],
    cond: &[f32],
    repeat: usize,
    w: &mut Work,
) -> Result<()> {
    condition(s, wv, t, cond, repeat, w)?;
    trunk(s, wv, x, w)
}

/// The conditioning half of [`forward`]: the timestep and observation embeddings, their sum
/// `c`, and from `SiLU(c)` every block's adaLN modulation and the final layer's — all that
/// depends on `(t, cond)` and not on `x`.
pub(crate) fn condition(
    s: &Shape,
    wv: &WeightView,
    t: &[f32],
    cond: &[f32],
    repeat: usize,
    w: &mut Work,
) -> Result<()> {
    let d = s.d;
    let m = t.len();
    let n = cond.len() / s.cond.max(1);
    w.samples = m;
    w.conds = n;
    timestep_embedding(t, sized(&mut w.tf, m * FREQ_DIM));
    linear(
        &w.tf,
        wv.linear("t_embedder.mlp.0.weight")?,
        Some(wv.get("t_embedder.mlp.0.bias")?),
        m,
        FREQ_DIM,
        d,
        sized(&mut w.t1, m * d),
    );
    ops::map(&w.t1, sized(&mut w.ts, m * d), ops::silu);
    linear(
        &w.ts,
        wv.linear("t_embedder.mlp.2.weight")?,
        Some(wv.get("t_embedder.mlp.2.bias")?),
        m,
        d,
        d,
        sized(&mut w.c, m * d),
    );
    linear(
        cond,
        wv.linear("cond_obs_emb.weight")?,
        Some(wv.get("cond_obs_emb.bias")?),
        n,
        s.cond,
        d,
        sized(&mut w.cemb, n * d),
    );
    for (i, row) in w.c.chunks_exact_mut(d).enumerate() {
        let e = &w.cemb[(i / repeat.max(1)) * d..][..d];
        for (v, e) in row.iter_mut().zip(e) {
            *v += e;
        }
    }
    ops::map(&w.c, sized(&mut w.cs, m * d), ops::silu);
    if w.blocks.len() != s.depth {
        w.blocks = (0..s.depth).map(|_| BlockActs::default()).collect();
    }
    for (i, b) in w.blocks.iter_mut().enumerate() {
        linear(
            &w.cs,
            wv.linear(&blk(i, "adaLN_modulation.1.weight"))?,
            Some(wv.get(&blk(i, "adaLN_modulation.1.bias"))?),
            m,
            d,
            6 * d,
            sized(&mut b.m6, m * 6 * d),
        );
    }
    linear(
        &w.cs,
        wv.linear("final_layer.adaLN_modulation.1.weight")?,
        Some(wv.get("final_layer.adaLN_modulation.1.bias")?),
        m,
        d,
        2 * d,
        sized(&mut w.fm, m * 2 * d),
    );
    Ok(())
}

/// The rest of [`forward`] on `x` `[M, T, A]`, with the modulations [`condition`] left in `w`
/// (or [`Work::set_modulation`] put there).
pub(crate) fn trunk(s: &Shape, wv: &WeightView, x: &[f32], w: &mut Work) -> Result<()> {
    let (d, tk, a) = (s.d, s.tokens, s.action);
    let rows = w.samples * tk;
    sized(&mut w.x, rows * a).copy_from_slice(&x[..rows * a]);
    let h = sized(&mut w.h, rows * d);
    linear(
        &w.x,
        wv.linear("x_embedder.weight")?,
        Some(wv.get("x_embedder.bias")?),
        rows,
        a,
        d,
        h,
    );
    let pos = wv.get("pos_embed")?;
    for sample in h.chunks_exact_mut(tk * d) {
        ops::add_into(sample, &pos[..tk * d]);
    }
    let at = s.attn();
    let m = w.samples;
    for (i, b) in w.blocks.iter_mut().enumerate() {
        ops::layer_norm(
            &w.h,
            d,
            LN_EPS,
            sized(&mut b.n1, rows * d),
            sized(&mut b.r1, rows),
        );
        ops::modulate(
            &b.n1,
            &b.m6,
            6 * d,
            (0, d),
            tk,
            d,
            sized(&mut b.u1, rows * d),
        );
        linear(
            &b.u1,
            wv.linear(&blk(i, "attn.qkv.weight"))?,
            Some(wv.get(&blk(i, "attn.qkv.bias"))?),
            rows,
            d,
            3 * d,
            sized(&mut b.qkv, rows * 3 * d),
        );
        attention::forward(
            at,
            &b.qkv,
            sized(&mut b.o, rows * d),
            sized(&mut b.p, m * at.probs_per_sample()),
        );
        linear(
            &b.o,
            wv.linear(&blk(i, "attn.proj.weight"))?,
            Some(wv.get(&blk(i, "attn.proj.bias"))?),
            rows,
            d,
            d,
            sized(&mut b.a, rows * d),
        );
        ops::gated_add(&mut w.h, &b.a, &b.m6, 6 * d, 2 * d, tk, d);
        ops::layer_norm(
            &w.h,
            d,
            LN_EPS,
            sized(&mut b.n2, rows * d),
            sized(&mut b.r2, rows),
        );
        ops::modulate(
            &b.n2,
            &b.m6,
            6 * d,
            (3 * d, 4 * d),
            tk,
            d,
            sized(&mut b.u2, rows * d),
        );
        let hid = s.mlp * d;
        linear(
            &b.u2,
            wv.linear(&blk(i, "mlp.fc1.weight"))?,
            Some(wv.get(&blk(i, "mlp.fc1.bias"))?),
            rows,
            d,
            hid,
            sized(&mut b.f1, rows * hid),
        );
        ops::map(&b.f1, sized(&mut b.g, rows * hid), ops::gelu);
        linear(
            &b.g,
            wv.linear(&blk(i, "mlp.fc2.weight"))?,
            Some(wv.get(&blk(i, "mlp.fc2.bias"))?),
            rows,
            hid,
            d,
            sized(&mut b.f2, rows * d),
        );
        ops::gated_add(&mut w.h, &b.f2, &b.m6, 6 * d, 5 * d, tk, d);
    }
    ops::layer_norm(
        &w.h,
        d,
        LN_EPS,
        sized(&mut w.nf, rows * d),
        sized(&mut w.rf, rows),
    );
    ops::modulate(
        &w.nf,
        &w.fm,
        2 * d,
        (0, d),
        tk,
        d,
        sized(&mut w.uf, rows * d),
    );
    linear(
        &w.uf,
        wv.linear("final_layer.linear.weight")?,
        Some(wv.get("final_layer.linear.bias")?),
        rows,
        d,
        a,
        sized(&mut w.out, rows * a),
    );
    Ok(())
}
