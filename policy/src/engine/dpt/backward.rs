//! DP-T's backward pass: every parameter's gradient and ∂loss/∂cond from the activations (and
//! dropout masks) [`super::forward`] kept.

use super::{attn, layer, rows, Shape, Work};
use crate::engine::ops::{self, linear_backward};
use crate::engine::{Grads, WeightView};
use crate::error::Result;

/// The backward of a Linear whose weight is rows `from .. from + n` of the `[out, k]` tensor
/// `w_name` (and whose bias is the same entries of `b_name`): gradients added to `grads`, and
/// `dx` `[rows, k]` from `dy` `[rows, n]` when asked for (`true`: added to it).
#[allow(clippy::too_many_arguments)]
fn lin_back(
    wv: &WeightView,
    grads: &mut Grads,
    (w_name, b_name): (&str, &str),
    (from, n): (usize, usize),
    x: &[f32],
    dy: &[f32],
    rows: usize,
    k: usize,
    dx: Option<(&mut [f32], bool)>,
) -> Result<()> {
    let w = &wv.get(w_name)?[from * k..(from + n) * k];
    let mut dw = vec![0f32; n * k];
    let mut db = vec![0f32; n];
    linear_backward(x, w, dy, rows, k, n, &mut dw, Some(&mut db), dx);
    let len = wv.get(w_name)?.len();
    ops::add_into(&mut grads.slot(w_name, len)[from * k..(from + n) * k], &dw);
    let len = wv.get(b_name)?.len();
    ops::add_into(&mut grads.slot(b_name, len)[from..from + n], &db);
    Ok(())
}

/// [`lin_back`] of a whole Linear `prefix.{weight,bias}` of `n` outputs.
#[allow(clippy::too_many_arguments)]
fn linear_back(
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
    let (w, b) = (format!("{prefix}.weight"), format!("{prefix}.bias"));
    lin_back(wv, grads, (&w, &b), (0, n), x, dy, rows, k, dx)
}

/// The backward of `norm(...)` (LayerNorm `prefix` with affine): `dh += ∂/∂x` from `du`.
#[allow(clippy::too_many_arguments)]
fn norm_back(
    wv: &WeightView,
    grads: &mut Grads,
    prefix: &str,
    (n, r): (&[f32], &[f32]),
    du: &[f32],
    d: usize,
    dh: &mut [f32],
    accumulate: bool,
) -> Result<()> {
    let (wn, bn) = (format!("{prefix}.weight"), format!("{prefix}.bias"));
    let w = wv.get(&wn)?;
    let mut dn = vec![0f32; n.len()];
    let (mut dw, mut db) = (vec![0f32; d], vec![0f32; d]);
    rows::affine_backward(n, w, du, d, &mut dn, &mut dw, &mut db);
    grads.add(&wn, &dw);
    grads.add(&bn, &db);
    ops::layer_norm_backward(n, r, &dn, d, dh, accumulate);
    Ok(())
}

/// `dy ∘ mask` (a residual branch's gradient through its dropout).
fn through(dy: &[f32], mask: &[f32]) -> Vec<f32> {
    let mut v = dy.to_vec();
    rows::mask_in_place(&mut v, mask);
    v
}

/// The backward of the last [`super::forward`]: `dout` `[M, T, A]` = ∂loss/∂ε̂. Adds every
/// denoiser parameter's gradient to `grads` and returns ∂loss/∂cond `[N, To · F]`.
pub(crate) fn backward(
    s: &Shape,
    wv: &WeightView,
    cond: &[f32],
    dout: &[f32],
    w: &mut Work,
    grads: &mut Grads,
) -> Result<Vec<f32>> {
    let (d, tk, a, tc, to) = (s.d, s.tokens, s.action, s.tc(), s.obs_steps);
    let (m, n, repeat) = (w.samples, w.conds, w.repeat);
    let rows = m * tk;
    let mrows = m * tc;
    // Head and final norm.
    let mut du = vec![0f32; rows * d];
    linear_back(
        wv,
        grads,
        "model.head",
        &w.uf,
        dout,
        rows,
        d,
        a,
        Some((&mut du, false)),
    )?;
    let mut dh = vec![0f32; rows * d];
    norm_back(
        wv,
        grads,
        "model.ln_f",
        (&w.nf, &w.rf),
        &du,
        d,
        &mut dh,
        false,
    )?;
    let mut dmem = vec![0f32; mrows * d];
    let mut dbig = vec![0f32; rows * 4 * d];
    let mut dsmall = vec![0f32; rows * d];
    let mut dq = vec![0f32; rows * d];
    let (sa, ca) = (s.self_attn(), s.cross_attn());
    for (i, l) in w.layers.iter().enumerate().rev() {
        // FFN.
        let df2 = through(&dh, &l.drop3);
        linear_back(
            wv,
            grads,
            &layer(i, "linear2"),
            &l.gd,
            &df2,
            rows,
            4 * d,
            d,
            Some((&mut dbig, false)),
        )?;
        rows::mask_in_place(&mut dbig, &l.drop_f);
        ops::map_grad(&l.f1, &mut dbig, rows::gelu_erf_grad);
        linear_back(
            wv,
            grads,
            &layer(i, "linear1"),
            &l.u3,
            &dbig,
            rows,
            d,
            4 * d,
            Some((&mut du, false)),
        )?;
        norm_back(
            wv,
            grads,
            &layer(i, "norm3"),
            (&l.n3, &l.r3),
            &du,
            d,
            &mut dh,
            true,
        )?;
        // Cross-attention.
        let (w_in, b_in) = (
            layer(i, "multihead_attn.in_proj_weight"),
            layer(i, "multihead_attn.in_proj_bias"),
        );
        let da2 = through(&dh, &l.drop2);
        linear_back(
            wv,
            grads,
            &layer(i, "multihead_attn.out_proj"),
            &l.o2,
            &da2,
            rows,
            d,
            d,
            Some((&mut dsmall, false)),
        )?;
        let mut dkv = vec![0f32; mrows * 2 * d];
        attn::backward(
            ca, &l.q2, &l.kv, &l.p2, &l.drop_p2, &dsmall, &mut dq, &mut dkv,
        );
        lin_back(
            wv,
            grads,
            (&w_in, &b_in),
            (0, d),
            &l.u2,
            &dq,
            rows,
            d,
            Some((&mut du, false)),
        )?;
        lin_back(
            wv,
            grads,
            (&w_in, &b_in),
            (d, 2 * d),
            &w.mem,
            &dkv,
            mrows,
            d,
            Some((&mut dmem, true)),
        )?;
        norm_back(
            wv,
            grads,
            &layer(i, "norm2"),
            (&l.n2, &l.r2),
            &du,
            d,
            &mut dh,
            true,
        )?;
        // Self-attention.
        let da1 = through(&dh, &l.drop1);
        linear_back(
            wv,
            grads,
            &layer(i, "self_attn.out_proj"),
            &l.o1,
            &da1,
            rows,
            d,
            d,
            Some((&mut dsmall, false)),
        )?;
        let mut dkv = vec![0f32; rows * 2 * d];
        attn::backward(
            sa, &l.qkv, &l.qkv, &l.p1, &l.drop_p1, &dsmall, &mut dq, &mut dkv,
        );
        let mut dqkv = vec![0f32; rows * 3 * d];
        for ((dst, q), kv) in dqkv
            .chunks_exact_mut(3 * d)
            .zip(dq.chunks_exact(d))
            .zip(dkv.chunks_exact(2 * d))
        {
            dst[..d].copy_from_slice(q);
            dst[d..].copy_from_slice(kv);
        }
        lin_back(
            wv,
            grads,
            (
                &layer(i, "self_attn.in_proj_weight"),
                &layer(i, "self_attn.in_proj_bias"),
            ),
            (0, 3 * d),
            &l.u1,
            &dqkv,
            rows,
            d,
            Some((&mut du, false)),
        )?;
        norm_back(
            wv,
            grads,
            &layer(i, "norm1"),
            (&l.n1, &l.r1),
            &du,
            d,
            &mut dh,
            true,
        )?;
    }
    // Action tokens: position and input embeddings.
    {
        let len = wv.get("model.pos_emb")?.len();
        let dpos = grads.slot("model.pos_emb", len);
        for sample in dh.chunks_exact(tk * d) {
            ops::add_into(dpos, sample);
        }
    }
    linear_back(wv, grads, "model.input_emb", &w.x, &dh, rows, a, d, None)?;
    // The memory: condition MLP, condition positions, observation embedding.
    let mut de1 = vec![0f32; mrows * 4 * d];
    linear_back(
        wv,
        grads,
        "model.encoder.2",
        &w.e1m,
        &dmem,
        mrows,
        4 * d,
        d,
        Some((&mut de1, false)),
    )?;
    ops::map_grad(&w.e1, &mut de1, rows::mish_grad);
    let mut dmx = vec![0f32; mrows * d];
    linear_back(
        wv,
        grads,
        "model.encoder.0",
        &w.mx,
        &de1,
        mrows,
        d,
        4 * d,
        Some((&mut dmx, false)),
    )?;
    {
        let len = wv.get("model.cond_pos_emb")?.len();
        let dcpos = grads.slot("model.cond_pos_emb", len);
        for sample in dmx.chunks_exact(tc * d) {
            ops::add_into(dcpos, sample);
        }
    }
    let mut dcemb = vec![0f32; n * to * d];
    for (i, sample) in dmx.chunks_exact(tc * d).enumerate() {
        let dst = &mut dcemb[(i / repeat) * to * d..][..to * d];
        for (o, v) in dst.iter_mut().zip(&sample[d..]) {
            *o += v;
        }
    }
    let mut dcond = vec![0f32; n * to * s.obs_dim];
    linear_back(
        wv,
        grads,
        "model.cond_obs_emb",
        cond,
        &dcemb,
        n * to,
        s.obs_dim,
        d,
        Some((&mut dcond, false)),
    )?;
    Ok(dcond)
}
