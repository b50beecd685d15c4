//! torchvision's ResNet-18 trunk (`children()[:-2]`: no average pool, no classifier) with every
//! BatchNorm replaced by GroupNorm(C/16 groups), as diffusion_policy's `replace_bn_with_gn`
//! leaves it. Weight names are torchvision's (`conv1`, `bn1`, `layer1.0.conv1`,
//! `layer2.0.downsample.0`, ...); the GroupNorms keep the BatchNorms' names.

use candle_core::Tensor;

use crate::error::Result;
use crate::model::conv::conv2d_nhwc;
use crate::model::fused;
use crate::model::params::{Builder, Init};

/// GroupNorm's epsilon (PyTorch's default).
const GN_EPS: f64 = 1e-5;

/// A bias-free convolution, initialised as torchvision does (`kaiming_normal_`, fan out).
#[derive(Clone, Debug)]
pub(crate) struct Conv {
    weight: Tensor,
    stride: usize,
    padding: usize,
}

impl Conv {
    fn new(vb: &Builder, c_in: usize, c_out: usize, k: usize, stride: usize) -> Result<Self> {
        let weight = vb.get(&[c_out, c_in, k, k], "weight", Init::KaimingFanOut, true)?;
        Ok(Conv {
            weight,
            stride,
            padding: k / 2,
        })
    }
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        Ok(if x.device().is_cpu() {
            conv2d_nhwc(x, &self.weight, self.stride, self.padding)?
        } else {
            conv2d_any_shape(x, &self.weight, self.padding, self.stride)?
        })
    }
}

/// candle's `conv2d` (NCHW, any device) whose backward also holds for non-square inputs.
///
/// candle 0.11 computes a strided convolution's input gradient with a transposed convolution
/// whose `output_padding` it derives from the height alone, so when `(H + 2p − k) mod s` and
/// `(W + 2p − k) mod s` differ the gradient comes out one column short or long and the backward
/// pass fails (on CUDA: the default 320×240 → 288×216 crop meets it in `layer3`, 27×36). Zero
/// rows or columns appended below or right make both remainders 0; they lie where the
/// convolution's own zero padding already is for every output kept, so the kept outputs are
/// unchanged, and the extra output row or column is cut off again.
pub(crate) fn conv2d_any_shape(
    x: &Tensor,
    w: &Tensor,
    padding: usize,
    stride: usize,
) -> Result<Tensor> {
    let (_, _, h, wd) = x.dims4()?;
    let (_, _, kh, kw) = w.dims4()?;
    let rem = |n: usize, k: usize| (n + 2 * padding).saturating_sub(k) % stride.max(1);
    let (rh, rw) = (rem(h, kh), rem(wd, kw));
    if rh == rw {
        return Ok(x.conv2d(w, padding, stride, 1, 1)?);
    }
    let extra = |r: usize| (stride - r) % stride;
    let y = x
        .pad_with_zeros(2, 0, extra(rh))?
        .pad_with_zeros(3, 0, extra(rw))?
        .conv2d(w, padding, stride, 1, 1)?;
    let out = |n: usize, k: usize| (n + 2 * padding - k) / stride + 1;
    Ok(y.narrow(2, 0, out(h, kh))?.narrow(3, 0, out(wd, kw))?)
}

/// diffusion_policy's GroupNorm for a BatchNorm of `c` channels: `c / 16` groups (at least one).
#[derive(Clone, Debug)]
pub(crate) struct GroupNorm {
    weight: Tensor,
    bias: Tensor,
    groups: usize,
}

impl GroupNorm {
    fn new(vb: &Builder, c: usize) -> Result<Self> {
        Ok(GroupNorm {
            weight: vb.get(&[c], "weight", Init::Ones, false)?,
            bias: vb.get(&[c], "bias", Init::Zeros, false)?,
            groups: (c / 16).max(1),
        })
    }

    /// The norm, then a ReLU when `relu`.
    fn forward(&self, x: &Tensor, relu: bool) -> Result<Tensor> {
        let (w, b, g) = (&self.weight, &self.bias, self.groups);
        Ok(if x.device().is_cpu() {
            fused::group_norm_nhwc(x, w, b, g, GN_EPS, relu)?
        } else {
            fused::group_norm_nchw(x, w, b, g, GN_EPS, relu)?
        })
    }
}

#[derive(Clone, Debug)]
struct BasicBlock {
    conv1: Conv,
    bn1: GroupNorm,
    conv2: Conv,
    bn2: GroupNorm,
    downsample: Option<(Conv, GroupNorm)>,
}

impl BasicBlock {
    fn new(vb: &Builder, c_in: usize, c_out: usize, stride: usize) -> Result<Self> {
        let downsample = if stride != 1 || c_in != c_out {
            let d = vb.pp("downsample");
            Some((
                Conv::new(&d.pp(0), c_in, c_out, 1, stride)?,
                GroupNorm::new(&d.pp(1), c_out)?,
            ))
        } else {
            None
        };
        Ok(BasicBlock {
            conv1: Conv::new(&vb.pp("conv1"), c_in, c_out, 3, stride)?,
            bn1: GroupNorm::new(&vb.pp("bn1"), c_out)?,
            conv2: Conv::new(&vb.pp("conv2"), c_out, c_out, 3, 1)?,
            bn2: GroupNorm::new(&vb.pp("bn2"), c_out)?,
            downsample,
        })
    }

    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let y = self.bn1.forward(&self.conv1.forward(x)?, true)?;
        let y = self.bn2.forward(&self.conv2.forward(&y)?, false)?;
        let skip = match &self.downsample {
            Some((conv, norm)) => norm.forward(&conv.forward(x)?, false)?,
            None => x.clone(),
        };
        Ok(if y.device().is_cpu() {
            fused::add_relu(&y, &skip)?
        } else {
            (y + skip)?.relu()?
        })
    }
}

/// The trunk: `[N, 3, H, W]` → `[N, 8·width, ⌈H/32⌉, ⌈W/32⌉]` (512 channels at width 64).
#[derive(Clone, Debug)]
pub(crate) struct ResNet18 {
    conv1: Conv,
    bn1: GroupNorm,
    layers: Vec<BasicBlock>,
}

impl ResNet18 {
    /// `width` is the first stage's channel count (64 in ResNet-18; tests use less).
    pub fn new(vb: &Builder, width: usize) -> Result<Self> {
        let mut layers = Vec::new();
        let mut c_in = width;
        for (stage, mult) in [1, 2, 4, 8].into_iter().enumerate() {
            let c_out = width * mult;
            let stride = if stage == 0 { 1 } else { 2 };
            let l = vb.pp(format!("layer{}", stage + 1));
            layers.push(BasicBlock::new(&l.pp(0), c_in, c_out, stride)?);
            layers.push(BasicBlock::new(&l.pp(1), c_out, c_out, 1)?);
            c_in = c_out;
        }
        Ok(ResNet18 {
            conv1: Conv::new(&vb.pp("conv1"), 3, width, 7, 2)?,
            bn1: GroupNorm::new(&vb.pp("bn1"), width)?,
            layers,
        })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let x = self.bn1.forward(&self.conv1.forward(x)?, true)?;
        let mut x = if x.device().is_cpu() {
            fused::max_pool_3x3_s2_nhwc(&x)?
        } else {
            max_pool_3x3_s2(&x)?
        };
        for block in &self.layers {
            x = block.forward(&x)?;
        }
        Ok(x)
    }
}

/// `MaxPool2d(3, stride=2, padding=1)` of a non-negative input (it follows a ReLU, so zero
/// padding is the same as PyTorch's −∞), composed of slices and `maximum` so that candle can
/// differentiate it (its own max-pool has no backward for kernel ≠ stride).
pub(crate) fn max_pool_3x3_s2(x: &Tensor) -> Result<Tensor> {
    let (n, c, h, w) = x.dims4()?;
    let (oh, ow) = ((h - 1) / 2 + 1, (w - 1) / 2 + 1);
    // One row/column of padding before, two after: every window start 2·o + i (i < 3) and the
    // pair it sits in fit.
    let p = x.pad_with_zeros(2, 1, 2)?.pad_with_zeros(3, 1, 2)?;
    let mut out: Option<Tensor> = None;
    for i in 0..3 {
        let rows = p
            .narrow(2, i, 2 * oh)?
            .reshape((n, c, oh, 2, w + 3))?
            .narrow(3, 0, 1)?;
        for j in 0..3 {
            let v = rows
                .narrow(4, j, 2 * ow)?
                .reshape((n, c, oh, 2 * ow))?
                .reshape((n, c, oh, ow, 2))?
                .narrow(4, 0, 1)?
                .reshape((n, c, oh, ow))?;
            out = Some(match out {
                None => v,
                Some(o) => o.maximum(&v)?,
            });
        }
    }
    Ok(out.unwrap_or(x.clone()))
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor, Var};

    use super::conv2d_any_shape;
    use crate::model::conv::conv2d_nhwc;

    /// The candle path (what CUDA runs) against the fused CPU convolution and its own backward,
    /// on the shapes where height and width leave different remainders: the input gradient,
    /// the kernel gradient and the output agree.
    #[test]
    fn non_square_strided_convolutions_have_the_right_gradients() -> crate::Result<()> {
        let dev = Device::Cpu;
        // (h, w, k, stride, padding): layer3 and its downsample at the 288×216 crop, the same
        // transposed, the stem at 72×41 (the tests' crop), a stride-1 case.
        for (h, w, k, s, p) in [
            (27, 36, 3, 2, 1),
            (27, 36, 1, 2, 0),
            (36, 27, 3, 2, 1),
            (41, 72, 7, 2, 3),
            (9, 12, 3, 1, 1),
        ] {
            let x = Var::from_tensor(&Tensor::randn(0f32, 1., (2, 4, h, w), &dev)?)?;
            let wt = Var::from_tensor(&Tensor::randn(0f32, 1., (5, 4, k, k), &dev)?)?;
            let ours = conv2d_any_shape(x.as_tensor(), wt.as_tensor(), p, s)?;
            let fused = conv2d_nhwc(&x.as_tensor().permute((0, 2, 3, 1))?, wt.as_tensor(), s, p)?
                .permute((0, 3, 1, 2))?;
            assert_eq!(ours.dims(), fused.dims(), "{h}×{w} k{k} s{s}");
            let d = (&ours - &fused)?.abs()?.max_all()?.to_scalar::<f32>()?;
            assert!(d < 1e-4, "{h}×{w} k{k} s{s}: forward differs by {d}");
            let m = Tensor::randn(0f32, 1., ours.dims(), &dev)?;
            let g1 = (ours * &m)?.sum_all()?.backward()?;
            let g2 = (fused * &m)?.sum_all()?.backward()?;
            for v in [&x, &wt] {
                let (Some(a), Some(b)) = (g1.get(v.as_tensor()), g2.get(v.as_tensor())) else {
                    panic!("no gradient")
                };
                assert_eq!(a.dims(), v.dims());
                let d = (a - b)?.abs()?.max_all()?.to_scalar::<f32>()?;
                let scale = b.abs()?.max_all()?.to_scalar::<f32>()?;
                assert!(
                    d <= 1e-4 * scale.max(1.0),
                    "{h}×{w} k{k} s{s}: {d} of {scale}"
                );
            }
        }
        Ok(())
    }

    /// What the workaround is for: candle's own backward of such a convolution fails. When a
    /// candle release fixes it, this test says so and the workaround can go.
    #[test]
    fn candles_own_backward_still_fails_on_them() -> candle_core::Result<()> {
        let dev = Device::Cpu;
        let x = Var::from_tensor(&Tensor::randn(0f32, 1., (1, 2, 27, 36), &dev)?)?;
        let wt = Var::from_tensor(&Tensor::randn(0f32, 1., (3, 2, 3, 3), &dev)?)?;
        let y = x.as_tensor().conv2d(wt.as_tensor(), 1, 2, 1, 1)?;
        assert!(y.sum_all()?.backward().is_err());
        Ok(())
    }
}
