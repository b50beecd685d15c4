//! The geometry of one convolution (channels-last input, OIHW kernel): what the convolution
//! kernels ([`super::conv`]'s im2col, [`super::winograd`], [`super::taps`]) share, in a module of
//! its own so that `conv` dispatches to the others and none of them imports `conv` back.

/// The geometry of one convolution.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geom {
    pub(crate) b: usize,
    pub(crate) c_in: usize,
    pub(crate) h: usize,
    pub(crate) w: usize,
    pub(crate) c_out: usize,
    pub(crate) kh: usize,
    pub(crate) kw: usize,
    pub(crate) stride: usize,
    pub(crate) padding: usize,
}

impl Geom {
    /// From the NHWC input's and the OIHW kernel's dims.
    pub(crate) fn new(
        x: &[usize],
        k: &[usize],
        stride: usize,
        padding: usize,
    ) -> candle_core::Result<Self> {
        let (&[b, h, w, c_in], &[c_out, kc, kh, kw]) = (x, k) else {
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
    pub(crate) fn out_h(&self) -> usize {
        (self.h + 2 * self.padding - self.kh) / self.stride + 1
    }
    pub(crate) fn out_w(&self) -> usize {
        (self.w + 2 * self.padding - self.kw) / self.stride + 1
    }
    pub(crate) fn pixels(&self) -> usize {
        self.out_h() * self.out_w()
    }
    pub(crate) fn k(&self) -> usize {
        self.c_in * self.kh * self.kw
    }
    /// Values of one input sample.
    pub(crate) fn per_in(&self) -> usize {
        self.h * self.w * self.c_in
    }
}
