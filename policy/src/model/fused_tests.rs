//! Tests of the fused kernels against candle's composed ops and plain references.

use super::*;
use candle_core::{Device, Var};

fn max_diff(a: &Tensor, b: &Tensor) -> f32 {
    (a - b)
        .and_then(|d| d.abs())
        .and_then(|d| d.max_all())
        .and_then(|d| d.to_scalar::<f32>())
        .unwrap_or(f32::INFINITY)
}

/// The fused op and its gradients against the composed one (which candle differentiates)
/// on the NCHW view of the same values.
#[test]
fn fused_group_norm_matches_the_composed_one() -> candle_core::Result<()> {
    let dev = Device::Cpu;
    for relu in [false, true] {
        let x = Var::from_tensor(&(Tensor::randn(0f32, 1., (3, 5, 4, 8), &dev)? * 3.0)?)?;
        let g = Var::from_tensor(&Tensor::randn(1f32, 0.5, 8, &dev)?)?;
        let b = Var::from_tensor(&Tensor::randn(0f32, 0.5, 8, &dev)?)?;
        let ours = group_norm_nhwc(x.as_tensor(), g.as_tensor(), b.as_tensor(), 2, 1e-5, relu)?;
        let theirs = group_norm_nchw(
            &x.as_tensor().permute((0, 3, 1, 2))?,
            g.as_tensor(),
            b.as_tensor(),
            2,
            1e-5,
            relu,
        )?
        .permute((0, 2, 3, 1))?;
        assert!(max_diff(&ours, &theirs) < 1e-5);
        let m = Tensor::randn(0f32, 1., (3, 5, 4, 8), &dev)?;
        let g1 = (ours * &m)?.sum_all()?.backward()?;
        let g2 = (theirs * &m)?.sum_all()?.backward()?;
        for v in [&x, &g, &b] {
            let (Some(a), Some(e)) = (g1.get(v.as_tensor()), g2.get(v.as_tensor())) else {
                panic!("no gradient");
            };
            assert!(max_diff(a, e) < 1e-4, "relu {relu}: {}", max_diff(a, e));
        }
    }
    Ok(())
}

#[test]
fn max_pool_matches_pytorchs_padding_and_routes_gradients_to_the_max() -> candle_core::Result<()> {
    let dev = Device::Cpu;
    // Two channels: c0 = 0..35, c1 = its negation (a different maximum per window).
    let plane = Tensor::arange(0f32, 35., &dev)?.reshape((1, 5, 7, 1))?;
    let x = Tensor::cat(&[&plane, &plane.neg()?], 3)?;
    let y = max_pool_3x3_s2_nhwc(&x)?;
    assert_eq!(y.dims(), &[1, 3, 4, 2]);
    // Window of output (0, 0) covers rows 0..2, cols 0..2: max is x[1][1] = 8.
    let v = y.narrow(3, 0, 1)?.flatten_all()?.to_vec1::<f32>()?;
    assert_eq!(
        v,
        vec![8., 10., 12., 13., 22., 24., 26., 27., 29., 31., 33., 34.]
    );
    // Of the negated plane, the window's first (top-left) value.
    let v = y.narrow(3, 1, 1)?.flatten_all()?.to_vec1::<f32>()?;
    assert_eq!(
        v,
        vec![-0., -1., -3., -5., -7., -8., -10., -12., -21., -22., -24., -26.]
    );
    let xv = Var::from_tensor(&x)?;
    let g = max_pool_3x3_s2_nhwc(xv.as_tensor())?
        .sum_all()?
        .backward()?;
    let dx = g.get(xv.as_tensor()).map(|t| t.flatten_all()).transpose()?;
    let dx = dx
        .map(|t| t.to_vec1::<f32>())
        .transpose()?
        .unwrap_or_default();
    assert_eq!(dx.iter().sum::<f32>(), 24.0);
    // x[1][1] of channel 0 is flat index (1·7 + 1)·2.
    assert_eq!(dx[16], 1.0);
    Ok(())
}

/// The window search one value at a time, with branches: the first maximum in row-major
/// order, a NaN taking over.
fn argmax_reference(x: &[f32], h: usize, w: usize, c: usize) -> Vec<u32> {
    let (oh, ow) = (pooled(h), pooled(w));
    let mut idx = vec![u32::MAX; oh * ow * c];
    for oy in 0..oh {
        for ox in 0..ow {
            for ch in 0..c {
                let at = &mut idx[(oy * ow + ox) * c + ch];
                let mut best = f32::NEG_INFINITY;
                for y in (2 * oy).saturating_sub(1)..(2 * oy + 2).min(h) {
                    for xx in (2 * ox).saturating_sub(1)..(2 * ox + 2).min(w) {
                        let k = (y * w + xx) * c + ch;
                        let v = x[k];
                        if *at == u32::MAX || v > best || (v.is_nan() && !best.is_nan()) {
                            best = v;
                            *at = k as u32;
                        }
                    }
                }
            }
        }
    }
    idx
}

#[test]
fn max_pool_takes_the_first_of_tied_maxima_and_propagates_nan() {
    // Values in 0..4 (ties in most windows), two NaNs and a −∞; odd and even sides.
    for (h, w, c) in [(7, 6, 5), (8, 9, 3), (1, 1, 17), (2, 3, 16)] {
        let mut x: Vec<f32> = (0..h * w * c)
            .map(|i| ((i * 7 + i / 3) % 4) as f32)
            .collect();
        let last = x.len() - 1;
        x[(c + 1) % last] = f32::NAN;
        x[last] = f32::NAN;
        x[0] = f32::NEG_INFINITY;
        let want = argmax_reference(&x, h, w, c);
        assert_eq!(argmax(&x, h, w, c), want, "{h}×{w}×{c}");
        let mut y = vec![0f32; want.len()];
        max_pool_forward((h, w, c), &x, &mut y);
        for (got, &k) in y.iter().zip(&want) {
            let v = x[k as usize];
            assert!(
                got.to_bits() == v.to_bits(),
                "{h}×{w}×{c}: {got} against {v}"
            );
        }
        let dy: Vec<f32> = (0..want.len()).map(|i| 1.0 + i as f32).collect();
        let mut dx = vec![0f32; x.len()];
        max_pool_backward((h, w, c), &x, &dy, &mut dx);
        let mut dx_want = vec![0f32; x.len()];
        for (&k, g) in want.iter().zip(&dy) {
            dx_want[k as usize] += g;
        }
        assert_eq!(dx, dx_want, "{h}×{w}×{c}");
    }
}

#[test]
fn add_relu_and_its_gradient_match_candles() -> candle_core::Result<()> {
    let dev = Device::Cpu;
    let a = Var::from_tensor(&Tensor::randn(0f32, 1., (4, 3, 5), &dev)?)?;
    let b = Var::from_tensor(&Tensor::randn(0f32, 1., (4, 3, 5), &dev)?)?;
    let ours = add_relu(a.as_tensor(), b.as_tensor())?;
    let theirs = (a.as_tensor() + b.as_tensor())?.relu()?;
    assert!(max_diff(&ours, &theirs) == 0.0);
    let m = Tensor::randn(0f32, 1., (4, 3, 5), &dev)?;
    let g1 = (ours * &m)?.sum_all()?.backward()?;
    let g2 = (theirs * &m)?.sum_all()?.backward()?;
    for v in [&a, &b] {
        let (Some(x), Some(y)) = (g1.get(v.as_tensor()), g2.get(v.as_tensor())) else {
            panic!("no gradient");
        };
        assert!(max_diff(x, y) < 1e-6);
    }
    Ok(())
}
