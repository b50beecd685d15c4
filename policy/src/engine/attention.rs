//! Multi-head self-attention over one sample's tokens, from the fused `qkv` rows (`[T, 3d]`:
//! q, k, v of every head side by side, PyTorch's `reshape(B, T, 3, H, hd)`), with its backward.
//! Sequences are short (C = 16 action tokens), so each (sample, head) is a few small loops;
//! samples run in parallel.

use rayon::prelude::*;

use crate::model::cpu::vectorized;

/// Shape of one attention call.
#[derive(Clone, Copy, Debug)]
pub(crate) struct AttnDims {
    /// Tokens per sample.
    pub tokens: usize,
    /// Model width d.
    pub d: usize,
    /// Heads.
    pub heads: usize,
    /// Token i sees tokens ≤ i only.
    pub causal: bool,
}

impl AttnDims {
    fn hd(&self) -> usize {
        self.d / self.heads
    }
    /// Probabilities per sample: heads · T · T.
    pub fn probs_per_sample(&self) -> usize {
        self.heads * self.tokens * self.tokens
    }
}

/// `o` `[S, T, d]` from `qkv` `[S, T, 3d]`; the softmax probabilities go to `probs`
/// `[S, H, T, T]` for the backward (pass an empty slice not to keep them: inference).
pub(crate) fn forward(a: AttnDims, qkv: &[f32], o: &mut [f32], probs: &mut [f32]) {
    let (t, d, hd) = (a.tokens, a.d, a.hd());
    let scale = (hd as f32).powf(-0.5);
    let keep = !probs.is_empty();
    let per_p = a.probs_per_sample();
    let samples = qkv.len() / (t * 3 * d);
    let mut scratch_p = Vec::new();
    let probs_chunks: Vec<&mut [f32]> = if keep {
        probs[..samples * per_p].chunks_mut(per_p).collect()
    } else {
        scratch_p.resize(samples * per_p, 0.0);
        scratch_p.chunks_mut(per_p).collect()
    };
    o[..samples * t * d]
        .par_chunks_mut(t * d)
        .zip(qkv.par_chunks(t * 3 * d))
        .zip(probs_chunks.into_par_iter())
        .for_each(|((os, x), ps)| {
            vectorized(|| {
                for h in 0..a.heads {
                    let p = &mut ps[h * t * t..(h + 1) * t * t];
                    for i in 0..t {
                        let q = &x[i * 3 * d + h * hd..][..hd];
                        let row = &mut p[i * t..(i + 1) * t];
                        let mut max = f32::NEG_INFINITY;
                        for (j, r) in row.iter_mut().enumerate() {
                            if a.causal && j > i {
                                *r = f32::NEG_INFINITY;
                                continue;
                            }
                            let k = &x[j * 3 * d + d + h * hd..][..hd];
                            let s = dot(q, k) * scale;
                            *r = s;
                            max = max.max(s);
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
                            if pj == 0.0 {
                                continue;
                            }
                            let v = &x[j * 3 * d + 2 * d + h * hd..][..hd];
                            for (o, v) in out.iter_mut().zip(v) {
                                *o += pj * v;
                            }
                        }
                    }
                }
            })
        });
}

/// The backward: `dqkv` `[S, T, 3d]` from `do_` `[S, T, d]`, the forward's `qkv` and `probs`.
pub(crate) fn backward(a: AttnDims, qkv: &[f32], probs: &[f32], do_: &[f32], dqkv: &mut [f32]) {
    let (t, d, hd) = (a.tokens, a.d, a.hd());
    let scale = (hd as f32).powf(-0.5);
    let per_p = a.probs_per_sample();
    dqkv[..qkv.len()]
        .par_chunks_mut(t * 3 * d)
        .zip(qkv.par_chunks(t * 3 * d))
        .zip(probs.par_chunks(per_p).zip(do_.par_chunks(t * d)))
        .for_each(|((dx, x), (ps, dos))| {
            vectorized(|| {
                dx.fill(0.0);
                let mut ds = vec![0f32; t * t];
                for h in 0..a.heads {
                    let p = &ps[h * t * t..(h + 1) * t * t];
                    // dP = dO · Vᵀ, then dS = P ∘ (dP − rowsum(P ∘ dP)); dV = Pᵀ · dO.
                    for i in 0..t {
                        let dout = &dos[i * d + h * hd..][..hd];
                        let prow = &p[i * t..(i + 1) * t];
                        let mut pdp = 0f32;
                        for j in 0..t {
                            let v = &x[j * 3 * d + 2 * d + h * hd..][..hd];
                            let dp = dot(dout, v);
                            ds[i * t + j] = dp;
                            pdp += prow[j] * dp;
                            if prow[j] != 0.0 {
                                let dv = &mut dx[j * 3 * d + 2 * d + h * hd..][..hd];
                                for (g, o) in dv.iter_mut().zip(dout) {
                                    *g += prow[j] * o;
                                }
                            }
                        }
                        for j in 0..t {
                            ds[i * t + j] = prow[j] * (ds[i * t + j] - pdp) * scale;
                        }
                    }
                    // dQ = dS · K, dK = dSᵀ · Q (a row of q and one of k are disjoint columns).
                    for i in 0..t {
                        for j in 0..t {
                            let g = ds[i * t + j];
                            if g == 0.0 {
                                continue;
                            }
                            let (qi, kj) = (i * 3 * d + h * hd, j * 3 * d + d + h * hd);
                            axpy(&mut dx[qi..qi + hd], g, &x[kj..kj + hd]);
                            axpy(&mut dx[kj..kj + hd], g, &x[qi..qi + hd]);
                        }
                    }
                }
            })
        });
}

/// `Σ a·b` over 16 lanes: an iterator's `sum` adds in order, one dependent addition per
/// element, which the compiler may not reorder into vector lanes (the attention's dot products
/// ran at one element per add's latency).
#[inline]
pub(crate) fn dot(a: &[f32], b: &[f32]) -> f32 {
    let (ca, cb) = (a.chunks_exact(16), b.chunks_exact(16));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0f32; 16];
    for (x, y) in ca.zip(cb) {
        for ((s, x), y) in acc.iter_mut().zip(x).zip(y) {
            *s += x * y;
        }
    }
    acc.iter().sum::<f32>() + tail
}

/// `y += a · x`.
#[inline]
pub(crate) fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}
