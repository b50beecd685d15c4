//! The ScaleDP denoiser's forward and backward passes written out by hand (no autograd graph):
//! every matrix product one parallel GEMM, every row op one parallel pass, activations kept in
//! buffers reused from step to step. The arithmetic is the candle module's
//! ([`crate::model::denoiser`]), which the tests hold it to.

use super::attention::{self, AttnDims};
use super::ops::{self, linear, linear_backward};
use super::{Grads, WeightView};
use crate::error::Result;
use crate::model::denoiser::FREQ_DIM;

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
    let (d, tk, a) = (s.d, s.tokens, s.action);
    let m = t.len();
    let n = cond.len() / s.cond.max(1);
    let rows = m * tk;
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
    if w.blocks.len() != s.depth {
        w.blocks = (0..s.depth).map(|_| BlockActs::default()).collect();
    }
    let at = s.attn();
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
    linear(
        &w.cs,
        wv.linear("final_layer.adaLN_modulation.1.weight")?,
        Some(wv.get("final_layer.adaLN_modulation.1.bias")?),
        m,
        d,
        2 * d,
        sized(&mut w.fm, m * 2 * d),
    );
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

/// The gradient buffer of `name` (zeroed on first use).
fn g<'a>(grads: &'a mut Grads, wv: &WeightView, name: &str) -> Result<&'a mut [f32]> {
    let len = wv.get(name)?.len();
    Ok(grads.slot(name, len))
}

/// The backward of the last [`forward`]: `dout` `[M, T, A]` = ∂loss/∂ε̂. Adds every
/// denoiser parameter's gradient to `grads` and returns ∂loss/∂cond `[N, cond]`.
pub(crate) fn backward(
    s: &Shape,
    wv: &WeightView,
    cond: &[f32],
    repeat: usize,
    dout: &[f32],
    w: &mut Work,
    grads: &mut Grads,
) -> Result<Vec<f32>> {
    let (d, tk, a) = (s.d, s.tokens, s.action);
    let (m, n) = (w.samples, w.conds);
    let rows = m * tk;
    let hid = s.mlp * d;
    let mut dcs = vec![0f32; m * d];
    // Final layer.
    let mut duf = vec![0f32; rows * d];
    {
        let (wn, bn) = ("final_layer.linear.weight", "final_layer.linear.bias");
        let wt = wv.get(wn)?;
        let mut dw = vec![0f32; a * d];
        let mut db = vec![0f32; a];
        linear_backward(
            &w.uf,
            wt,
            dout,
            rows,
            d,
            a,
            &mut dw,
            Some(&mut db),
            Some((&mut duf, false)),
        );
        ops::add_into(g(grads, wv, wn)?, &dw);
        ops::add_into(g(grads, wv, bn)?, &db);
    }
    let mut dfm = vec![0f32; m * 2 * d];
    let mut dn = vec![0f32; rows * d];
    ops::modulate_backward(&w.nf, &w.fm, &duf, 2 * d, (0, d), tk, d, &mut dn, &mut dfm);
    let mut dh = vec![0f32; rows * d];
    ops::layer_norm_backward(&w.nf, &w.rf, &dn, d, &mut dh, false);
    mod_linear_backward(
        wv,
        grads,
        "final_layer.adaLN_modulation.1",
        &w.cs,
        &dfm,
        m,
        d,
        2 * d,
        &mut dcs,
    )?;
    // Blocks, last first.
    let at = s.attn();
    let mut dbig = vec![0f32; rows * hid];
    let mut dsmall = vec![0f32; rows * d];
    let mut dqkv = vec![0f32; rows * 3 * d];
    for (i, b) in w.blocks.iter().enumerate().rev() {
        let mut dm6 = vec![0f32; m * 6 * d];
        // h = h_mid + gate_mlp · f2
        ops::gated_add_backward(
            &dh,
            &b.f2,
            &b.m6,
            6 * d,
            5 * d,
            tk,
            d,
            &mut dsmall,
            &mut dm6,
        );
        lin_back(
            wv,
            grads,
            &blk(i, "mlp.fc2"),
            &b.g,
            &dsmall,
            rows,
            hid,
            d,
            Some((&mut dbig, false)),
        )?;
        ops::map_grad(&b.f1, &mut dbig, ops::gelu_grad);
        lin_back(
            wv,
            grads,
            &blk(i, "mlp.fc1"),
            &b.u2,
            &dbig,
            rows,
            d,
            hid,
            Some((&mut dsmall, false)),
        )?;
        ops::modulate_backward(
            &b.n2,
            &b.m6,
            &dsmall,
            6 * d,
            (3 * d, 4 * d),
            tk,
            d,
            &mut dn,
            &mut dm6,
        );
        ops::layer_norm_backward(&b.n2, &b.r2, &dn, d, &mut dh, true);
        // h_mid = h_in + gate_msa · proj(attn(...))
        ops::gated_add_backward(&dh, &b.a, &b.m6, 6 * d, 2 * d, tk, d, &mut dsmall, &mut dm6);
        let mut do_ = vec![0f32; rows * d];
        lin_back(
            wv,
            grads,
            &blk(i, "attn.proj"),
            &b.o,
            &dsmall,
            rows,
            d,
            d,
            Some((&mut do_, false)),
        )?;
        attention::backward(at, &b.qkv, &b.p, &do_, &mut dqkv);
        lin_back(
            wv,
            grads,
            &blk(i, "attn.qkv"),
            &b.u1,
            &dqkv,
            rows,
            d,
            3 * d,
            Some((&mut dsmall, false)),
        )?;
        ops::modulate_backward(
            &b.n1,
            &b.m6,
            &dsmall,
            6 * d,
            (0, d),
            tk,
            d,
            &mut dn,
            &mut dm6,
        );
        ops::layer_norm_backward(&b.n1, &b.r1, &dn, d, &mut dh, true);
        mod_linear_backward(
            wv,
            grads,
            &blk(i, "adaLN_modulation.1"),
            &w.cs,
            &dm6,
            m,
            d,
            6 * d,
            &mut dcs,
        )?;
    }
    // Input embedding and position.
    {
        let dpos = g(grads, wv, "pos_embed")?;
        for sample in dh.chunks_exact(tk * d) {
            ops::add_into(dpos, sample);
        }
    }
    lin_back(wv, grads, "x_embedder", &w.x, &dh, rows, a, d, None)?;
    // c = t_emb + cond_emb; cs = silu(c).
    ops::map_grad(&w.c, &mut dcs, ops::silu_grad);
    let dc = dcs;
    let mut dts = vec![0f32; m * d];
    lin_back(
        wv,
        grads,
        "t_embedder.mlp.2",
        &w.ts,
        &dc,
        m,
        d,
        d,
        Some((&mut dts, false)),
    )?;
    ops::map_grad(&w.t1, &mut dts, ops::silu_grad);
    lin_back(
        wv,
        grads,
        "t_embedder.mlp.0",
        &w.tf,
        &dts,
        m,
        FREQ_DIM,
        d,
        None,
    )?;
    let mut dcemb = vec![0f32; n * d];
    for (i, row) in dc.chunks_exact(d).enumerate() {
        let dst = &mut dcemb[(i / repeat.max(1)) * d..][..d];
        for (o, v) in dst.iter_mut().zip(row) {
            *o += v;
        }
    }
    let mut dcond = vec![0f32; n * s.cond];
    lin_back(
        wv,
        grads,
        "cond_obs_emb",
        cond,
        &dcemb,
        n,
        s.cond,
        d,
        Some((&mut dcond, false)),
    )?;
    Ok(dcond)
}

/// A Linear's backward under `prefix` (`.weight`, `.bias`), gradients added to `grads`.
#[allow(clippy::too_many_arguments)]
fn lin_back(
    wv: &WeightView,
    grads: &mut Grads,
    prefix: &str,
    x: &[f32],
    dy: &[f32],
    rows: usize,
    k: usize,
    n: usize,
    dx: Option<(&mut [f32], bool)>,
) -> Result<()> {
    let (wn, bn) = (format!("{prefix}.weight"), format!("{prefix}.bias"));
    let wt = wv.get(&wn)?;
    let mut dw = vec![0f32; n * k];
    let mut db = vec![0f32; n];
    linear_backward(x, wt, dy, rows, k, n, &mut dw, Some(&mut db), dx);
    grads.add(&wn, &dw);
    grads.add(&bn, &db);
    Ok(())
}

/// The backward of an adaLN Linear on `silu(c)` (`cs`): its gradients, and `dcs += dm · W`.
#[allow(clippy::too_many_arguments)]
fn mod_linear_backward(
    wv: &WeightView,
    grads: &mut Grads,
    prefix: &str,
    cs: &[f32],
    dm: &[f32],
    m: usize,
    d: usize,
    width: usize,
    dcs: &mut [f32],
) -> Result<()> {
    lin_back(wv, grads, prefix, cs, dm, m, d, width, Some((dcs, true)))
}
