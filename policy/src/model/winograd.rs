//! Winograd's F(2×2, 3×3) for the 3×3, stride-1, padding-1 convolutions of the ResNet trunk
//! (every one of its convolutions but the stem, the stride-2 ones and the 1×1 shortcuts):
//! forward, input gradient and weight gradient, channels-last, in place of im2col + GEMM.
//!
//! Each 2×2 block of outputs ("tile") is `Aᵀ [(G g Gᵀ) ⊙ (Bᵀ d B)] A` of the 4×4 input patch
//! `d` around it (Lavin & Gray, 2016). Over all tiles and channels, the elementwise product is
//! 16 matrix products `V_ξ [tiles, C_in] · U_ξ [C_in, C_out]`, one per position ξ of the 4×4
//! transform: 16 multiplications per 2×2 outputs and input channel where im2col's product
//! makes 36 (2.25× fewer; tiles overhanging an odd-sized map waste some). The input and
//! output transforms are additions only, vectorized across channels.
//!
//! - input gradient: the convolution of `dy` with the kernel rotated 180° and its channels
//!   swapped, the same Winograd forward;
//! - weight gradient: `dU_ξ = V_ξᵀ · (A dy Aᵀ)_ξ` summed over tiles, then `dg = Gᵀ dU G`.
//!
//! Transformed tiles are laid out `[tiles, 16, C]`: a tile's transform is one contiguous
//! write, and each product reads its plane ξ in place with a row stride of 16·C.
//! [`applies`] picks the convolutions where it pays.

use rayon::prelude::*;

use crate::model::cpu::{
    side_by_side, strided_product, sum_in_order, vectorized, with_scratch, Strided,
};
use crate::model::geom::Geom;

/// Largest transformed chunk (input and output tiles together, f32 values) per thread.
const MAX_CHUNK_VALUES: usize = 4 << 20;

/// The transformed chunk a thread aims at when chunks run side by side (f32 values): 512 K =
/// 2 MiB, mostly in cache between the transforms and the 16 products. With 4 M a chunk, the
/// 84×84 trunk's 64-channel 19×19 layer took 16 ms a product, with 512 K–1 M 12 ms
/// (`conv_ops` example).
const CACHED_CHUNK_VALUES: usize = 1 << 19;

/// Whether Winograd runs `g`: it [`fits`], and it pays, measured layer by layer on the
/// 2-core machine (`conv_ops` example): the map tiles with little waste (at most 0.7 of
/// im2col's multiplications: a 3×3 map, 4 tiles for 9 outputs, does not), the channels are 64
/// or more (the transforms cost per value what the product costs per channel: at 32 channels
/// a 15×15 layer ran no faster), and the batch has 2,048 tiles or more (the transformed kernel
/// is packed again for every chunk: a 2×2 map of 256 channels, 128 tiles, ran 2× slower).
pub(crate) fn applies(g: &Geom) -> bool {
    fits(g)
        && 10 * 16 * tiles(g) <= 7 * 9 * g.h * g.w
        && g.c_in.min(g.c_out) >= 64
        && g.b * tiles(g) >= 2048
}

/// Whether `g` is a 3×3, stride-1, padding-1 convolution, which these kernels compute.
pub(crate) fn fits(g: &Geom) -> bool {
    g.kh == 3 && g.kw == 3 && g.stride == 1 && g.padding == 1
}

/// Tiles of one sample.
fn tiles(g: &Geom) -> usize {
    g.h.div_ceil(2) * g.w.div_ceil(2)
}

/// How the samples are cut: `(samples per chunk, chunks side by side)`, as `conv`'s plan:
/// side by side (one thread each, single-threaded products) for a training batch.
fn plan(g: &Geom, per_sample: usize) -> (usize, bool) {
    let threads = rayon::current_num_threads();
    let parallel = side_by_side(g.b);
    let budget = if parallel {
        // At least 4 transformed kernels' worth: the products pack it again for every chunk.
        CACHED_CHUNK_VALUES.max(4 * 16 * g.c_in * g.c_out)
    } else {
        MAX_CHUNK_VALUES * threads
    };
    let limit = (budget / per_sample.max(1)).clamp(1, g.b.max(1));
    if !parallel {
        return (limit, false);
    }
    let chunks = g.b.div_ceil(limit).next_multiple_of(threads);
    (g.b.div_ceil(chunks), true)
}

/// `G · v` of a kernel column or row, G = [1 0 0; ½ ½ ½; ½ −½ ½; 0 0 1].
fn g3(v: [f32; 3]) -> [f32; 4] {
    [
        v[0],
        0.5 * (v[0] + v[1] + v[2]),
        0.5 * (v[0] - v[1] + v[2]),
        v[2],
    ]
}

/// `Gᵀ · v`, the transpose of [`g3`].
fn gt4(v: [f32; 4]) -> [f32; 3] {
    [
        v[0] + 0.5 * (v[1] + v[2]),
        0.5 * (v[1] - v[2]),
        0.5 * (v[1] + v[2]) + v[3],
    ]
}

/// `U` `[16, C_in, C_out]` = `G g Gᵀ` of every (input, output) channel pair of an OHWI kernel
/// `wp` `[C_out, 3, 3, C_in]`. With `flip`, of the input gradient's kernel instead (each 3×3
/// rotated 180°, the channels swapped): `U` is `[16, C_out, C_in]`. The loops run along the
/// output's rows, so writes are contiguous.
fn kernel_transform(c_in: usize, c_out: usize, wp: &[f32], flip: bool) -> Vec<f32> {
    let mut u = vec![0f32; 16 * c_in * c_out];
    let one = |o: usize, c: usize| -> [f32; 16] {
        let k = &wp[o * 9 * c_in..(o + 1) * 9 * c_in];
        let g = |i: usize, j: usize| {
            let t = if flip { 8 - (i * 3 + j) } else { i * 3 + j };
            k[t * c_in + c]
        };
        // cols[j] = G · (column j of g), then each row of that · Gᵀ.
        let cols = [0, 1, 2].map(|j| g3([g(0, j), g(1, j), g(2, j)]));
        let mut out = [0f32; 16];
        for (a, dst) in out.chunks_exact_mut(4).enumerate() {
            dst.copy_from_slice(&g3([cols[0][a], cols[1][a], cols[2][a]]));
        }
        out
    };
    if flip {
        for o in 0..c_out {
            for c in 0..c_in {
                for (xi, v) in one(o, c).into_iter().enumerate() {
                    u[(xi * c_out + o) * c_in + c] = v;
                }
            }
        }
    } else {
        for c in 0..c_in {
            for o in 0..c_out {
                for (xi, v) in one(o, c).into_iter().enumerate() {
                    u[(xi * c_in + c) * c_out + o] = v;
                }
            }
        }
    }
    u
}

/// `o = a + b`, or `a − b` when `sub`: one vectorized pass over a tile's channels.
#[inline]
fn bin(o: &mut [f32], a: &[f32], b: &[f32], sub: bool) {
    let it = o.iter_mut().zip(a.iter().zip(b));
    if sub {
        it.for_each(|(o, (a, b))| *o = a - b);
    } else {
        it.for_each(|(o, (a, b))| *o = a + b);
    }
}

/// `o (+)= a + b + c`, or `a − b − c` when `sub` (`acc`: added to `o`).
#[inline]
fn tri(o: &mut [f32], (a, b, c): (&[f32], &[f32], &[f32]), sub: bool, acc: bool) {
    let it = o.iter_mut().zip(a.iter().zip(b.iter().zip(c)));
    match (sub, acc) {
        (false, false) => it.for_each(|(o, (a, (b, c)))| *o = a + b + c),
        (true, false) => it.for_each(|(o, (a, (b, c)))| *o = a - b - c),
        (false, true) => it.for_each(|(o, (a, (b, c)))| *o += a + b + c),
        (true, true) => it.for_each(|(o, (a, (b, c)))| *o += a - b - c),
    }
}

/// Runs `f(sample, its part of out)` over `out` cut `per` values per sample, across rayon's
/// threads when `par`.
fn per_sample(out: &mut [f32], per: usize, par: bool, f: impl Fn(usize, &mut [f32]) + Sync) {
    if par {
        out.par_chunks_mut(per)
            .enumerate()
            .for_each(|(s, o)| vectorized(|| f(s, o)));
    } else {
        vectorized(|| out.chunks_mut(per).enumerate().for_each(|(s, o)| f(s, o)));
    }
}

/// The `r`-th tile's top-left output (row, column) on a map `w` wide.
fn corner(r: usize, w: usize) -> (usize, usize) {
    let tx = w.div_ceil(2);
    (2 * (r / tx), 2 * (r % tx))
}

/// Pixel (y, x) of one sample's channels-last `h×w×c` map, or `zero` outside it (a row or
/// column of −1 wraps around to outside).
fn pixel<'a>(
    xs: &'a [f32],
    (h, w, c): (usize, usize, usize),
    (y, x): (usize, usize),
    zero: &'a [f32],
) -> &'a [f32] {
    if y < h && x < w {
        &xs[(y * w + x) * c..(y * w + x + 1) * c]
    } else {
        zero
    }
}

/// `V` `[n · tiles, 16, C]` = `Bᵀ d B` of every tile's 4×4 input patch (zero outside the map)
/// of the `n` samples `x` (NHWC, `C = g.c_in`).
fn input_transform(g: &Geom, x: &[f32], n: usize, v: &mut [f32], par: bool) {
    let (h, w, c, per) = (g.h, g.w, g.c_in, tiles(g));
    let zero = vec![0f32; c];
    per_sample(&mut v[..n * per * 16 * c], per * 16 * c, par, |s, vs| {
        let xs = &x[s * h * w * c..(s + 1) * h * w * c];
        // Bᵀ d, row by row of the patch: m[a][j].
        let mut m = vec![0f32; 16 * c];
        for (r, vt) in vs.chunks_exact_mut(16 * c).enumerate() {
            let (by, bx) = corner(r, w);
            let d = |i: usize, j: usize| {
                pixel(
                    xs,
                    (h, w, c),
                    ((by + i).wrapping_sub(1), (bx + j).wrapping_sub(1)),
                    &zero,
                )
            };
            let mut ms: Vec<&mut [f32]> = m.chunks_exact_mut(c).collect();
            for j in 0..4 {
                bin(ms[j], d(0, j), d(2, j), true);
                bin(ms[4 + j], d(1, j), d(2, j), false);
                bin(ms[8 + j], d(2, j), d(1, j), true);
                bin(ms[12 + j], d(1, j), d(3, j), true);
            }
            // · B, column by column: V[a][b].
            let ms: Vec<&[f32]> = m.chunks_exact(c).collect();
            let mut out: Vec<&mut [f32]> = vt.chunks_exact_mut(c).collect();
            for a in 0..4 {
                let r = &ms[a * 4..a * 4 + 4];
                bin(out[a * 4], r[0], r[2], true);
                bin(out[a * 4 + 1], r[1], r[2], false);
                bin(out[a * 4 + 2], r[2], r[1], true);
                bin(out[a * 4 + 3], r[1], r[3], true);
            }
        }
    });
}

/// `y` (NHWC, `n` samples, `C = g.c_out`) (+)= `Aᵀ M A` of the transformed outputs `M`
/// `[n · tiles, 16, C]`, the overhanging row and column of an odd-sized map dropped.
fn output_transform(g: &Geom, m: &[f32], y: &mut [f32], acc: bool, par: bool) {
    let (h, w, c, per) = (g.h, g.w, g.c_out, tiles(g));
    let n = m.len() / (per * 16 * c);
    per_sample(&mut y[..n * h * w * c], h * w * c, par, |s, ys| {
        // Aᵀ M: rows s[p][b] (p < 2).
        let mut t = vec![0f32; 8 * c];
        for r in 0..per {
            let (by, bx) = corner(r, w);
            let mt = &m[(s * per + r) * 16 * c..(s * per + r + 1) * 16 * c];
            let p: Vec<&[f32]> = mt.chunks_exact(c).collect();
            let mut ts: Vec<&mut [f32]> = t.chunks_exact_mut(c).collect();
            for b in 0..4 {
                tri(ts[b], (p[b], p[4 + b], p[8 + b]), false, false);
                tri(ts[4 + b], (p[4 + b], p[8 + b], p[12 + b]), true, false);
            }
            let ts: Vec<&[f32]> = t.chunks_exact(c).collect();
            for dy in 0..2.min(h - by) {
                let row = &ts[dy * 4..dy * 4 + 4];
                for dx in 0..2.min(w - bx) {
                    let at = ((by + dy) * w + bx + dx) * c;
                    let parts = if dx == 0 {
                        (row[0], row[1], row[2])
                    } else {
                        (row[1], row[2], row[3])
                    };
                    tri(&mut ys[at..at + c], parts, dx == 1, acc);
                }
            }
        }
    });
}

/// `dM` `[n · tiles, 16, C]` = `A dy Aᵀ` of every tile's 2×2 output gradient (zero where
/// a tile overhangs the map) of the `n` samples `dy` (NHWC, `C = g.c_out`).
fn grad_output_transform(g: &Geom, dy: &[f32], n: usize, dm: &mut [f32], par: bool) {
    let (h, w, c, per) = (g.h, g.w, g.c_out, tiles(g));
    let zero = vec![0f32; c];
    per_sample(&mut dm[..n * per * 16 * c], per * 16 * c, par, |s, ms| {
        let ds = &dy[s * h * w * c..(s + 1) * h * w * c];
        // A · dy (A = [1 0; 1 1; 1 −1; 0 −1]): rows q[a][j].
        let mut q = vec![0f32; 8 * c];
        for (r, mt) in ms.chunks_exact_mut(16 * c).enumerate() {
            let (by, bx) = corner(r, w);
            let d = |i: usize, j: usize| pixel(ds, (h, w, c), (by + i, bx + j), &zero);
            let mut qs: Vec<&mut [f32]> = q.chunks_exact_mut(c).collect();
            for j in 0..2 {
                bin(qs[j], d(0, j), &zero, false);
                bin(qs[2 + j], d(0, j), d(1, j), false);
                bin(qs[4 + j], d(0, j), d(1, j), true);
                bin(qs[6 + j], &zero, d(1, j), true);
            }
            // · Aᵀ, column by column.
            let qs: Vec<&[f32]> = q.chunks_exact(c).collect();
            let mut out: Vec<&mut [f32]> = mt.chunks_exact_mut(c).collect();
            for a in 0..4 {
                let (q0, q1) = (qs[a * 2], qs[a * 2 + 1]);
                bin(out[a * 4], q0, &zero, false);
                bin(out[a * 4 + 1], q0, q1, false);
                bin(out[a * 4 + 2], q0, q1, true);
                bin(out[a * 4 + 3], &zero, q1, true);
            }
        }
    });
}

/// `out` (NHWC, `B · H · W · C_out`) (+)= the convolution of `x` with the OHWI kernel `wp`.
pub(crate) fn forward(g: &Geom, x: &[f32], wp: &[f32], out: &mut [f32], acc: bool) {
    let u = kernel_transform(g.c_in, g.c_out, wp, false);
    transformed_forward(g, x, &u, out, acc);
}

/// [`forward`] with the kernel's transform `u` `[16, C_in, C_out]`.
fn transformed_forward(g: &Geom, x: &[f32], u: &[f32], out: &mut [f32], acc: bool) {
    let (ci, co, per) = (g.c_in, g.c_out, tiles(g));
    let (step, parallel) = plan(g, per * 16 * (ci + co));
    let run = |s0: usize, dst: &mut [f32], scratch: &mut [f32]| {
        let n = dst.len() / (g.h * g.w * co);
        let rows = n * per;
        let (v, m) = scratch.split_at_mut(rows * 16 * ci);
        input_transform(g, &x[s0 * g.per_in()..], n, v, !parallel);
        for xi in 0..16 {
            strided_product(
                !parallel,
                [rows, co, ci],
                Strided::new(&v[xi * ci..], 16 * ci, 1),
                Strided::new(&u[xi * ci * co..(xi + 1) * ci * co], co, 1),
                (&mut m[xi * co..], 16 * co),
                false,
            );
        }
        output_transform(g, &m[..rows * 16 * co], dst, acc, !parallel);
    };
    let per_out = g.h * g.w * co;
    let out = &mut out[..g.b * per_out];
    let scratch = step * per * 16 * (ci + co);
    if parallel {
        out.par_chunks_mut(step * per_out)
            .enumerate()
            .for_each(|(i, o)| with_scratch(scratch, |s| run(i * step, o, s)));
    } else {
        with_scratch(scratch, |s| {
            for (i, o) in out.chunks_mut(step * per_out).enumerate() {
                run(i * step, o, s);
            }
        });
    }
}

/// `dx` (NHWC) (+)= the input gradient from `dy` and the OHWI kernel `wp`: the convolution of
/// `dy` with the kernel rotated 180°, input and output channels swapped.
pub(crate) fn grad_input(g: &Geom, dy: &[f32], wp: &[f32], dx: &mut [f32], acc: bool) {
    let u = kernel_transform(g.c_in, g.c_out, wp, true);
    let swapped = Geom {
        c_in: g.c_out,
        c_out: g.c_in,
        ..*g
    };
    transformed_forward(&swapped, dy, &u, dx, acc);
}

/// `dwp` (OHWI `[C_out, 3, 3, C_in]`, overwritten) from `x` and `dy`.
pub(crate) fn grad_weight(g: &Geom, x: &[f32], dy: &[f32], dwp: &mut [f32]) {
    let (ci, co, per) = (g.c_in, g.c_out, tiles(g));
    let (step, parallel) = plan(g, per * 16 * (ci + co));
    // dU of samples [s0, s0 + n) added to `du` `[16, C_in, C_out]`.
    let add = |du: &mut [f32], s0: usize, n: usize, first: bool| {
        let rows = n * per;
        with_scratch(rows * 16 * (ci + co), |scratch| {
            let (v, m) = scratch.split_at_mut(rows * 16 * ci);
            input_transform(g, &x[s0 * g.per_in()..], n, v, !parallel);
            grad_output_transform(g, &dy[s0 * g.h * g.w * co..], n, m, !parallel);
            for xi in 0..16 {
                strided_product(
                    !parallel,
                    [ci, co, rows],
                    Strided::new(&v[xi * ci..], 1, 16 * ci),
                    Strided::new(&m[xi * co..], 16 * co, 1),
                    (&mut du[xi * ci * co..(xi + 1) * ci * co], co),
                    !first,
                );
            }
        });
    };
    let starts: Vec<usize> = (0..g.b).step_by(step).collect();
    let du = if parallel {
        // Each thread sums a fixed, contiguous share of the chunks, and the shares are added
        // in order: the result does not depend on which thread ran what (see `conv`).
        let threads = rayon::current_num_threads().min(starts.len()).max(1);
        let sums: Vec<Vec<f32>> = (0..threads)
            .into_par_iter()
            .map(|t| {
                let mut du = vec![0f32; 16 * ci * co];
                let share = &starts[t * starts.len() / threads..(t + 1) * starts.len() / threads];
                for (i, &s0) in share.iter().enumerate() {
                    add(&mut du, s0, step.min(g.b - s0), i == 0);
                }
                du
            })
            .collect();
        let mut du = vec![0f32; 16 * ci * co];
        sum_in_order(&mut du, sums.iter().map(Vec::as_slice));
        du
    } else {
        let mut du = vec![0f32; 16 * ci * co];
        for (i, &s0) in starts.iter().enumerate() {
            add(&mut du, s0, step.min(g.b - s0), i == 0);
        }
        du
    };
    // dg = Gᵀ dU G for every channel pair.
    let dwp = &mut dwp[..co * 9 * ci];
    for c in 0..ci {
        for o in 0..co {
            let d = |a: usize, b: usize| du[((a * 4 + b) * ci + c) * co + o];
            // cols[b] = Gᵀ · (column b of dU), then each row of that · G.
            let cols = [0, 1, 2, 3].map(|b| gt4([d(0, b), d(1, b), d(2, b), d(3, b)]));
            for i in 0..3 {
                let row = gt4([cols[0][i], cols[1][i], cols[2][i], cols[3][i]]);
                for (j, v) in row.into_iter().enumerate() {
                    dwp[(o * 9 + i * 3 + j) * ci + c] = v;
                }
            }
        }
    }
}

#[cfg(test)]
#[path = "winograd_tests.rs"]
mod tests;
