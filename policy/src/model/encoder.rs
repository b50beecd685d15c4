//! diffusion_policy's image encoder (robomimic's `VisualCore`), one per camera: crop, scale to
//! [−1, 1] (diffusion_policy's image range normalizer; [0, 1] for older checkpoints),
//! ResNet-18-GN trunk, SpatialSoftmax (32 keypoints → 64 values), Linear(64 → 64).
//! No ImageNet normalisation: diffusion_policy applies none to encoders trained from scratch.
//!
//! Weight names under the encoder's prefix (`obs_encoder.<camera>.`): `backbone.*` (the trunk,
//! torchvision names), `pool.nets.{weight,bias}` (the keypoint 1×1 convolution, robomimic's
//! name), `linear.{weight,bias}`.

use candle_core::{Device, Tensor};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::config::ImageRange;
use crate::error::Result;
use crate::model::params::{Builder, Init};
use crate::model::resnet::ResNet18;

/// robomimic's `SpatialSoftmax`: a 1×1 convolution to `keypoints` maps, a softmax over each
/// map's pixels, and the expected (x, y) on a linspace(−1, 1) grid → `[N, 2·keypoints]`,
/// interleaved x0, y0, x1, y1, ...
#[derive(Clone, Debug)]
struct SpatialSoftmax {
    weight: Tensor,
    bias: Tensor,
    keypoints: usize,
}

impl SpatialSoftmax {
    fn new(vb: &Builder, c_in: usize, keypoints: usize) -> Result<Self> {
        Ok(SpatialSoftmax {
            weight: vb.get(
                &[keypoints, c_in, 1, 1],
                "weight",
                Init::FanInUniform(c_in),
                true,
            )?,
            bias: vb.get(&[keypoints], "bias", Init::FanInUniform(c_in), false)?,
            keypoints,
        })
    }

    /// `x` is channels-last `[N, h, w, C]` on the CPU, channels-first elsewhere.
    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let k = self.keypoints;
        let (n, h, w, maps) = if x.device().is_cpu() {
            // The 1×1 convolution of channels-last maps is one matrix product.
            let (n, h, w, c) = x.dims4()?;
            let maps = x
                .reshape((n * h * w, c))?
                .matmul(&self.weight.reshape((k, c))?.t()?)?
                .broadcast_add(&self.bias)?
                .reshape((n, h * w, k))?
                .transpose(1, 2)?
                .contiguous()?;
            (n, h, w, maps)
        } else {
            let (n, _, h, w) = x.dims4()?;
            let maps = x
                .conv2d(&self.weight, 0, 1, 1, 1)?
                .broadcast_add(&self.bias.reshape((1, k, 1, 1))?)?;
            (n, h, w, maps)
        };
        let maps = maps.reshape((n * k, h * w))?;
        let attention = candle_nn::ops::softmax(&maps, 1)?;
        let grid = Tensor::from_vec(grid(h, w), (h * w, 2), x.device())?;
        Ok(attention.matmul(&grid)?.reshape((n, 2 * k))?)
    }
}

/// `[h·w, 2]`: (x, y) of each pixel, x = linspace(−1, 1, w)[col], y = linspace(−1, 1, h)[row].
fn grid(h: usize, w: usize) -> Vec<f32> {
    let lin = |i: usize, n: usize| -> f32 {
        if n <= 1 {
            -1.0
        } else {
            (-1.0 + 2.0 * i as f64 / (n - 1) as f64) as f32
        }
    };
    let mut g = Vec::with_capacity(h * w * 2);
    for r in 0..h {
        for c in 0..w {
            g.push(lin(c, w));
            g.push(lin(r, h));
        }
    }
    g
}

/// One camera's encoder: `[N, 3, h, w]` in [0, 1] → `[N, feature_dim]`.
#[derive(Clone, Debug)]
pub(crate) struct ObsEncoder {
    backbone: ResNet18,
    pool: SpatialSoftmax,
    linear_w: Tensor,
    linear_b: Tensor,
}

impl ObsEncoder {
    pub fn new(vb: &Builder, width: usize, keypoints: usize, feature_dim: usize) -> Result<Self> {
        let backbone = ResNet18::new(&vb.pp("backbone"), width)?;
        let pool = SpatialSoftmax::new(&vb.pp("pool").pp("nets"), 8 * width, keypoints)?;
        let l = vb.pp("linear");
        let fan_in = 2 * keypoints;
        Ok(ObsEncoder {
            backbone,
            pool,
            linear_w: l.get(
                &[feature_dim, fan_in],
                "weight",
                Init::FanInUniform(fan_in),
                true,
            )?,
            linear_b: l.get(&[feature_dim], "bias", Init::FanInUniform(fan_in), false)?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let f = self.pool.forward(&self.backbone.forward(x)?)?;
        Ok(f.matmul(&self.linear_w.t()?)?
            .broadcast_add(&self.linear_b)?)
    }
}

/// Where each image is cropped: random offsets (training; one draw per image, as
/// diffusion_policy's `CropRandomizer`) or the centre (inference).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crop {
    /// A random window per image.
    Random,
    /// The centred window.
    Center,
}

/// torchvision's `center_crop` offset of a margin `d`: `int(round(d / 2))`, Python rounding
/// half to even.
fn centre(d: usize) -> usize {
    let half = d / 2;
    if d % 2 == 1 && half % 2 == 1 {
        half + 1
    } else {
        half
    }
}

/// Crops `n` uint8 RGB images `[n, 3, h, w]` to `[n, 3, ch, cw]` (`[n, ch, cw, 3]` when
/// `channels_last`) and scales them as `range` says. `pick(i)` selects image i of the source
/// (so one camera can be taken out of a batch laid out `[B, To, cams, 3, H, W]`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn crop_images(
    src: &[u8],
    range: ImageRange,
    pick: impl Fn(usize) -> usize,
    n: usize,
    (w, h): (usize, usize),
    (cw, ch): (usize, usize),
    crop: Crop,
    channels_last: bool,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> Result<Tensor> {
    let out = crop_values(
        src,
        range,
        pick,
        n,
        (w, h),
        (cw, ch),
        crop,
        channels_last,
        rng,
    );
    Ok(if channels_last {
        Tensor::from_vec(out, (n, ch, cw, 3), device)?
    } else {
        Tensor::from_vec(out, (n, 3, ch, cw), device)?
    })
}

/// [`crop_images`]' values: the same draws from `rng` (one window per image, in order), the
/// same arithmetic.
#[allow(clippy::too_many_arguments)]
pub(crate) fn crop_values(
    src: &[u8],
    range: ImageRange,
    pick: impl Fn(usize) -> usize,
    n: usize,
    (w, h): (usize, usize),
    (cw, ch): (usize, usize),
    crop: Crop,
    channels_last: bool,
    rng: &mut ChaCha8Rng,
) -> Vec<f32> {
    let plane = w * h;
    let (scale, offset) = range.affine();
    let lut: Vec<f32> = (0..=255u8)
        .map(|p| (f64::from(p) * f64::from(scale) + f64::from(offset)) as f32)
        .collect();
    let mut out = vec![0f32; n * 3 * ch * cw];
    for i in 0..n {
        let (y0, x0) = match crop {
            Crop::Random => (rng.random_range(0..=h - ch), rng.random_range(0..=w - cw)),
            Crop::Center => (centre(h - ch), centre(w - cw)),
        };
        let img = &src[pick(i) * 3 * plane..(pick(i) + 1) * 3 * plane];
        let dst = &mut out[i * 3 * ch * cw..(i + 1) * 3 * ch * cw];
        for c in 0..3 {
            for r in 0..ch {
                let s = &img[c * plane + (y0 + r) * w + x0..][..cw];
                if channels_last {
                    let d = &mut dst[r * cw * 3..(r + 1) * cw * 3];
                    for (k, s) in s.iter().enumerate() {
                        d[k * 3 + c] = lut[usize::from(*s)];
                    }
                } else {
                    let d = &mut dst[(c * ch + r) * cw..][..cw];
                    for (d, s) in d.iter_mut().zip(s) {
                        *d = lut[usize::from(*s)];
                    }
                }
            }
        }
    }
    out
}
