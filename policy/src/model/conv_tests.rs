//! The convolution and its gradients against candle's own conv2d.

use super::*;
use candle_core::{Device, Tensor, Var};

/// The op and its gradients against candle's own conv2d on the NCHW view.
#[test]
fn matches_candles_conv2d_and_its_gradients() -> candle_core::Result<()> {
    for (c_in, c_out, h, w, k, stride, pad) in [
        (3, 5, 9, 11, 3, 1, 1),
        (4, 6, 12, 10, 3, 2, 1),
        (3, 4, 15, 13, 7, 2, 3),
        (6, 3, 7, 8, 1, 1, 0),
        // Square: candle's own backward takes the output padding of both axes from the
        // height, which breaks a strided 1×1 convolution of a 7×8 input.
        (6, 3, 8, 8, 1, 2, 0),
    ] {
        check([2, h, w, c_in], [c_out, c_in, k, k], stride, pad)?;
    }
    Ok(())
}

/// Chunked patch matrices (more samples than one chunk holds) give the same result.
#[test]
fn chunks_add_up() -> candle_core::Result<()> {
    let g = Geom::new(&[5, 80, 80, 64], &[4, 64, 3, 3], 1, 1)?;
    assert!(g.chunk() < 5, "the case must span several chunks");
    check([5, 80, 80, 64], [4, 64, 3, 3], 1, 1)
}

/// A training batch's chunks run side by side, one thread each, and the weight gradient's
/// per-thread sums add up: with a chunk per sample and an odd batch (a last chunk alone), with
/// cache-sized chunks of several samples, several to a thread (the recipe's 32-channel layer),
/// and with a strided kernel.
#[test]
fn side_by_side_chunks_add_up() -> candle_core::Result<()> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .map_err(candle_core::Error::wrap)?;
    pool.install(|| {
        for (x, w, stride, pad) in [
            ([9, 80, 80, 64], [4, 64, 3, 3], 1, 1),
            ([16, 15, 15, 32], [32, 32, 3, 3], 1, 1),
            ([12, 15, 13, 3], [5, 3, 7, 7], 2, 3),
        ] {
            let g = Geom::new(&x, &w, stride, pad)?;
            let plan = Plan::new(&g);
            assert!(plan.parallel, "{x:?} must run side by side");
            if x[3] == 32 {
                assert!(
                    plan.step > 1 && plan.step < 8,
                    "{x:?}: {} a chunk",
                    plan.step
                );
            }
            check(x, w, stride, pad)?;
            // The same gradient to the last bit, run after run.
            let xs: Vec<f32> = (0..g.b * g.per_in())
                .map(|i| (i % 13) as f32 * 0.1)
                .collect();
            let dy: Vec<f32> = (0..g.b * g.pixels() * g.c_out)
                .map(|i| ((i % 7) as f32 - 3.0) * 0.3)
                .collect();
            let runs: Vec<Vec<f32>> = (0..3)
                .map(|_| {
                    let mut dw = vec![0f32; g.c_out * g.k()];
                    grad_weight(&g, &xs, &dy, &mut dw);
                    dw
                })
                .collect();
            assert!(
                runs.windows(2).all(|r| r[0] == r[1]),
                "{x:?}: not repeatable"
            );
        }
        Ok(())
    })
}

/// [`conv2d_nhwc`] of an `x`-shaped input and a `w`-shaped kernel, and its gradients, against
/// candle's conv2d.
fn check(x: [usize; 4], w: [usize; 4], stride: usize, pad: usize) -> candle_core::Result<()> {
    let dev = Device::Cpu;
    let x = Var::from_tensor(&Tensor::randn(0f32, 1., &x, &dev)?)?;
    let wt = Var::from_tensor(&Tensor::randn(0f32, 0.1, &w, &dev)?)?;
    let ours = conv2d_nhwc(x.as_tensor(), wt.as_tensor(), stride, pad)?;
    let theirs = x
        .as_tensor()
        .permute((0, 3, 1, 2))?
        .conv2d(wt.as_tensor(), pad, stride, 1, 1)?
        .permute((0, 2, 3, 1))?;
    assert_eq!(ours.dims(), theirs.dims());
    let diff = (&ours - &theirs)?.abs()?.max_all()?.to_scalar::<f32>()?;
    let scale = theirs.abs()?.max_all()?.to_scalar::<f32>()?;
    assert!(
        diff <= 1e-5 * scale.max(1.0),
        "forward differs by {diff} (of {scale})"
    );
    // A loss that weights every output differently.
    let m = Tensor::randn(0f32, 1., ours.dims(), &dev)?;
    let g1 = (ours * &m)?.sum_all()?.backward()?;
    let g2 = (theirs * &m)?.sum_all()?.backward()?;
    for v in [&x, &wt] {
        let (Some(a), Some(b)) = (g1.get(v.as_tensor()), g2.get(v.as_tensor())) else {
            panic!("no gradient")
        };
        let d = (a - b)?.abs()?.max_all()?.to_scalar::<f32>()?;
        let scale = b.abs()?.max_all()?.to_scalar::<f32>()?;
        assert!(
            d <= 1e-4 * scale.max(1.0),
            "gradient differs by {d} (of {scale})"
        );
    }
    Ok(())
}
