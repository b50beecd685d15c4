//! `nn.MultiheadAttention`'s core for DP-T: queries of one sequence attending to keys and values
//! of another (the memory) or of the same one, under DP-T's masks, with dropout on the
//! attention weights, and its backward. Queries, keys and values are read in place from the
//! projections' rows (the fused self-attention `[T, 3d]` rows, or separate query rows and
//! `[S, 2d]` key/value rows); samples run in parallel.

use rayon::prelude::*;

use crate::engine::attention::{axpy, dot};
use crate::model::cpu::vectorized;

/// Which keys a query sees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mask {
    /// All of them.
    None,
    /// Keys ≤ the query (DP-T's `mask`).
    Causal,
    /// Condition token s for action t when t ≥ s − 1 (DP-T's `memory_mask`: token 0 is the
    /// diffusion step, token s the observation step s − 1).
    Memory,
}

impl Mask {
    #[inline]
    fn sees(self, i: usize, j: usize) -> bool {
        match self {
            Mask::None => true,
            Mask::Causal => j <= i,
            Mask::Memory => i + 1 >= j,
        }
    }
}

/// The shape and layout of one attention call.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// Queries per sample.
    pub tq: usize,
    /// Keys per sample.
    pub tk: usize,
    /// Model width d.
    pub d: usize,
    pub heads: usize,
    /// Values per query row of the query buffer, and where q starts in it.
    pub q_stride: usize,
    pub q_off: usize,
    /// Values per key row of the key/value buffer, and where k and v start in it.
    pub kv_stride: usize,
    pub k_off: usize,
    pub v_off: usize,
    pub mask: Mask,
}

impl Layout {
    fn hd(&self) -> usize {
        self.d / self.heads
    }
    /// Attention weights per sample: heads · tq · tk.
    pub fn probs_per_sample(&self) -> usize {
        self.heads * self.tq * self.tk
    }
}

/// `o` `[S, tq, d]` from queries `q` and keys/values `kv`; the softmax weights go to `probs`
/// `[S, H, tq, tk]` (kept for the backward); `drop` (same shape, or empty) multiplies them on
/// the way to the output.
pub(crate) fn forward(
    a: Layout,
    q: &[f32],
    kv: &[f32],
    o: &mut [f32],
    probs: &mut [f32],
    drop: &[f32],
) {
    let (hd, d) = (a.hd(), a.d);
    let scale = (hd as f32).powf(-0.5);
    let per_p = a.probs_per_sample();
    let samples = o.len() / (a.tq * d);
    let drops: Vec<&[f32]> = if drop.is_empty() {
        vec![&[]; samples]
    } else {
        drop.chunks(per_p).collect()
    };
    o[..samples * a.tq * d]
        .par_chunks_mut(a.tq * d)
        .zip(q.par_chunks(a.tq * a.q_stride))
        .zip(kv.par_chunks(a.tk * a.kv_stride))
        .zip(probs[..samples * per_p].par_chunks_mut(per_p).zip(drops))
        .for_each(|(((os, qs), kvs), (ps, ds))| {
            vectorized(|| {
                for h in 0..a.heads {
                    for i in 0..a.tq {
                        let qi = &qs[i * a.q_stride + a.q_off + h * hd..][..hd];
                        let row = &mut ps[(h * a.tq + i) * a.tk..][..a.tk];
                        let mut max = f32::NEG_INFINITY;
                        for (j, r) in row.iter_mut().enumerate() {
                            if !a.mask.sees(i, j) {
                                *r = f32::NEG_INFINITY;
                                continue;
                            }
                            let kj = &kvs[j * a.kv_stride + a.k_off + h * hd..][..hd];
                            *r = dot(qi, kj) * scale;
                            max = max.max(*r);
                        }
                        let mut sum = 0f32;
                        for r in row.iter_mut() {
                            *r = (*r - max).exp();
                            sum += *r;
                        }
                        for r in row.iter_mut() {
                            *r /= sum;
                        }
                        let out = &mut os[i * d + h * hd..][..hd];
                        out.fill(0.0);
                        for (j, &pj) in row.iter().enumerate() {
                            let w = if ds.is_empty() {
                                pj
                            } else {
                                pj * ds[(h * a.tq + i) * a.tk + j]
                            };
                            if w == 0.0 {
                                continue;
                            }
                            let v = &kvs[j * a.kv_stride + a.v_off + h * hd..][..hd];
                            for (o, v) in out.iter_mut().zip(v) {
                                *o += w * v;
                            }
                        }
                    }
                }
            })
        });
}

/// The backward: `dq` `[S, tq, d]` and `dkv` `[S, tk, 2d]` (k then v per key row) from `do_`
/// `[S, tq, d]`, the forward's inputs, weights and dropout mask.
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward(
    a: Layout,
    q: &[f32],
    kv: &[f32],
    probs: &[f32],
    drop: &[f32],
    do_: &[f32],
    dq: &mut [f32],
    dkv: &mut [f32],
) {
    let (hd, d, tq, tk) = (a.hd(), a.d, a.tq, a.tk);
    let scale = (hd as f32).powf(-0.5);
    let per_p = a.probs_per_sample();
    let samples = do_.len() / (tq * d);
    let drops: Vec<&[f32]> = if drop.is_empty() {
        vec![&[]; samples]
    } else {
        drop.chunks(per_p).collect()
    };
    dq[..samples * tq * d]
        .par_chunks_mut(tq * d)
        .zip(dkv[..samples * tk * 2 * d].par_chunks_mut(tk * 2 * d))
        .zip(
            q.par_chunks(tq * a.q_stride)
                .zip(kv.par_chunks(tk * a.kv_stride)),
        )
        .zip(
            probs
                .par_chunks(per_p)
                .zip(do_.par_chunks(tq * d))
                .zip(drops),
        )
        .for_each(|(((dqs, dkvs), (qs, kvs)), ((ps, dos), ds))| {
            vectorized(|| {
                dqs.fill(0.0);
                dkvs.fill(0.0);
                let mut dsr = vec![0f32; tk];
                for h in 0..a.heads {
                    for i in 0..tq {
                        let dout = &dos[i * d + h * hd..][..hd];
                        let prow = &ps[(h * tq + i) * tk..][..tk];
                        let mrow = (!ds.is_empty()).then(|| &ds[(h * tq + i) * tk..][..tk]);
                        // dP' = dO · Vᵀ; dP = dP' ∘ mask; dV += (P ∘ mask)ᵀ dO;
                        // dS = P ∘ (dP − Σ P ∘ dP) · scale.
                        let mut pdp = 0f32;
                        for j in 0..tk {
                            if prow[j] == 0.0 {
                                dsr[j] = 0.0;
                                continue;
                            }
                            let m = mrow.map_or(1.0, |r| r[j]);
                            let v = &kvs[j * a.kv_stride + a.v_off + h * hd..][..hd];
                            let dp = dot(dout, v) * m;
                            dsr[j] = dp;
                            pdp += prow[j] * dp;
                            let w = prow[j] * m;
                            if w != 0.0 {
                                let dv = &mut dkvs[j * 2 * d + d + h * hd..][..hd];
                                axpy(dv, w, dout);
                            }
                        }
                        let qi = &qs[i * a.q_stride + a.q_off + h * hd..][..hd];
                        for j in 0..tk {
                            let g = prow[j] * (dsr[j] - pdp) * scale;
                            if g == 0.0 {
                                continue;
                            }
                            let kj = &kvs[j * a.kv_stride + a.k_off + h * hd..][..hd];
                            axpy(&mut dqs[i * d + h * hd..][..hd], g, kj);
                            axpy(&mut dkvs[j * 2 * d + h * hd..][..hd], g, qi);
                        }
                    }
                }
            })
        });
}
