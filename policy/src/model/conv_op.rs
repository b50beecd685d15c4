//! [`conv2d_nhwc`]: the convolution as a differentiable candle op (the candle modules' path),
//! its forward and both gradients the kernels of [`super`].

use candle_core::{CpuStorage, CustomOp2, Layout, Shape, Tensor};

use super::{forward, grad_input, grad_weight, ohwi_to_oihw, oihw_to_ohwi, Geom};
use crate::model::cpu::values;

/// A convolution without bias, PyTorch's `Conv2d(..., bias=False)` with equal stride and
/// padding on both axes, on a channels-last input: `x` is `[B, H, W, C_in]`, `w` PyTorch's
/// `[C_out, C_in, kh, kw]`; the output is `[B, H', W', C_out]`. CPU and f32 only.
pub fn conv2d_nhwc(
    x: &Tensor,
    w: &Tensor,
    stride: usize,
    padding: usize,
) -> candle_core::Result<Tensor> {
    let x = x.contiguous()?;
    let w = w.contiguous()?;
    x.apply_op2(&w, Conv { stride, padding })
}

/// `y = conv(x, w)`; its backward is [`GradInput`] and [`GradWeight`].
struct Conv {
    stride: usize,
    padding: usize,
}

impl CustomOp2 for Conv {
    fn name(&self) -> &'static str {
        "scaledp-conv2d-nhwc"
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
        let wp = oihw_to_ohwi(&g, w);
        let mut out = vec![0f32; g.b * g.pixels() * g.c_out];
        forward(&g, x, &wp, false, &mut out);
        let shape = Shape::from((g.b, g.out_h(), g.out_w(), g.c_out));
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
        "scaledp-conv2d-nhwc-grad-input"
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
        let wp = oihw_to_ohwi(&g, w);
        let mut dx = vec![0f32; g.b * g.per_in()];
        grad_input(&g, dy, &wp, &mut dx, false);
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
        "scaledp-conv2d-nhwc-grad-weight"
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
        let mut dwp = vec![0f32; g.c_out * g.k()];
        grad_weight(&g, x, dy, &mut dwp);
        let dw = ohwi_to_oihw(&g, &dwp);
        Ok((CpuStorage::F32(dw), Shape::from(self.w_dims.clone())))
    }
}
