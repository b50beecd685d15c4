//! The denoiser's backward pass: every parameter's gradient and ∂loss/∂cond from the
//! activations [`super::forward`] kept.

use super::{blk, Shape, Work, FREQ_DIM};
use crate::engine::attention;
use crate::engine::ops::{self, linear_backward};
use crate::engine::{Grads, WeightView};
use crate::error::Result;

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
