//! GroupNorm (then ReLU, optionally) on channels-last activations, forward and backward, two
//! or three passes per sample in parallel over samples; and the composed NCHW version for other
//! devices and as the tests' reference.

use candle_core::{CpuStorage, CustomOp3, Layout, Shape, Tensor};
use rayon::prelude::*;

use crate::model::cpu::{values, vectorized};

/// `GroupNorm(groups, eps)` of a channels-last `x` `[N, *, C]` with per-channel `gamma`,
/// `beta`, then ReLU when `relu`. CPU and f32 only.
pub fn group_norm_nhwc(
    x: &Tensor,
    gamma: &Tensor,
    beta: &Tensor,
    groups: usize,
    eps: f64,
    relu: bool,
) -> candle_core::Result<Tensor> {
    let op = GroupNorm { groups, eps, relu };
    x.contiguous()?
        .apply_op3(&gamma.contiguous()?, &beta.contiguous()?, op)
}

/// `GroupNorm(groups, eps)` of a channels-first `x` `[N, C, *]`, composed of candle ops (for
/// devices other than the CPU, and as the tests' reference).
pub fn group_norm_nchw(
    x: &Tensor,
    gamma: &Tensor,
    beta: &Tensor,
    groups: usize,
    eps: f64,
    relu: bool,
) -> candle_core::Result<Tensor> {
    let (n, c) = (x.dim(0)?, x.dim(1)?);
    let dims = x.dims().to_vec();
    let xg = x.reshape((n, groups, ()))?;
    let mean = xg.mean_keepdim(2)?;
    let xc = xg.broadcast_sub(&mean)?;
    let var = xc.sqr()?.mean_keepdim(2)?;
    let xhat = xc
        .broadcast_div(&(var + eps)?.sqrt()?)?
        .reshape(dims.as_slice())?;
    let mut wdims = vec![1; dims.len()];
    wdims[1] = c;
    let y = xhat
        .broadcast_mul(&gamma.reshape(wdims.as_slice())?)?
        .broadcast_add(&beta.reshape(wdims.as_slice())?)?;
    if relu {
        y.relu()
    } else {
        Ok(y)
    }
}

/// Geometry: N samples, S pixels, C channels (innermost), G groups.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dims {
    pub(crate) n: usize,
    pub(crate) s: usize,
    pub(crate) c: usize,
    pub(crate) g: usize,
}

impl Dims {
    pub(crate) fn of(dims: &[usize], groups: usize) -> candle_core::Result<Self> {
        let c = dims.last().copied().unwrap_or(0);
        if dims.len() < 2 || groups == 0 || c % groups != 0 {
            candle_core::bail!("group norm: shape {dims:?} with {groups} groups");
        }
        Ok(Dims {
            n: dims[0],
            s: dims[1..dims.len() - 1].iter().product(),
            c,
            g: groups,
        })
    }
    /// Values per sample.
    fn per(&self) -> usize {
        self.s * self.c
    }
    /// Values per (sample, group).
    fn m(&self) -> usize {
        self.c / self.g * self.s
    }
}

/// Rows summed in f32 before their sums are added into f64: the f32 loops run vector-wide,
/// and a block's f32 sum (32 values a channel) loses about as little as the f64 sum.
const BLOCK_ROWS: usize = 32;

/// Per channel of rows `x` `[S, C]`: `Σ x`, or `Σ (x − center)²` when `center` is given.
#[inline]
fn channel_sums(x: &[f32], c: usize, center: Option<&[f32]>) -> Vec<f64> {
    let (mut total, mut part) = (vec![0f64; c], vec![0f32; c]);
    for block in x.chunks(BLOCK_ROWS * c) {
        part.fill(0.0);
        for row in block.chunks_exact(c) {
            match center {
                None => part.iter_mut().zip(row).for_each(|(p, v)| *p += v),
                Some(mu) => {
                    for ((p, v), m) in part.iter_mut().zip(row).zip(mu) {
                        let e = v - m;
                        *p += e * e;
                    }
                }
            }
        }
        total
            .iter_mut()
            .zip(&part)
            .for_each(|(t, p)| *t += f64::from(*p));
    }
    total
}

/// Per group of one sample (`x` `[S, C]`): mean and 1/σ, two passes (sums kept in f64).
#[inline]
fn stats(d: &Dims, x: &[f32], eps: f64) -> (Vec<f32>, Vec<f32>) {
    let cg = d.c / d.g;
    let m = d.m().max(1) as f64;
    let sum = channel_sums(x, d.c, None);
    let mean: Vec<f32> = sum
        .chunks(cg)
        .map(|s| (s.iter().sum::<f64>() / m) as f32)
        .collect();
    let mean_c: Vec<f32> = (0..d.c).map(|c| mean[c / cg]).collect();
    let sq = channel_sums(x, d.c, Some(&mean_c));
    let rstd = sq
        .chunks(cg)
        .map(|s| (1.0 / (s.iter().sum::<f64>() / m + eps).sqrt()) as f32)
        .collect();
    (mean, rstd)
}

/// GroupNorm (then ReLU when `relu`) of channels-last `x` into `y`, parallel over samples.
pub(crate) fn group_norm_forward(
    d: &Dims,
    x: &[f32],
    gamma: &[f32],
    beta: &[f32],
    eps: f64,
    relu: bool,
    y: &mut [f32],
) {
    let cg = d.c / d.g;
    y[..x.len()]
        .par_chunks_mut(d.per())
        .zip(x.par_chunks(d.per()))
        .for_each(|(y, x)| {
            vectorized(|| {
                let (mean, rstd) = stats(d, x, eps);
                // y = x·a + b per channel.
                let a: Vec<f32> = (0..d.c).map(|c| rstd[c / cg] * gamma[c]).collect();
                let b: Vec<f32> = (0..d.c).map(|c| beta[c] - mean[c / cg] * a[c]).collect();
                for (y, x) in y.chunks_exact_mut(d.c).zip(x.chunks_exact(d.c)) {
                    for (((y, &x), &a), &b) in y.iter_mut().zip(x).zip(&a).zip(&b) {
                        let v = x * a + b;
                        *y = if relu { v.max(0.0) } else { v };
                    }
                }
            })
        });
}

struct GroupNorm {
    groups: usize,
    eps: f64,
    relu: bool,
}

impl CustomOp3 for GroupNorm {
    fn name(&self) -> &'static str {
        "scaledp-group-norm-nhwc"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let d = Dims::of(l1.dims(), self.groups)?;
        let (x, gamma, beta) = (values(s1, l1)?, values(s2, l2)?, values(s3, l3)?);
        let mut y = vec![0f32; x.len()];
        group_norm_forward(&d, x, gamma, beta, self.eps, self.relu, &mut y);
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        gamma: &Tensor,
        beta: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let c = gamma.elem_count();
        let packed = x.apply_op3_no_bwd(
            &grad.contiguous()?,
            &Tensor::cat(&[gamma, beta], 0)?,
            &GroupNormGrad {
                groups: self.groups,
                eps: self.eps,
                relu: self.relu,
            },
        )?;
        let nx = x.elem_count();
        let dx = packed.narrow(0, 0, nx)?.reshape(x.dims())?;
        let dgamma = packed.narrow(0, nx, c)?;
        let dbeta = packed.narrow(0, nx + c, c)?;
        Ok((Some(dx), Some(dgamma), Some(dbeta)))
    }
}

/// The gradients of [`group_norm_forward`] from `x` and `dy`: `dx` (overwritten), and
/// `dgamma`, `dbeta` (overwritten, or added to when `accumulate`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn group_norm_backward(
    d: &Dims,
    x: &[f32],
    dy: &[f32],
    gamma: &[f32],
    beta: &[f32],
    eps: f64,
    relu: bool,
    dx: &mut [f32],
    dgamma_out: &mut [f32],
    dbeta_out: &mut [f32],
    accumulate: bool,
) {
    let cg = d.c / d.g;
    let m = d.m().max(1) as f64;
    // Per (sample, channel): Σ e·x̂ and Σ e (e: dy through the ReLU), reduced over
    // samples afterwards.
    let mut partial = vec![0f64; d.n * d.c * 2];
    dx.par_chunks_mut(d.per())
        .zip(x.par_chunks(d.per()))
        .zip(dy.par_chunks(d.per()))
        .zip(partial.par_chunks_mut(d.c * 2))
        .for_each(|(((dx, x), dy), part)| {
            vectorized(|| {
                let (mean, rstd) = stats(d, x, eps);
                let mean_c: Vec<f32> = (0..d.c).map(|c| mean[c / cg]).collect();
                let rstd_c: Vec<f32> = (0..d.c).map(|c| rstd[c / cg]).collect();
                let (sg, sb) = part.split_at_mut(d.c);
                // Pass 1: e into dx, and the per-channel sums (f32 over a block of rows, then f64).
                let (c, gamma, beta) = (d.c, &gamma[..d.c], &beta[..d.c]);
                let (mu, rs) = (&mean_c[..c], &rstd_c[..c]);
                let (mut sgf, mut sbf) = (vec![0f32; c], vec![0f32; c]);
                let blocks = dx
                    .chunks_mut(BLOCK_ROWS * c)
                    .zip(x.chunks(BLOCK_ROWS * c))
                    .zip(dy.chunks(BLOCK_ROWS * c));
                for ((dxb, xb), dyb) in blocks {
                    sgf.fill(0.0);
                    sbf.fill(0.0);
                    let rows = dxb
                        .chunks_exact_mut(c)
                        .zip(xb.chunks_exact(c))
                        .zip(dyb.chunks_exact(c));
                    for ((dx, x), dy) in rows {
                        let sums = (&mut sgf[..], &mut sbf[..]);
                        backward_row(dx, x, dy, (mu, rs), (gamma, beta), relu, sums);
                    }
                    for k in 0..c {
                        sg[k] += f64::from(sgf[k]);
                        sb[k] += f64::from(sbf[k]);
                    }
                }
                // Group sums of dx̂ = e·γ and dx̂·x̂.
                let mut mean_d = vec![0f32; d.g];
                let mut mean_dx = vec![0f32; d.g];
                for g in 0..d.g {
                    let (mut s_d, mut s_dx) = (0f64, 0f64);
                    for c in g * cg..(g + 1) * cg {
                        s_d += f64::from(gamma[c]) * sb[c];
                        s_dx += f64::from(gamma[c]) * sg[c];
                    }
                    mean_d[g] = (s_d / m) as f32;
                    mean_dx[g] = (s_dx / m) as f32;
                }
                let md_c: Vec<f32> = (0..d.c).map(|c| mean_d[c / cg]).collect();
                let mdx_c: Vec<f32> = (0..d.c).map(|c| mean_dx[c / cg]).collect();
                // Pass 2: dx = 1/σ · (e·γ − mean(dx̂) − x̂ · mean(dx̂·x̂)).
                let (md, mdx) = (&md_c[..c], &mdx_c[..c]);
                for (dx, x) in dx.chunks_exact_mut(c).zip(x.chunks_exact(c)) {
                    let (dx, x) = (&mut dx[..c], &x[..c]);
                    for k in 0..c {
                        let xhat = (x[k] - mu[k]) * rs[k];
                        dx[k] = rs[k] * (dx[k] * gamma[k] - md[k] - xhat * mdx[k]);
                    }
                }
            })
        });
    let (mut dgamma, mut dbeta) = (vec![0f64; d.c], vec![0f64; d.c]);
    for part in partial.chunks(2 * d.c) {
        for c in 0..d.c {
            dgamma[c] += part[c];
            dbeta[c] += part[d.c + c];
        }
    }
    for c in 0..d.c {
        if accumulate {
            dgamma_out[c] += dgamma[c] as f32;
            dbeta_out[c] += dbeta[c] as f32;
        } else {
            dgamma_out[c] = dgamma[c] as f32;
            dbeta_out[c] = dbeta[c] as f32;
        }
    }
}

/// Pass 1 of [`group_norm_backward`] on one row of channels: `e` (`dy` through the ReLU) into
/// `dx`, and `Σ e·x̂`, `Σ e` added into `sums`. A function of its own over slices cut to one
/// length, and branch-free: inlined into the closure, the loop ran scalar.
#[inline]
fn backward_row(
    dx: &mut [f32],
    x: &[f32],
    dy: &[f32],
    (mu, rs): (&[f32], &[f32]),
    (gamma, beta): (&[f32], &[f32]),
    relu: bool,
    (sg, sb): (&mut [f32], &mut [f32]),
) {
    let c = dx.len();
    let (x, dy, mu, rs) = (&x[..c], &dy[..c], &mu[..c], &rs[..c]);
    let (gamma, beta, sg, sb) = (&gamma[..c], &beta[..c], &mut sg[..c], &mut sb[..c]);
    for k in 0..c {
        let (xhat, g) = ((x[k] - mu[k]) * rs[k], dy[k]);
        let cut = relu & (xhat * gamma[k] + beta[k] <= 0.0);
        let e = if cut { 0.0 } else { g };
        dx[k] = e;
        sg[k] += e * xhat;
        sb[k] += e;
    }
}

/// The gradients of [`GroupNorm`], packed: `[dx (N·S·C), dgamma (C), dbeta (C)]`.
struct GroupNormGrad {
    groups: usize,
    eps: f64,
    relu: bool,
}

impl CustomOp3 for GroupNormGrad {
    fn name(&self) -> &'static str {
        "scaledp-group-norm-nhwc-grad"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let d = Dims::of(l1.dims(), self.groups)?;
        let (x, dy, gb) = (values(s1, l1)?, values(s2, l2)?, values(s3, l3)?);
        let (gamma, beta) = gb.split_at(d.c);
        let mut out = vec![0f32; x.len() + 2 * d.c];
        let (dx, tail) = out.split_at_mut(x.len());
        let (dgamma, dbeta) = tail.split_at_mut(d.c);
        group_norm_backward(
            &d, x, dy, gamma, beta, self.eps, self.relu, dx, dgamma, dbeta, false,
        );
        let len = out.len();
        Ok((CpuStorage::F32(out), Shape::from(len)))
    }
}
