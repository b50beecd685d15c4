//! Convolutions of small maps (the trunk's last stages), tap by tap: `y = Σ_taps X_tap · W_tap`,
//! one product per kernel tap over the output pixels whose input pixel for that tap lies
//! inside the map, with the tap's `[C_in, C_out]` block of the kernel.
//!
//! im2col multiplies the padding's zeros too: at a 3×3 map with padding 1, 32 of the 81 taps
//! of its 9 outputs fall outside, at 5×5 56 of 225. Here they are skipped. The gathered rows are
//! fewer than im2col's patch matrix and the kernel is packed once in all; each tap's product is
//! added into the output (or scattered into the input gradient), about 1/C of its work.
//! [`applies`] picks the maps where enough of the taps fall on the padding.

use crate::model::cpu::{
    side_by_side, strided_product, sum_in_order, vectorized, with_scratch, Strided,
};
use crate::model::geom::Geom;

/// Whether `g` goes tap by tap: a kernel larger than 1×1 on a small map (64 output pixels or
/// fewer) with at least 35 % of its taps on the padding. Measured layer by layer (`conv_ops`
/// example, 128 images): 40 % (3×3 maps, and the stride-2 convolution into them) ran 20–30 %
/// faster than im2col, 25–31 % (5×5 and 4×4 maps) no faster, and a 2×2 map (56 %) faster.
pub(crate) fn applies(g: &Geom) -> bool {
    if g.kh * g.kw == 1 || g.pixels() > 64 {
        return false;
    }
    let inside: usize = (0..g.kh)
        .flat_map(|i| (0..g.kw).map(move |j| (i, j)))
        .map(|(i, j)| reach(g, i, j).len())
        .sum();
    100 * inside <= 65 * g.kh * g.kw * g.pixels()
}

/// The output pixels `(oy, ox)` whose input pixel for tap `(i, j)` is inside the map, and
/// that input pixel `(y, x)`.
fn reach(g: &Geom, i: usize, j: usize) -> Vec<((usize, usize), (usize, usize))> {
    let mut out = Vec::new();
    for oy in 0..g.out_h() {
        let Some(y) = (oy * g.stride + i)
            .checked_sub(g.padding)
            .filter(|&y| y < g.h)
        else {
            continue;
        };
        for ox in 0..g.out_w() {
            if let Some(x) = (ox * g.stride + j)
                .checked_sub(g.padding)
                .filter(|&x| x < g.w)
            {
                out.push(((oy, ox), (y, x)));
            }
        }
    }
    out
}

/// Rows `[n · pixels, c]` of `src` (NHWC: `n` samples of an `hh × ww` map of `c` channels):
/// for every sample, each of `pixels` `(y, x)` in turn.
fn gather(
    src: &[f32],
    n: usize,
    (hh, ww, c): (usize, usize, usize),
    pairs: &[(usize, usize)],
    rows: &mut [f32],
) {
    for s in 0..n {
        for (r, &(y, x)) in pairs.iter().enumerate() {
            let at = ((s * hh + y) * ww + x) * c;
            let dst = (s * pairs.len() + r) * c;
            rows[dst..dst + c].copy_from_slice(&src[at..at + c]);
        }
    }
}

/// Adds rows `[n · pixels, c]` into `dst` (NHWC, as [`gather`] reads) at each pixel.
fn scatter_add(
    rows: &[f32],
    n: usize,
    (hh, ww, c): (usize, usize, usize),
    pairs: &[(usize, usize)],
    dst: &mut [f32],
) {
    for s in 0..n {
        for (r, &(y, x)) in pairs.iter().enumerate() {
            let at = ((s * hh + y) * ww + x) * c;
            let src = &rows[(s * pairs.len() + r) * c..(s * pairs.len() + r + 1) * c];
            dst[at..at + c]
                .iter_mut()
                .zip(src)
                .for_each(|(d, v)| *d += v);
        }
    }
}

/// Pixels `(row, column)` of a map.
type Pixels = Vec<(usize, usize)>;

/// Each tap's offset in the OHWI kernel, and its output pixels with their input pixels.
fn taps(g: &Geom) -> Vec<(usize, Pixels, Pixels)> {
    let mut out = Vec::new();
    for i in 0..g.kh {
        for j in 0..g.kw {
            let (outs, ins): (Vec<_>, Vec<_>) = reach(g, i, j).into_iter().unzip();
            if !outs.is_empty() {
                out.push(((i * g.kw + j) * g.c_in, outs, ins));
            }
        }
    }
    out
}

/// Samples per chunk, and whether the chunks run side by side (one per thread, each product
/// on its thread alone: the gathers and scatters then run in parallel too), as `conv`'s plan.
fn plan(g: &Geom) -> (usize, bool) {
    if side_by_side(g.b) {
        (g.b.div_ceil(rayon::current_num_threads()), true)
    } else {
        (g.b.max(1), false)
    }
}

/// Runs `f(geometry of the chunk, first sample, its part of out)` for every chunk of samples,
/// `out` holding `per` values per sample.
fn chunked(g: &Geom, out: &mut [f32], per: usize, f: impl Fn(&Geom, usize, &mut [f32]) + Sync) {
    use rayon::prelude::*;
    let (step, parallel) = plan(g);
    let run = |(c, o): (usize, &mut [f32])| {
        let part = Geom {
            b: o.len() / per,
            ..*g
        };
        f(&part, c * step, o);
    };
    let out = &mut out[..g.b * per];
    if parallel {
        out.par_chunks_mut(step * per)
            .enumerate()
            .for_each(|c| vectorized(|| run(c)));
    } else {
        vectorized(|| out.chunks_mut(step * per).enumerate().for_each(run));
    }
}

/// `out` `[B, H', W', C_out]` = the convolution of `x` (NHWC) with the OHWI kernel `wp`.
pub(crate) fn forward(g: &Geom, x: &[f32], wp: &[f32], out: &mut [f32]) {
    let (ci, co, k) = (g.c_in, g.c_out, g.k());
    let taps = taps(g);
    let split = !plan(g).1;
    chunked(g, out, g.pixels() * co, |g, s0, out| {
        let (b, x) = (g.b, &x[s0 * g.per_in()..]);
        out.fill(0.0);
        let most = taps.iter().map(|t| t.1.len()).max().unwrap_or(0) * b;
        with_scratch(most * (ci + co), |scratch| {
            let (a, t) = scratch.split_at_mut(most * ci);
            for (off, outs, ins) in &taps {
                let rows = b * outs.len();
                gather(x, b, (g.h, g.w, ci), ins, a);
                strided_product(
                    split,
                    [rows, co, ci],
                    Strided::new(a, ci, 1),
                    Strided::new(&wp[*off..], 1, k),
                    (t, co),
                    false,
                );
                scatter_add(t, b, (g.out_h(), g.out_w(), co), outs, out);
            }
        });
    });
}

/// `dx` (NHWC, `B · per_in` values) from `dy` and the OHWI kernel `wp`; `accumulate` adds to
/// `dx`.
pub(crate) fn grad_input(g: &Geom, dy: &[f32], wp: &[f32], dx: &mut [f32], accumulate: bool) {
    let (ci, co, k) = (g.c_in, g.c_out, g.k());
    let taps = taps(g);
    let split = !plan(g).1;
    chunked(g, dx, g.per_in(), |g, s0, dx| {
        let (b, dy) = (g.b, &dy[s0 * g.pixels() * co..]);
        if !accumulate {
            dx.fill(0.0);
        }
        let most = taps.iter().map(|t| t.1.len()).max().unwrap_or(0) * b;
        with_scratch(most * (ci + co), |scratch| {
            let (a, t) = scratch.split_at_mut(most * co);
            for (off, outs, ins) in &taps {
                let rows = b * outs.len();
                gather(dy, b, (g.out_h(), g.out_w(), co), outs, a);
                strided_product(
                    split,
                    [rows, ci, co],
                    Strided::new(a, co, 1),
                    Strided::new(&wp[*off..], k, 1),
                    (t, ci),
                    false,
                );
                scatter_add(t, b, (g.h, g.w, ci), ins, dx);
            }
        });
    });
}

/// `dwp` (OHWI `[C_out, kh, kw, C_in]`, overwritten) from `x` and `dy`. Chunks side by side
/// sum into buffers of their own, added in order (the same bits whichever thread ran what).
pub(crate) fn grad_weight(g: &Geom, x: &[f32], dy: &[f32], dwp: &mut [f32]) {
    let (ci, co, k) = (g.c_in, g.c_out, g.k());
    let taps = taps(g);
    let (step, parallel) = plan(g);
    let chunks = g.b.div_ceil(step.max(1));
    let mut sums = vec![0f32; chunks * co * k];
    let part = |s0: usize, acc: &mut [f32]| {
        let b = step.min(g.b - s0);
        let (x, dy) = (&x[s0 * g.per_in()..], &dy[s0 * g.pixels() * co..]);
        let most = taps.iter().map(|t| t.1.len()).max().unwrap_or(0) * b;
        with_scratch(most * (ci + co), |scratch| {
            let (xa, da) = scratch.split_at_mut(most * ci);
            for (off, outs, ins) in &taps {
                let rows = b * outs.len();
                gather(x, b, (g.h, g.w, ci), ins, xa);
                gather(dy, b, (g.out_h(), g.out_w(), co), outs, da);
                // dW_tap [C_out, C_in] = dyᵀ · x over the tap's rows, into the kernel's rows.
                strided_product(
                    !parallel,
                    [co, ci, rows],
                    Strided::new(da, 1, co),
                    Strided::new(xa, ci, 1),
                    (&mut acc[*off..], k),
                    false,
                );
            }
        });
    };
    {
        use rayon::prelude::*;
        let run = |(c, acc): (usize, &mut [f32])| part(c * step, acc);
        if parallel {
            sums.par_chunks_mut(co * k)
                .enumerate()
                .for_each(|c| vectorized(|| run(c)));
        } else {
            vectorized(|| sums.chunks_mut(co * k).enumerate().for_each(run));
        }
    }
    let dwp = &mut dwp[..co * k];
    sum_in_order(dwp, sums.chunks(co * k));
}

#[cfg(test)]
#[path = "taps_tests.rs"]
mod tests;
