//! Fused CPU kernels with their own backward passes for the encoder's hot spots, on
//! channels-last (NHWC) activations: GroupNorm (optionally followed by ReLU; in `group_norm.rs`,
//! re-exported here), the stem's
//! 3×3 / stride-2 max-pool, and a residual block's `relu(a + b)`. Composed of candle ops, a
//! GroupNorm is ~12 passes over the activation in the forward pass and more in the backward,
//! each allocating; these are two or three, parallel over samples. Other devices use composed
//! ops on NCHW activations ([`group_norm_nchw`]).

use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Shape, Tensor};
use rayon::prelude::*;

use crate::model::cpu::{values, vectorized};

#[path = "group_norm.rs"]
mod group_norm;
pub(crate) use group_norm::{group_norm_backward, group_norm_forward, Dims};
pub use group_norm::{group_norm_nchw, group_norm_nhwc};

/// `MaxPool2d(3, stride=2, padding=1)` (PyTorch's −∞ padding) of a channels-last
/// `[N, H, W, C]`.
pub fn max_pool_3x3_s2_nhwc(x: &Tensor) -> candle_core::Result<Tensor> {
    x.contiguous()?.apply_op1(MaxPool)
}

/// Output size of a 3×3 / stride 2 / padding 1 pool.
pub(crate) fn pooled(side: usize) -> usize {
    (side - 1) / 2 + 1
}

/// Whether `v` replaces `best` as a window's maximum: larger, or a NaN (which propagates,
/// as in PyTorch); ties keep the first in row-major order. Branch-free, so the loops over
/// channels below vectorize.
#[inline]
fn replaces(v: f32, best: f32) -> bool {
    (v > best) | (v.is_nan() & !best.is_nan())
}

/// Calls `f(oy, ox, pos)` for each output position of a 3×3 / stride 2 / padding 1 pool over
/// `h × w` and each input position `pos = y · w + x` of its window, in row-major order.
#[inline]
fn windows(h: usize, w: usize, mut f: impl FnMut(usize, usize, usize, bool)) {
    for oy in 0..pooled(h) {
        for ox in 0..pooled(w) {
            let mut first = true;
            for y in (2 * oy).saturating_sub(1)..(2 * oy + 2).min(h) {
                for x in (2 * ox).saturating_sub(1)..(2 * ox + 2).min(w) {
                    f(oy, ox, y * w + x, first);
                    first = false;
                }
            }
        }
    }
}

/// For each output value of one sample (`x` `[H, W, C]`), the flat index (in the sample) of
/// the input it takes: the first maximum of its window in row-major order, as PyTorch; a NaN
/// propagates.
fn argmax(x: &[f32], h: usize, w: usize, c: usize) -> Vec<u32> {
    let ow = pooled(w);
    let mut idx = vec![0u32; pooled(h) * ow * c];
    let mut best = vec![f32::NEG_INFINITY; c];
    windows(h, w, |oy, ox, pos, first| {
        let at = &mut idx[(oy * ow + ox) * c..(oy * ow + ox + 1) * c];
        let base = pos * c;
        let v = &x[base..base + c];
        for (ch, ((b, a), &vi)) in best.iter_mut().zip(at.iter_mut()).zip(v).enumerate() {
            let take = first | replaces(vi, *b);
            *b = if take { vi } else { *b };
            *a = if take { (base + ch) as u32 } else { *a };
        }
    });
    idx
}

/// The 3×3 / stride 2 / padding 1 max-pool of channels-last samples of `(h, w, c)`, in
/// parallel over samples: each output is the value [`argmax`] picks, found without the index.
pub(crate) fn max_pool_forward((h, w, c): (usize, usize, usize), x: &[f32], y: &mut [f32]) {
    let (oh, ow) = (pooled(h), pooled(w));
    y.par_chunks_mut(oh * ow * c)
        .zip(x.par_chunks(h * w * c))
        .for_each(|(y, x)| {
            vectorized(|| {
                windows(h, w, |oy, ox, pos, first| {
                    let out = &mut y[(oy * ow + ox) * c..(oy * ow + ox + 1) * c];
                    let v = &x[pos * c..(pos + 1) * c];
                    for (o, &vi) in out.iter_mut().zip(v) {
                        *o = if first | replaces(vi, *o) { vi } else { *o };
                    }
                });
            })
        });
}

/// `dx` (overwritten) of [`max_pool_forward`] from `x` and `dy`: each output's gradient to the
/// input it took.
pub(crate) fn max_pool_backward(
    (h, w, c): (usize, usize, usize),
    x: &[f32],
    dy: &[f32],
    dx: &mut [f32],
) {
    let per = pooled(h) * pooled(w) * c;
    dx[..x.len()]
        .par_chunks_mut(h * w * c)
        .zip(x.par_chunks(h * w * c).zip(dy.par_chunks(per)))
        .for_each(|(dx, (x, dy))| {
            vectorized(|| {
                dx.fill(0.0);
                for (&k, &g) in argmax(x, h, w, c).iter().zip(dy) {
                    dx[k as usize] += g;
                }
            })
        });
}

struct MaxPool;

impl CustomOp1 for MaxPool {
    fn name(&self) -> &'static str {
        "scaledp-max-pool-nhwc"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> candle_core::Result<(CpuStorage, Shape)> {
        let (n, h, w, c) = l.shape().dims4()?;
        let x = values(s, l)?;
        let (oh, ow) = (pooled(h), pooled(w));
        let mut y = vec![0f32; n * oh * ow * c];
        max_pool_forward((h, w, c), x, &mut y);
        Ok((CpuStorage::F32(y), Shape::from((n, oh, ow, c))))
    }

    fn bwd(&self, x: &Tensor, _res: &Tensor, grad: &Tensor) -> candle_core::Result<Option<Tensor>> {
        Ok(Some(x.apply_op2_no_bwd(&grad.contiguous()?, &MaxPoolGrad)?))
    }
}

/// `dx` of [`MaxPool`] from `x` (arg 1) and `dy` (arg 2).
struct MaxPoolGrad;

impl CustomOp2 for MaxPoolGrad {
    fn name(&self) -> &'static str {
        "scaledp-max-pool-nhwc-grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (_, h, w, c) = l1.shape().dims4()?;
        let (x, dy) = (values(s1, l1)?, values(s2, l2)?);
        let mut dx = vec![0f32; x.len()];
        max_pool_backward((h, w, c), x, dy, &mut dx);
        Ok((CpuStorage::F32(dx), l1.shape().clone()))
    }
}

/// `relu(a + b)` of two tensors of one shape (a residual block's output), one pass; its
/// backward passes the gradient where the output is positive to both inputs.
pub fn add_relu(a: &Tensor, b: &Tensor) -> candle_core::Result<Tensor> {
    a.contiguous()?.apply_op2(&b.contiguous()?, AddRelu)
}

/// `y = relu(a + b)`, in parallel.
pub(crate) fn add_relu_forward(a: &[f32], b: &[f32], y: &mut [f32]) {
    y[..a.len()]
        .par_chunks_mut(1 << 14)
        .zip(a.par_chunks(1 << 14).zip(b.par_chunks(1 << 14)))
        .for_each(|(y, (a, b))| {
            vectorized(|| {
                for ((y, &a), &b) in y.iter_mut().zip(a).zip(b) {
                    *y = (a + b).max(0.0);
                }
            })
        });
}

/// `dx = dy` where `y > 0`, else 0 (the backward of a ReLU from its output), in parallel.
pub(crate) fn relu_backward(y: &[f32], dy: &[f32], dx: &mut [f32]) {
    dx[..y.len()]
        .par_chunks_mut(1 << 14)
        .zip(y.par_chunks(1 << 14).zip(dy.par_chunks(1 << 14)))
        .for_each(|(dx, (y, dy))| {
            vectorized(|| {
                for ((dx, &y), &g) in dx.iter_mut().zip(y).zip(dy) {
                    *dx = if y > 0.0 { g } else { 0.0 };
                }
            })
        });
}

struct AddRelu;

impl CustomOp2 for AddRelu {
    fn name(&self) -> &'static str {
        "scaledp-add-relu"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (a, b) = (values(s1, l1)?, values(s2, l2)?);
        if a.len() != b.len() {
            candle_core::bail!("add_relu: {:?} and {:?}", l1.dims(), l2.dims());
        }
        let mut y = vec![0f32; a.len()];
        add_relu_forward(a, b, &mut y);
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        _a: &Tensor,
        _b: &Tensor,
        res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let g = res.apply_op2_no_bwd(&grad.contiguous()?, &ReluGrad)?;
        Ok((Some(g.clone()), Some(g)))
    }
}

/// `dy` where `y` (arg 1) is positive, else 0; `dy` is arg 2.
struct ReluGrad;

impl CustomOp2 for ReluGrad {
    fn name(&self) -> &'static str {
        "scaledp-relu-grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let (y, dy) = (values(s1, l1)?, values(s2, l2)?);
        let mut dx = vec![0f32; y.len()];
        relu_backward(y, dy, &mut dx);
        Ok((CpuStorage::F32(dx), l1.shape().clone()))
    }
}

#[cfg(test)]
#[path = "fused_tests.rs"]
mod tests;
