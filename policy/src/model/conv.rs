//! 2-D convolution for training on the CPU, channels-last (NHWC): im2col + one large GEMM per
//! chunk of samples, with its own backward pass.
//!
//! candle 0.11's CPU `conv2d` is differentiable, but its input gradient goes through
//! `conv_transpose2d`, a loop of dot products without GEMM, and its weight gradient through a
//! convolution whose kernel is the whole output map. Here all three products are GEMMs over a
//! patch matrix laid out `[samples · pixels, K]`, K = kh·kw·C_in in (i, j, c) order:
//!
//! - forward: `y = patches · W'ᵀ` (W' is the kernel reordered to `[C_out, kh, kw, C_in]`),
//! - input gradient: `dpatches = dy · W'`, scattered back by col2im,
//! - weight gradient: `dW' = dyᵀ · patches` (patches recomputed, never stored).
//!
//! Channels-last, a patch row is kh·kw contiguous runs of C_in values, the GEMM's output rows
//! are the output's pixels (no transposition), and a 1×1 stride-1 convolution needs no patch
//! matrix at all. The patch matrix is built for a bounded chunk of samples at a time in a
//! buffer reused between calls. A training batch's chunks run side by side, one per thread,
//! each with its own patch matrix and a single-threaded GEMM (see [`Plan`]).
//!
//! [`forward`], [`grad_input`] and [`grad_weight`] hand the 3×3 stride-1 convolutions of a
//! map large enough to [`winograd`] (2.25× fewer multiplications), and those of the small
//! maps to [`taps`] (which skips the padding); `*_im2col` are the general kernels, which the
//! tests of both hold them to.

use rayon::prelude::*;

use crate::model::cpu::{gemm, product, side_by_side, sum_in_order, vectorized, with_scratch};
pub(crate) use crate::model::geom::Geom;
use crate::model::{taps, winograd};

/// Largest patch matrix built at once (f32 values): 8 M = 32 MB.
const MAX_PATCH_VALUES: usize = 8 << 20;

/// The patch matrix a thread's chunk aims at when chunks run side by side (f32 values):
/// 256 K = 1 MiB, a core's L2 on the Zen 4 this was measured on. A patch matrix is written
/// once and read back by the GEMM; kept in cache, neither pass goes to memory. Chunks of
/// 64 samples (16–60 MB) ran the recipe's 32-channel 15×15 layer in 6 ms a product, chunks
/// this size in 3 (`conv_ops` example).
const CACHED_PATCH_VALUES: usize = 1 << 18;

#[path = "conv_op.rs"]
mod op;
pub use op::conv2d_nhwc;

impl Geom {
    /// Samples per chunk so that a chunk's patch matrix stays under the limit.
    fn chunk(&self) -> usize {
        (MAX_PATCH_VALUES / (self.pixels() * self.k()).max(1)).clamp(1, self.b.max(1))
    }
    /// Whether the patch matrix is the input itself (1×1, stride 1, no padding).
    fn pointwise(&self) -> bool {
        self.kh == 1 && self.kw == 1 && self.stride == 1 && self.padding == 0
    }
    /// Where (in one NHWC sample) the kw taps of kernel row `i` at output (oy, ox) start, when
    /// all of them are inside the input: they are then kw·C_in consecutive values.
    #[inline]
    fn row_run(&self, oy: usize, ox: usize, i: usize) -> Option<usize> {
        let y = (oy * self.stride + i).checked_sub(self.padding)?;
        let x = (ox * self.stride).checked_sub(self.padding)?;
        (y < self.h && x + self.kw <= self.w).then_some((y * self.w + x) * self.c_in)
    }
    /// The input row and column of kernel tap (i, j) at output (oy, ox), if inside.
    #[inline]
    fn tap(&self, oy: usize, ox: usize, i: usize, j: usize) -> Option<(usize, usize)> {
        let y = (oy * self.stride + i).checked_sub(self.padding)?;
        let x = (ox * self.stride + j).checked_sub(self.padding)?;
        (y < self.h && x < self.w).then_some((y, x))
    }
}

/// `[C_out, C_in, kh, kw]` → `[C_out, kh, kw, C_in]`.
pub(crate) fn oihw_to_ohwi(g: &Geom, w: &[f32]) -> Vec<f32> {
    kernel_to_ohwi(g.c_in, g.kh * g.kw, w)
}

/// A row-major `[rows, cols]` matrix transposed to `[cols, rows]`: a `[C_out, kh, kw, C_in]`
/// kernel (`cols` = kh·kw·C_in) to `[kh, kw, C_in, C_out]`, or a Linear weight `[out, in]` to
/// `[in, out]` — the layouts a forward pass with few rows multiplies in place (the GEMM
/// repacks the others on every call).
pub(crate) fn transposed(rows: usize, cols: usize, w: &[f32]) -> Vec<f32> {
    let mut out = vec![0f32; rows * cols];
    for (o, row) in w.chunks_exact(cols).take(rows).enumerate() {
        for (i, v) in row.iter().enumerate() {
            out[i * rows + o] = *v;
        }
    }
    out
}

/// [`oihw_to_ohwi`] of a kernel with `ci` input channels and `kk` taps.
pub(crate) fn kernel_to_ohwi(ci: usize, kk: usize, w: &[f32]) -> Vec<f32> {
    let mut out = vec![0f32; w.len()];
    for (o, dst) in out.chunks_mut(ci * kk).enumerate() {
        let src = &w[o * ci * kk..(o + 1) * ci * kk];
        for c in 0..ci {
            for t in 0..kk {
                dst[t * ci + c] = src[c * kk + t];
            }
        }
    }
    out
}

/// `[C_out, kh, kw, C_in]` → `[C_out, C_in, kh, kw]`.
pub(crate) fn ohwi_to_oihw(g: &Geom, w: &[f32]) -> Vec<f32> {
    let (ci, kk) = (g.c_in, g.kh * g.kw);
    let mut out = vec![0f32; w.len()];
    for (o, dst) in out.chunks_mut(ci * kk).enumerate() {
        let src = &w[o * ci * kk..(o + 1) * ci * kk];
        for c in 0..ci {
            for t in 0..kk {
                dst[c * kk + t] = src[t * ci + c];
            }
        }
    }
    out
}

/// Patches of the `n` samples `x` (NHWC) into `cols` `[n · P, K]`, K ordered (i, j, c);
/// across rayon's threads when `par`.
fn im2col(g: &Geom, x: &[f32], n: usize, cols: &mut [f32], par: bool) {
    let (oh, ow, k, ci) = (g.out_h(), g.out_w(), g.k(), g.c_in);
    let cols = &mut cols[..n * oh * ow * k];
    let fill = |(row, dst): (usize, &mut [f32])| {
        let (s, oy) = (row / oh, row % oh);
        let xs = &x[s * g.per_in()..(s + 1) * g.per_in()];
        for ox in 0..ow {
            let d = &mut dst[ox * k..(ox + 1) * k];
            for i in 0..g.kh {
                let run = &mut d[i * g.kw * ci..(i + 1) * g.kw * ci];
                // The kw taps of a kernel row are kw neighbouring pixels of one input row:
                // one copy of kw·C_in values when all are inside.
                if let Some(at) = g.row_run(oy, ox, i) {
                    run.copy_from_slice(&xs[at..at + g.kw * ci]);
                    continue;
                }
                for j in 0..g.kw {
                    let t = &mut run[j * ci..(j + 1) * ci];
                    match g.tap(oy, ox, i, j) {
                        Some((y, xx)) => {
                            let at = (y * g.w + xx) * ci;
                            t.copy_from_slice(&xs[at..at + ci]);
                        }
                        None => t.fill(0.0),
                    }
                }
            }
        }
    };
    if par {
        cols.par_chunks_mut(ow * k)
            .enumerate()
            .for_each(|r| vectorized(|| fill(r)));
    } else {
        vectorized(|| cols.chunks_mut(ow * k).enumerate().for_each(fill));
    }
}

/// Adds patch gradients `cols` `[n · P, K]` back into `dx` (`n` samples, NHWC); across
/// rayon's threads when `par`.
fn col2im(g: &Geom, cols: &[f32], dx: &mut [f32], par: bool) {
    let (oh, ow, k, ci) = (g.out_h(), g.out_w(), g.k(), g.c_in);
    let add = |(s, xs): (usize, &mut [f32])| {
        let cs = &cols[s * oh * ow * k..(s + 1) * oh * ow * k];
        for oy in 0..oh {
            for ox in 0..ow {
                let src = &cs[(oy * ow + ox) * k..(oy * ow + ox + 1) * k];
                for i in 0..g.kh {
                    if let Some(at) = g.row_run(oy, ox, i) {
                        let run = &src[i * g.kw * ci..(i + 1) * g.kw * ci];
                        for (d, v) in xs[at..at + g.kw * ci].iter_mut().zip(run) {
                            *d += v;
                        }
                        continue;
                    }
                    for j in 0..g.kw {
                        if let Some((y, xx)) = g.tap(oy, ox, i, j) {
                            let at = (y * g.w + xx) * ci;
                            let t = &src[(i * g.kw + j) * ci..(i * g.kw + j + 1) * ci];
                            for (d, v) in xs[at..at + ci].iter_mut().zip(t) {
                                *d += v;
                            }
                        }
                    }
                }
            }
        }
    };
    if par {
        dx.par_chunks_mut(g.per_in())
            .enumerate()
            .for_each(|s| vectorized(|| add(s)));
    } else {
        vectorized(|| dx.chunks_mut(g.per_in()).enumerate().for_each(add));
    }
}

/// How a convolution's samples are cut into chunks, each one patch matrix and one GEMM.
#[derive(Clone, Copy)]
struct Plan {
    /// Samples per chunk (the last may have fewer).
    step: usize,
    /// Chunks run side by side, one per thread, each op inside on that thread alone; else one
    /// after another, each op split across the threads.
    parallel: bool,
}

impl Plan {
    /// Side by side when there are samples enough for several per thread (a training batch):
    /// one GEMM split across threads synchronizes them at every depth block of the product,
    /// and the weight gradient's (C_out × K outputs, a reduction over all pixels) scaled to
    /// about 1.2 of 2 cores. A few samples (inference) keep the split GEMM.
    fn new(g: &Geom) -> Self {
        let threads = rayon::current_num_threads();
        if !side_by_side(g.b) {
            return Plan {
                step: g.chunk(),
                parallel: false,
            };
        }
        // A chunk's patch matrix fits in cache, but holds at least 4 kernels' worth of values:
        // the forward and input-gradient GEMMs pack the kernel again for every chunk (a 5×5
        // layer of 256 channels ran 25 % slower with chunks of 1 MiB than of 4 kernels).
        // Each thread holds its own patch matrix: together they stay under the limit. A
        // multiple of `threads` chunks keeps the threads evenly loaded.
        let aim = CACHED_PATCH_VALUES.max(4 * g.k() * g.c_out);
        let limit = (aim.min(MAX_PATCH_VALUES / threads) / (g.pixels() * g.k()).max(1)).max(1);
        let chunks = g.b.div_ceil(limit).next_multiple_of(threads);
        Plan {
            step: g.b.div_ceil(chunks),
            parallel: true,
        }
    }

    /// The product for one chunk ([`product`]): on the calling thread when chunks run side
    /// by side.
    fn gemm(&self, dims: [usize; 3], a: (&[f32], bool), b: (&[f32], bool), c: &mut [f32]) {
        product(!self.parallel, dims, a, b, c, false);
    }

    /// Runs `f(first sample, its part of out, a patch buffer)` for every chunk, `out` holding
    /// `per_sample` values per sample.
    fn run(
        &self,
        g: &Geom,
        out: &mut [f32],
        per_sample: usize,
        f: impl Fn(usize, &mut [f32], &mut [f32]) + Sync,
    ) {
        let patch = g.pixels() * g.k();
        let parts = out[..g.b * per_sample].chunks_mut(self.step * per_sample);
        if self.parallel {
            let parts = out[..g.b * per_sample].par_chunks_mut(self.step * per_sample);
            parts.enumerate().for_each(|(c, o)| {
                let n = o.len() / per_sample;
                with_scratch(n * patch, |cols| f(c * self.step, o, cols));
            });
        } else {
            with_scratch(self.step * patch, |cols| {
                for (c, o) in parts.enumerate() {
                    f(c * self.step, o, cols);
                }
            });
        }
    }
}

/// `out` `[B, H', W', C_out]` = the convolution of `x` (NHWC) with `wp`: `[C_out, kh, kw, C_in]`
/// (see [`oihw_to_ohwi`]), or `[kh, kw, C_in, C_out]` when `hwio` (see [`transposed`]).
pub(crate) fn forward(g: &Geom, x: &[f32], wp: &[f32], hwio: bool, out: &mut [f32]) {
    if !hwio && winograd::applies(g) {
        return winograd::forward(g, x, wp, out, false);
    }
    if !hwio && taps::applies(g) {
        return taps::forward(g, x, wp, out);
    }
    forward_im2col(g, x, wp, hwio, out);
}

/// [`forward`] by im2col + GEMM, whatever the geometry.
pub(crate) fn forward_im2col(g: &Geom, x: &[f32], wp: &[f32], hwio: bool, out: &mut [f32]) {
    let (p, k, co) = (g.pixels(), g.k(), g.c_out);
    if g.pointwise() {
        gemm(g.b * p, co, k, x, false, wp, !hwio, out, false);
        return;
    }
    let plan = Plan::new(g);
    plan.run(g, out, p * co, |s0, dst, cols| {
        let n = dst.len() / (p * co);
        let xs = &x[s0 * g.per_in()..(s0 + n) * g.per_in()];
        im2col(g, xs, n, cols, !plan.parallel);
        plan.gemm([n * p, co, k], (cols, false), (wp, !hwio), dst);
    });
}

/// `dx` (NHWC, `B · per_in` values) from `dy` and `wp`; `accumulate` adds to `dx`.
pub(crate) fn grad_input(g: &Geom, dy: &[f32], wp: &[f32], dx: &mut [f32], accumulate: bool) {
    if winograd::applies(g) {
        return winograd::grad_input(g, dy, wp, dx, accumulate);
    }
    if taps::applies(g) {
        return taps::grad_input(g, dy, wp, dx, accumulate);
    }
    grad_input_im2col(g, dy, wp, dx, accumulate);
}

/// [`grad_input`] by GEMM + col2im, whatever the geometry.
pub(crate) fn grad_input_im2col(
    g: &Geom,
    dy: &[f32],
    wp: &[f32],
    dx: &mut [f32],
    accumulate: bool,
) {
    let (p, k, co) = (g.pixels(), g.k(), g.c_out);
    if g.pointwise() {
        gemm(g.b * p, k, co, dy, false, wp, false, dx, accumulate);
        return;
    }
    let plan = Plan::new(g);
    plan.run(g, dx, g.per_in(), |s0, dxs, cols| {
        let n = dxs.len() / g.per_in();
        if !accumulate {
            dxs.fill(0.0);
        }
        let dys = &dy[s0 * p * co..(s0 + n) * p * co];
        plan.gemm([n * p, k, co], (dys, false), (wp, false), cols);
        col2im(g, cols, dxs, !plan.parallel);
    });
}

/// `dwp` (`[C_out, kh, kw, C_in]`, overwritten) from `x` and `dy`.
pub(crate) fn grad_weight(g: &Geom, x: &[f32], dy: &[f32], dwp: &mut [f32]) {
    if winograd::applies(g) {
        return winograd::grad_weight(g, x, dy, dwp);
    }
    if taps::applies(g) {
        return taps::grad_weight(g, x, dy, dwp);
    }
    grad_weight_im2col(g, x, dy, dwp);
}

/// [`grad_weight`] by im2col + GEMM, whatever the geometry.
pub(crate) fn grad_weight_im2col(g: &Geom, x: &[f32], dy: &[f32], dwp: &mut [f32]) {
    let (p, k, co) = (g.pixels(), g.k(), g.c_out);
    if g.pointwise() {
        gemm(co, k, g.b * p, dy, true, x, false, dwp, false);
        return;
    }
    let plan = Plan::new(g);
    // dW' of samples [s0, s0 + n) added to `acc`.
    let add = |acc: &mut [f32], s0: usize, n: usize, cols: &mut [f32], first: bool| {
        im2col(
            g,
            &x[s0 * g.per_in()..(s0 + n) * g.per_in()],
            n,
            cols,
            !plan.parallel,
        );
        let dys = &dy[s0 * p * co..(s0 + n) * p * co];
        product(
            !plan.parallel,
            [co, k, n * p],
            (dys, true),
            (cols, false),
            acc,
            !first,
        );
    };
    if !plan.parallel {
        with_scratch(plan.step * p * k, |cols| {
            for s0 in (0..g.b).step_by(plan.step) {
                add(dwp, s0, plan.step.min(g.b - s0), cols, s0 == 0);
            }
        });
        return;
    }
    // Each thread sums a fixed, contiguous share of the chunks in a buffer of its own, and the
    // buffers are added in order: the sums' order, and so the result to the last bit, does
    // not depend on which thread ran what (a resumed run repeats an uninterrupted one).
    let starts: Vec<usize> = (0..g.b).step_by(plan.step).collect();
    let threads = rayon::current_num_threads().min(starts.len()).max(1);
    let sums: Vec<Vec<f32>> = (0..threads)
        .into_par_iter()
        .map(|t| {
            let mut acc = vec![0f32; co * k];
            let share = &starts[t * starts.len() / threads..(t + 1) * starts.len() / threads];
            for (i, &s0) in share.iter().enumerate() {
                let n = plan.step.min(g.b - s0);
                with_scratch(n * p * k, |cols| add(&mut acc, s0, n, cols, i == 0));
            }
            acc
        })
        .collect();
    let dwp = &mut dwp[..co * k];
    sum_in_order(dwp, sums.iter().map(Vec::as_slice));
}

#[cfg(test)]
#[path = "conv_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "conv_check.rs"]
pub(crate) mod check;
