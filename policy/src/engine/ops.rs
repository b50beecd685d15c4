//! Row-wise building blocks of the hand-written passes, on plain `f32` slices: Linear layers
//! (one GEMM each way), LayerNorm without affine, SiLU, tanh-GELU, adaLN modulation and gated
//! residuals, each with its backward. Work is split over rayon's threads by rows.

use rayon::prelude::*;

use crate::model::cpu::{gemm, vectorized};

/// Rows per parallel task: enough work to amortise a task, enough tasks to keep both cores busy.
pub(crate) fn rows_per_task(rows: usize, width: usize) -> usize {
    let target = (1 << 14) / width.max(1);
    target.clamp(1, rows.div_ceil(8).max(1))
}

/// A Linear layer's weight as a forward pass multiplies with it: PyTorch's `[out, in]` layout
/// (the model's own tensor), or a copy laid out `[in, out]`. With a few rows (DDIM at batch 1:
/// 16 action tokens) the GEMM repacks an `[out, in]` weight on every call, which costs about
/// as much as the product; an `[in, out]` copy is multiplied in place.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LinearWeight<'a> {
    pub values: &'a [f32],
    /// `values` is `[in, out]` (else `[out, in]`).
    pub in_out: bool,
}

impl<'a> From<&'a [f32]> for LinearWeight<'a> {
    fn from(values: &'a [f32]) -> Self {
        LinearWeight {
            values,
            in_out: false,
        }
    }
}

/// `y[r] = x[r] · wᵀ + b` for `rows` rows: `x` `[rows, k]`, `w` `[n, k]` (PyTorch's Linear
/// layout) or its `[k, n]` copy, `y` `[rows, n]`.
pub(crate) fn linear<'a>(
    x: &[f32],
    w: impl Into<LinearWeight<'a>>,
    b: Option<&[f32]>,
    rows: usize,
    k: usize,
    n: usize,
    y: &mut [f32],
) {
    let w = w.into();
    gemm(
        rows,
        n,
        k,
        x,
        false,
        w.values,
        !w.in_out,
        &mut y[..rows * n],
        false,
    );
    if let Some(b) = b {
        let per = rows_per_task(rows, n);
        y[..rows * n].par_chunks_mut(per * n).for_each(|ys| {
            vectorized(|| {
                for row in ys.chunks_exact_mut(n) {
                    for (v, bb) in row.iter_mut().zip(b) {
                        *v += bb;
                    }
                }
            })
        });
    }
}

/// The backward of [`linear`]: `dw (+)= dyᵀ · x`, `db (+)= Σ_r dy[r]`, and `dx = dy · w` when
/// asked for (`accumulate_dx` adds to `dx` instead of overwriting it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn linear_backward(
    x: &[f32],
    w: &[f32],
    dy: &[f32],
    rows: usize,
    k: usize,
    n: usize,
    dw: &mut [f32],
    db: Option<&mut [f32]>,
    dx: Option<(&mut [f32], bool)>,
) {
    gemm(n, k, rows, dy, true, x, false, dw, false);
    if let Some(db) = db {
        column_sums(&dy[..rows * n], n, db);
    }
    if let Some((dx, acc)) = dx {
        gemm(rows, k, n, dy, false, w, false, &mut dx[..rows * k], acc);
    }
}

/// `out[j] = Σ_r m[r, j]` of a row-major `[rows, n]` matrix, reduced in parallel.
pub(crate) fn column_sums(m: &[f32], n: usize, out: &mut [f32]) {
    let rows = m.len() / n.max(1);
    let per = rows_per_task(rows, n).max(16);
    let partial: Vec<Vec<f64>> = m
        .par_chunks(per * n)
        .map(|ms| {
            let mut acc = vec![0f64; n];
            for row in ms.chunks_exact(n) {
                for (a, v) in acc.iter_mut().zip(row) {
                    *a += f64::from(*v);
                }
            }
            acc
        })
        .collect();
    for (j, o) in out.iter_mut().enumerate().take(n) {
        *o = partial.iter().map(|p| p[j]).sum::<f64>() as f32;
    }
}

/// LayerNorm without affine over rows of `d`: `n = (x − μ) / √(σ² + eps)`; also returns each
/// row's `1/√(σ² + eps)` into `rstd`.
pub(crate) fn layer_norm(x: &[f32], d: usize, eps: f64, n: &mut [f32], rstd: &mut [f32]) {
    let rows = x.len() / d;
    let per = rows_per_task(rows, d);
    n[..rows * d]
        .par_chunks_mut(per * d)
        .zip(x.par_chunks(per * d))
        .zip(rstd[..rows].par_chunks_mut(per))
        .for_each(|((ns, xs), rs)| {
            vectorized(|| {
                for ((nr, xr), r) in ns.chunks_exact_mut(d).zip(xs.chunks_exact(d)).zip(rs) {
                    let mean = xr.iter().map(|v| f64::from(*v)).sum::<f64>() / d as f64;
                    let var = xr
                        .iter()
                        .map(|v| (f64::from(*v) - mean).powi(2))
                        .sum::<f64>()
                        / d as f64;
                    let rs = 1.0 / (var + eps).sqrt();
                    *r = rs as f32;
                    for (o, v) in nr.iter_mut().zip(xr) {
                        *o = ((f64::from(*v) - mean) * rs) as f32;
                    }
                }
            })
        });
}

/// The backward of [`layer_norm`]: `dx (+)= rstd · (dn − mean(dn) − n · mean(dn · n))`.
pub(crate) fn layer_norm_backward(
    n: &[f32],
    rstd: &[f32],
    dn: &[f32],
    d: usize,
    dx: &mut [f32],
    accumulate: bool,
) {
    let rows = n.len() / d;
    let per = rows_per_task(rows, d);
    dx[..rows * d]
        .par_chunks_mut(per * d)
        .zip(n.par_chunks(per * d).zip(dn.par_chunks(per * d)))
        .zip(rstd[..rows].par_chunks(per))
        .for_each(|((dxs, (ns, dns)), rs)| {
            vectorized(|| {
                for (((dxr, nr), dnr), r) in dxs
                    .chunks_exact_mut(d)
                    .zip(ns.chunks_exact(d))
                    .zip(dns.chunks_exact(d))
                    .zip(rs)
                {
                    let (mut s, mut sn) = (0f32, 0f32);
                    for (a, b) in dnr.iter().zip(nr) {
                        s += a;
                        sn += a * b;
                    }
                    let (m, mn) = (s / d as f32, sn / d as f32);
                    for ((o, a), b) in dxr.iter_mut().zip(dnr).zip(nr) {
                        let v = r * (a - m - b * mn);
                        if accumulate {
                            *o += v;
                        } else {
                            *o = v;
                        }
                    }
                }
            })
        });
}

/// SiLU, `x · σ(x)`.
#[inline]
pub(crate) fn silu(x: f32) -> f32 {
    x / (1.0 + (-x).exp())
}

/// d SiLU / dx.
#[inline]
pub(crate) fn silu_grad(x: f32) -> f32 {
    let s = 1.0 / (1.0 + (-x).exp());
    s * (1.0 + x * (1.0 - s))
}

const SQRT_2_OVER_PI: f32 = 0.797_884_6;
const GELU_C: f32 = 0.044_715;

/// tanh as a rational function of degree 13/6 on [−7.9988, 7.9988] (±1 beyond, the identity
/// below 4·10⁻⁴): Eigen's `generic_fast_tanh_float`, within 5·10⁻⁷ of tanh (see the test).
/// Branch-free, so a loop of it vectorizes; libm's `tanhf`, one value at a time, took an eighth
/// of a DDIM sample and of a training step's denoiser (the MLP's GELU on every hidden unit).
#[inline]
pub(crate) fn tanh(x: f32) -> f32 {
    const A: [f32; 7] = [
        4.893_524_6e-3,
        6.372_619_3e-4,
        1.485_722_4e-5,
        5.122_297e-8,
        -8.604_672e-11,
        2.000_188e-13,
        -2.760_768_5e-16,
    ];
    const B: [f32; 4] = [4.893_525e-3, 2.268_434_6e-3, 1.185_347e-4, 1.198_258_4e-6];
    let c = x.clamp(-7.998_811_7, 7.998_811_7);
    let x2 = c * c;
    // Plain products and sums: `mul_add` without the FMA target feature is a libm call.
    let mut p = x2 * A[6] + A[5];
    for a in A[..5].iter().rev() {
        p = x2 * p + a;
    }
    let q = ((x2 * B[3] + B[2]) * x2 + B[1]) * x2 + B[0];
    if x.abs() < 4e-4 {
        x
    } else {
        c * p / q
    }
}

/// tanh-GELU (PyTorch's `approximate="tanh"`, candle's `gelu`).
#[inline]
pub(crate) fn gelu(x: f32) -> f32 {
    0.5 * x * (1.0 + tanh(SQRT_2_OVER_PI * (x + GELU_C * x * x * x)))
}

/// d tanh-GELU / dx.
#[inline]
pub(crate) fn gelu_grad(x: f32) -> f32 {
    let u = SQRT_2_OVER_PI * (x + GELU_C * x * x * x);
    let t = tanh(u);
    let du = SQRT_2_OVER_PI * (1.0 + 3.0 * GELU_C * x * x);
    0.5 * (1.0 + t) + 0.5 * x * (1.0 - t * t) * du
}

/// `y = f(x)` elementwise, in parallel.
pub(crate) fn map(x: &[f32], y: &mut [f32], f: impl Fn(f32) -> f32 + Sync) {
    y[..x.len()]
        .par_chunks_mut(1 << 14)
        .zip(x.par_chunks(1 << 14))
        .for_each(|(ys, xs)| {
            vectorized(|| {
                for (o, v) in ys.iter_mut().zip(xs) {
                    *o = f(*v);
                }
            })
        });
}

/// `dx = dy · f'(x)` elementwise, in parallel (in place on `dy`).
pub(crate) fn map_grad(x: &[f32], dy: &mut [f32], f: impl Fn(f32) -> f32 + Sync) {
    dy[..x.len()]
        .par_chunks_mut(1 << 14)
        .zip(x.par_chunks(1 << 14))
        .for_each(|(ds, xs)| {
            vectorized(|| {
                for (d, v) in ds.iter_mut().zip(xs) {
                    *d *= f(*v);
                }
            })
        });
}

/// adaLN modulation of `tokens` rows per sample: `u = n · (1 + scale[s]) + shift[s]`, the
/// sample's `shift` and `scale` taken from its modulation row `m` (width `stride`) at column
/// offsets `shift_at` and `scale_at`.
pub(crate) fn modulate(
    n: &[f32],
    m: &[f32],
    stride: usize,
    (shift_at, scale_at): (usize, usize),
    tokens: usize,
    d: usize,
    u: &mut [f32],
) {
    u[..n.len()]
        .par_chunks_mut(tokens * d)
        .zip(n.par_chunks(tokens * d))
        .enumerate()
        .for_each(|(s, (us, ns))| {
            vectorized(|| {
                let row = &m[s * stride..(s + 1) * stride];
                let (shift, scale) = (&row[shift_at..shift_at + d], &row[scale_at..scale_at + d]);
                for (ur, nr) in us.chunks_exact_mut(d).zip(ns.chunks_exact(d)) {
                    for j in 0..d {
                        ur[j] = nr[j] * (1.0 + scale[j]) + shift[j];
                    }
                }
            })
        });
}

/// The backward of [`modulate`]: `dn = du · (1 + scale)`, and into the sample's gradient row
/// `dm` (width `stride`): `dshift = Σ_t du`, `dscale = Σ_t du · n`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn modulate_backward(
    n: &[f32],
    m: &[f32],
    du: &[f32],
    stride: usize,
    (shift_at, scale_at): (usize, usize),
    tokens: usize,
    d: usize,
    dn: &mut [f32],
    dm: &mut [f32],
) {
    dn[..n.len()]
        .par_chunks_mut(tokens * d)
        .zip(n.par_chunks(tokens * d).zip(du.par_chunks(tokens * d)))
        .zip(dm.par_chunks_mut(stride))
        .enumerate()
        .for_each(|(s, ((dns, (ns, dus)), dmr))| {
            vectorized(|| {
                let scale = &m[s * stride + scale_at..s * stride + scale_at + d];
                for (dnr, (nr, dur)) in dns
                    .chunks_exact_mut(d)
                    .zip(ns.chunks_exact(d).zip(dus.chunks_exact(d)))
                {
                    for j in 0..d {
                        dnr[j] = dur[j] * (1.0 + scale[j]);
                        dmr[shift_at + j] += dur[j];
                        dmr[scale_at + j] += dur[j] * nr[j];
                    }
                }
            })
        });
}

/// Gated residual `h += gate[s] · a` over `tokens` rows per sample (`gate` at column `gate_at`
/// of the sample's modulation row).
pub(crate) fn gated_add(
    h: &mut [f32],
    a: &[f32],
    m: &[f32],
    stride: usize,
    gate_at: usize,
    tokens: usize,
    d: usize,
) {
    let len = a.len();
    h[..len]
        .par_chunks_mut(tokens * d)
        .zip(a.par_chunks(tokens * d))
        .enumerate()
        .for_each(|(s, (hs, as_))| {
            vectorized(|| {
                let gate = &m[s * stride + gate_at..s * stride + gate_at + d];
                for (hr, ar) in hs.chunks_exact_mut(d).zip(as_.chunks_exact(d)) {
                    for j in 0..d {
                        hr[j] += gate[j] * ar[j];
                    }
                }
            })
        });
}

/// The backward of [`gated_add`] for the branch: `da = dh · gate`, `dgate += Σ_t dh · a`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn gated_add_backward(
    dh: &[f32],
    a: &[f32],
    m: &[f32],
    stride: usize,
    gate_at: usize,
    tokens: usize,
    d: usize,
    da: &mut [f32],
    dm: &mut [f32],
) {
    da[..a.len()]
        .par_chunks_mut(tokens * d)
        .zip(dh.par_chunks(tokens * d).zip(a.par_chunks(tokens * d)))
        .zip(dm.par_chunks_mut(stride))
        .enumerate()
        .for_each(|(s, ((das, (dhs, as_)), dmr))| {
            vectorized(|| {
                let gate = &m[s * stride + gate_at..s * stride + gate_at + d];
                for (dar, (dhr, ar)) in das
                    .chunks_exact_mut(d)
                    .zip(dhs.chunks_exact(d).zip(as_.chunks_exact(d)))
                {
                    for j in 0..d {
                        dar[j] = dhr[j] * gate[j];
                        dmr[gate_at + j] += dhr[j] * ar[j];
                    }
                }
            })
        });
}

/// `a += b` elementwise, in parallel.
pub(crate) fn add_into(a: &mut [f32], b: &[f32]) {
    a[..b.len()]
        .par_chunks_mut(1 << 14)
        .zip(b.par_chunks(1 << 14))
        .for_each(|(xs, ys)| {
            vectorized(|| {
                for (x, y) in xs.iter_mut().zip(ys) {
                    *x += y;
                }
            })
        });
}
