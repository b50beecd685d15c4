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
            x.conv2d(&self.weight, self.padding, self.stride, 1, 1)?
        })
    }
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
