//! 2-D convolution for training on the CPU: im2col + one large GEMM per chunk of samples, with
//! its own backward pass.
//!
//! candle 0.11's CPU `conv2d` is differentiable, but its input gradient goes through
//! `conv_transpose2d`, a loop of dot products without GEMM, and its weight gradient through a
//! convolution whose kernel is the whole output map. On ResNet-18 that made one training step
//! several times slower than the forward pass warranted (see the crate docs for the figures).
//! Here all three products are GEMMs over a patch matrix laid out `[samples · pixels, K]`
//! (K = C_in·kh·kw in PyTorch's weight order):
//!
//! - forward: `y = patches · Wᵀ`,
//! - input gradient: `dpatches = dy · W`, scattered back by col2im,
//! - weight gradient: `dW = dyᵀ · patches` (patches recomputed, never stored).
//!
//! The patch matrix is built for a bounded chunk of samples at a time, so memory stays near the
//! size of the activations. Other devices use candle's own `conv2d`.

use candle_core::{CpuStorage, CustomOp2, DType, Device, Layout, Shape, Tensor};
use rayon::prelude::*;

/// Largest patch matrix built at once (f32 values): 32 M = 128 MB.
const MAX_PATCH_VALUES: usize = 32 << 20;

/// A convolution without bias, PyTorch's `Conv2d(..., bias=False)` with equal stride and
/// padding on both axes; `x` is `[B, C_in, H, W]`, `w` `[C_out, C_in, kh, kw]`.
pub fn conv2d(
    x: &Tensor,
    w: &Tensor,
    stride: usize,
    padding: usize,
) -> candle_core::Result<Tensor> {
    if x.device().is_cpu()
        && x.dtype() == DType::F32
        && std::env::var_os("SCALEDP_NATIVE_CONV").is_none()
    {
        let x = x.contiguous()?;
        let w = w.contiguous()?;
        x.apply_op2(&w, Conv { stride, padding })
    } else {
        x.conv2d(w, padding, stride, 1, 1)
    }
}

/// The geometry of one convolution.
#[derive(Clone, Copy, Debug)]
struct Geom {
    b: usize,
    c_in: usize,
    h: usize,
    w: usize,
    c_out: usize,
    kh: usize,
    kw: usize,
    stride: usize,
    padding: usize,
}

impl Geom {
    fn new(x: &[usize], k: &[usize], stride: usize, padding: usize) -> candle_core::Result<Self> {
        let (&[b, c_in, h, w], &[c_out, kc, kh, kw]) = (x, k) else {
            candle_core::bail!("conv2d: input {x:?} and kernel {k:?} must both be 4-D");
        };
        if kc != c_in {
            candle_core::bail!("conv2d: input has {c_in} channels, kernel {kc}");
        }
        if h + 2 * padding < kh || w + 2 * padding < kw || stride == 0 {
            candle_core::bail!("conv2d: kernel {kh}×{kw} larger than the padded input {h}×{w}");
        }
        Ok(Geom {
            b,
            c_in,
            h,
            w,
            c_out,
            kh,
            kw,
            stride,
            padding,
        })
    }
    fn out_h(&self) -> usize {
        (self.h + 2 * self.padding - self.kh) / self.stride + 1
    }
    fn out_w(&self) -> usize {
        (self.w + 2 * self.padding - self.kw) / self.stride + 1
    }
    fn pixels(&self) -> usize {
        self.out_h() * self.out_w()
    }
    fn k(&self) -> usize {
        self.c_in * self.kh * self.kw
    }
    /// Samples per chunk so that a chunk's patch matrix stays under the limit.
    fn chunk(&self) -> usize {
        (MAX_PATCH_VALUES / (self.pixels() * self.k()).max(1)).clamp(1, self.b.max(1))
    }
    /// Whether the patch matrix of a sample is its input, transposed (1×1, stride 1).
    fn pointwise(&self) -> bool {
        self.kh == 1 && self.kw == 1 && self.stride == 1 && self.padding == 0
    }
}

/// The contiguous values of a storage with a contiguous layout.
fn values<'a>(s: &'a CpuStorage, l: &Layout) -> candle_core::Result<&'a [f32]> {
    let data = s.as_slice::<f32>()?;
    match l.contiguous_offsets() {
        Some((start, end)) => Ok(&data[start..end]),
        None => candle_core::bail!("conv2d: operands must be contiguous"),
    }
}

/// Patches of samples `x` (`n` samples, NCHW): `[n · P, K]`, K ordered (c, i, j).
fn im2col(g: &Geom, x: &[f32], n: usize) -> Vec<f32> {
    let (oh, ow, k) = (g.out_h(), g.out_w(), g.k());
    let mut out = vec![0f32; n * oh * ow * k];
    let plane = g.h * g.w;
    out.par_chunks_mut(ow * k)
        .enumerate()
        .for_each(|(row, dst)| {
            let (s, oy) = (row / oh, row % oh);
            let xs = &x[s * g.c_in * plane..(s + 1) * g.c_in * plane];
            for ox in 0..ow {
                let d = &mut dst[ox * k..(ox + 1) * k];
                let mut idx = 0;
                for c in 0..g.c_in {
                    let xc = &xs[c * plane..(c + 1) * plane];
                    for i in 0..g.kh {
                        let y = (oy * g.stride + i) as isize - g.padding as isize;
                        if y < 0 || y >= g.h as isize {
                            idx += g.kw;
                            continue;
                        }
                        let xr = &xc[y as usize * g.w..(y as usize + 1) * g.w];
                        for j in 0..g.kw {
                            let xx = (ox * g.stride + j) as isize - g.padding as isize;
                            if xx >= 0 && xx < g.w as isize {
                                d[idx] = xr[xx as usize];
                            }
                            idx += 1;
                        }
                    }
                }
            }
        });
    out
}

/// Adds patch gradients `[n · P, K]` back into `dx` (`n` samples, NCHW).
fn col2im(g: &Geom, cols: &[f32], dx: &mut [f32]) {
    let (oh, ow, k) = (g.out_h(), g.out_w(), g.k());
    let plane = g.h * g.w;
    dx.par_chunks_mut(g.c_in * plane)
        .enumerate()
        .for_each(|(s, xs)| {
            let cs = &cols[s * oh * ow * k..(s + 1) * oh * ow * k];
            for oy in 0..oh {
                for ox in 0..ow {
                    let src = &cs[(oy * ow + ox) * k..(oy * ow + ox + 1) * k];
                    let mut idx = 0;
                    for c in 0..g.c_in {
                        let xc = &mut xs[c * plane..(c + 1) * plane];
                        for i in 0..g.kh {
                            let y = (oy * g.stride + i) as isize - g.padding as isize;
                            if y < 0 || y >= g.h as isize {
                                idx += g.kw;
                                continue;
                            }
                            let xr = &mut xc[y as usize * g.w..(y as usize + 1) * g.w];
                            for j in 0..g.kw {
                                let xx = (ox * g.stride + j) as isize - g.padding as isize;
                                if xx >= 0 && xx < g.w as isize {
                                    xr[xx as usize] += src[idx];
                                }
                                idx += 1;
                            }
                        }
                    }
                }
            }
        });
}

/// `[n, C, P]` (NCHW) → `[n · P, C]`.
fn to_rows(v: &[f32], n: usize, c: usize, p: usize) -> Vec<f32> {
    let mut out = vec![0f32; n * p * c];
    out.par_chunks_mut(p * c).enumerate().for_each(|(s, dst)| {
        let src = &v[s * c * p..(s + 1) * c * p];
        for ci in 0..c {
            for pi in 0..p {
                dst[pi * c + ci] = src[ci * p + pi];
            }
        }
    });
    out
}

/// `[n · P, C]` → `[n, C, P]` (NCHW), written into `dst`.
fn from_rows(v: &[f32], n: usize, c: usize, p: usize, dst: &mut [f32]) {
    dst[..n * c * p]
        .par_chunks_mut(c * p)
        .enumerate()
        .for_each(|(s, d)| {
            let src = &v[s * p * c..(s + 1) * p * c];
            for pi in 0..p {
                for ci in 0..c {
                    d[ci * p + pi] = src[pi * c + ci];
                }
            }
        });
}

/// The patch matrix of samples `s0 .. s0 + n` as a `[n · P, K]` tensor.
fn patches(g: &Geom, x: &[f32], s0: usize, n: usize) -> candle_core::Result<Tensor> {
    let per = g.c_in * g.h * g.w;
    let xs = &x[s0 * per..(s0 + n) * per];
    let cols = if g.pointwise() {
        to_rows(xs, n, g.c_in, g.h * g.w)
    } else {
        im2col(g, xs, n)
    };
    Tensor::from_vec(cols, (n * g.pixels(), g.k()), &Device::Cpu)
}

/// `y = conv(x, w)`; its backward is [`GradInput`] and [`GradWeight`].
struct Conv {
    stride: usize,
    padding: usize,
}

impl CustomOp2 for Conv {
    fn name(&self) -> &'static str {
        "scaledp-conv2d"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = Geom::new(l1.dims(), l2.dims(), self.stride, self.padding)?;
        let (x, w) = (values(s1, l1)?, values(s2, l2)?);
        let wt = Tensor::from_slice(w, (g.c_out, g.k()), &Device::Cpu)?.t()?;
        let p = g.pixels();
        let mut out = vec![0f32; g.b * g.c_out * p];
        let step = g.chunk();
        for s0 in (0..g.b).step_by(step) {
            let n = step.min(g.b - s0);
            let y = patches(&g, x, s0, n)?.matmul(&wt)?;
            let y = y.flatten_all()?.to_vec1::<f32>()?;
            let dst = &mut out[s0 * g.c_out * p..(s0 + n) * g.c_out * p];
            from_rows(&y, n, g.c_out, p, dst);
        }
        let shape = Shape::from((g.b, g.c_out, g.out_h(), g.out_w()));
        Ok((CpuStorage::F32(out), shape))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> candle_core::Result<(Option<Tensor>, Option<Tensor>)> {
        let grad = grad.contiguous()?;
        // Images entering the first layer need no gradient.
        let dx = if x.track_op() {
            Some(grad.apply_op2_no_bwd(
                w,
                &GradInput {
                    stride: self.stride,
                    padding: self.padding,
                    x_dims: x.dims().to_vec(),
                },
            )?)
        } else {
            None
        };
        let dw = x.apply_op2_no_bwd(
            &grad,
            &GradWeight {
                stride: self.stride,
                padding: self.padding,
                w_dims: w.dims().to_vec(),
            },
        )?;
        Ok((dx, Some(dw)))
    }
}

/// `dx` from `dy` (arg 1) and `w` (arg 2).
struct GradInput {
    stride: usize,
    padding: usize,
    x_dims: Vec<usize>,
}

impl CustomOp2 for GradInput {
    fn name(&self) -> &'static str {
        "scaledp-conv2d-grad-input"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = Geom::new(&self.x_dims, l2.dims(), self.stride, self.padding)?;
        let (dy, w) = (values(s1, l1)?, values(s2, l2)?);
        let wm = Tensor::from_slice(w, (g.c_out, g.k()), &Device::Cpu)?;
        let p = g.pixels();
        let per = g.c_in * g.h * g.w;
        let mut dx = vec![0f32; g.b * per];
        let step = g.chunk();
        for s0 in (0..g.b).step_by(step) {
            let n = step.min(g.b - s0);
            let rows = to_rows(&dy[s0 * g.c_out * p..(s0 + n) * g.c_out * p], n, g.c_out, p);
            let rows = Tensor::from_vec(rows, (n * p, g.c_out), &Device::Cpu)?;
            let cols = rows.matmul(&wm)?.flatten_all()?.to_vec1::<f32>()?;
            let dst = &mut dx[s0 * per..(s0 + n) * per];
            if g.pointwise() {
                from_rows(&cols, n, g.c_in, p, dst);
            } else {
                col2im(&g, &cols, dst);
            }
        }
        Ok((CpuStorage::F32(dx), Shape::from(self.x_dims.clone())))
    }
}

/// `dw` from `x` (arg 1) and `dy` (arg 2).
struct GradWeight {
    stride: usize,
    padding: usize,
    w_dims: Vec<usize>,
}

impl CustomOp2 for GradWeight {
    fn name(&self) -> &'static str {
        "scaledp-conv2d-grad-weight"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
    ) -> candle_core::Result<(CpuStorage, Shape)> {
        let g = Geom::new(l1.dims(), &self.w_dims, self.stride, self.padding)?;
        let (x, dy) = (values(s1, l1)?, values(s2, l2)?);
        let p = g.pixels();
        let mut dw: Option<Tensor> = None;
        let step = g.chunk();
        for s0 in (0..g.b).step_by(step) {
            let n = step.min(g.b - s0);
            let rows = to_rows(&dy[s0 * g.c_out * p..(s0 + n) * g.c_out * p], n, g.c_out, p);
            let rows = Tensor::from_vec(rows, (n * p, g.c_out), &Device::Cpu)?;
            let part = rows.t()?.matmul(&patches(&g, x, s0, n)?)?;
            dw = Some(match dw {
                None => part,
                Some(acc) => (acc + part)?,
            });
        }
        let dw = match dw {
            Some(t) => t.flatten_all()?.to_vec1::<f32>()?,
            None => vec![0f32; g.c_out * g.k()],
        };
        Ok((CpuStorage::F32(dw), Shape::from(self.w_dims.clone())))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Var;

    /// The op and its gradients against candle's own conv2d.
    #[test]
    fn matches_candles_conv2d_and_its_gradients() -> candle_core::Result<()> {
        let dev = Device::Cpu;
        for (c_in, c_out, h, w, k, stride, pad) in [
            (3, 5, 9, 11, 3, 1, 1),
            (4, 6, 12, 10, 3, 2, 1),
            (3, 4, 15, 13, 7, 2, 3),
            (6, 3, 7, 8, 1, 1, 0),
            // Square: candle's own backward takes the output padding of both axes from the
            // height, which breaks a strided 1×1 convolution of a 7×8 input.
            (6, 3, 8, 8, 1, 2, 0),
        ] {
            let x = Var::from_tensor(&Tensor::randn(0f32, 1., (2, c_in, h, w), &dev)?)?;
            let wt = Var::from_tensor(&Tensor::randn(0f32, 1., (c_out, c_in, k, k), &dev)?)?;
            let ours = conv2d(x.as_tensor(), wt.as_tensor(), stride, pad)?;
            let theirs = x.as_tensor().conv2d(wt.as_tensor(), pad, stride, 1, 1)?;
            assert_eq!(ours.dims(), theirs.dims());
            let diff = (&ours - &theirs)?.abs()?.max_all()?.to_scalar::<f32>()?;
            assert!(diff < 1e-4, "forward differs by {diff}");
            // A loss that weights every output differently.
            let m = Tensor::randn(0f32, 1., ours.dims(), &dev)?;
            let g1 = (ours * &m)?.sum_all()?.backward()?;
            let g2 = (theirs * &m)?.sum_all()?.backward()?;
            for v in [&x, &wt] {
                let (a, b) = (g1.get(v.as_tensor()), g2.get(v.as_tensor()));
                let (Some(a), Some(b)) = (a, b) else {
                    panic!("no gradient")
                };
                let d = (a - b)?.abs()?.max_all()?.to_scalar::<f32>()?;
                let scale = b.abs()?.max_all()?.to_scalar::<f32>()?;
                assert!(
                    d <= 1e-4 * scale.max(1.0),
                    "gradient differs by {d} (of {scale})"
                );
            }
        }
        Ok(())
    }
}
