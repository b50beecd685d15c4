//! DP-T's row operations beyond ScaleDP's ([`crate::engine::ops`]): LayerNorm's affine part,
//! exact (erf) GELU, Mish, and residuals through a dropout mask, each with its backward.

use rayon::prelude::*;

use crate::engine::ops::rows_per_task;
use crate::model::cpu::vectorized;

/// `u = n · w + b` over rows of `d` (LayerNorm's affine part on the normalized `n`).
pub(crate) fn affine(n: &[f32], w: &[f32], b: &[f32], d: usize, u: &mut [f32]) {
    let per = rows_per_task(n.len() / d, d) * d;
    u[..n.len()]
        .par_chunks_mut(per)
        .zip(n.par_chunks(per))
        .for_each(|(us, ns)| {
            vectorized(|| {
                for (ur, nr) in us.chunks_exact_mut(d).zip(ns.chunks_exact(d)) {
                    for j in 0..d {
                        ur[j] = nr[j] * w[j] + b[j];
                    }
                }
            })
        });
}

/// The backward of [`affine`]: `dn = du · w`, `dw += Σ du · n`, `db += Σ du` (the parameter
/// sums in float64, added in row order).
pub(crate) fn affine_backward(
    n: &[f32],
    w: &[f32],
    du: &[f32],
    d: usize,
    dn: &mut [f32],
    dw: &mut [f32],
    db: &mut [f32],
) {
    let per = rows_per_task(n.len() / d, d).max(16) * d;
    let partial: Vec<(Vec<f64>, Vec<f64>)> = dn[..n.len()]
        .par_chunks_mut(per)
        .zip(n.par_chunks(per).zip(du.par_chunks(per)))
        .map(|(dns, (ns, dus))| {
            let (mut sw, mut sb) = (vec![0f64; d], vec![0f64; d]);
            for (dnr, (nr, dur)) in dns
                .chunks_exact_mut(d)
                .zip(ns.chunks_exact(d).zip(dus.chunks_exact(d)))
            {
                for j in 0..d {
                    dnr[j] = dur[j] * w[j];
                    sw[j] += f64::from(dur[j] * nr[j]);
                    sb[j] += f64::from(dur[j]);
                }
            }
            (sw, sb)
        })
        .collect();
    for j in 0..d {
        dw[j] += partial.iter().map(|p| p.0[j]).sum::<f64>() as f32;
        db[j] += partial.iter().map(|p| p.1[j]).sum::<f64>() as f32;
    }
}

/// eˣ in float32, branch-free so a loop of it vectorizes (libm's `expf`, one value at a time,
/// made the FFN's GELU and its gradient a fifth of a DP-T step): Cephes' `expf` — x = n·ln 2 +
/// r with |r| ≤ ln 2 / 2, a degree-6 polynomial for eʳ, and 2ⁿ put into the exponent bits.
/// Within 2.5e-7 of `f32::exp` relatively (the test); e⁻⁸⁷·³ below −87.3, e⁸⁸·⁷ above 88.7.
#[inline]
pub(crate) fn exp(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    const C1: f32 = 0.693_359_4;
    const C2: f32 = -2.121_944_4e-4;
    let x = x.clamp(-87.3, 88.7);
    let n = (x * LOG2E + 0.5).floor();
    let r = x - n * C1 - n * C2;
    let z = r * r;
    let p = (((((1.987_569_2e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2)
        * r
        + 0.166_666_65)
        * r
        + 0.5)
        * z
        + r
        + 1.0;
    p * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

/// erf by Abramowitz & Stegun 7.1.26 (|error| ≤ 1.5·10⁻⁷, PyTorch's vectorized CPU erf):
/// branch-free, so a loop of it vectorizes.
#[inline]
pub(crate) fn erf(x: f32) -> f32 {
    const P: f32 = 0.327_591_1;
    const A: [f32; 5] = [
        0.254_829_6,
        -0.284_496_74,
        1.421_413_8,
        -1.453_152_1,
        1.061_405_4,
    ];
    let ax = x.abs();
    let t = 1.0 / (1.0 + P * ax);
    let poly = ((((A[4] * t + A[3]) * t + A[2]) * t + A[1]) * t + A[0]) * t;
    let y = 1.0 - poly * exp(-ax * ax);
    y.copysign(x)
}

const FRAC_1_SQRT_2: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// 1 / √(2π).
const INV_SQRT_2PI: f32 = 0.398_942_3;

/// Exact GELU, `x · Φ(x)` (PyTorch's default `F.gelu`, the decoder layers' `activation="gelu"`).
#[inline]
pub(crate) fn gelu_erf(x: f32) -> f32 {
    0.5 * x * (1.0 + erf(x * FRAC_1_SQRT_2))
}

/// d GELU / dx = Φ(x) + x · φ(x).
#[inline]
pub(crate) fn gelu_erf_grad(x: f32) -> f32 {
    0.5 * (1.0 + erf(x * FRAC_1_SQRT_2)) + x * INV_SQRT_2PI * exp(-0.5 * x * x)
}

/// softplus, `ln(1 + eˣ)`, without overflow.
#[inline]
fn softplus(x: f32) -> f32 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

/// Mish, `x · tanh(softplus(x))` (the condition encoder's activation).
#[inline]
pub(crate) fn mish(x: f32) -> f32 {
    x * softplus(x).tanh()
}

/// d Mish / dx = tanh(sp) + x · (1 − tanh²(sp)) · σ(x).
#[inline]
pub(crate) fn mish_grad(x: f32) -> f32 {
    let t = softplus(x).tanh();
    let sig = 1.0 / (1.0 + (-x).exp());
    t + x * (1.0 - t * t) * sig
}

/// `h += a ∘ m` (a residual branch through a dropout mask; `m` empty: no dropout).
pub(crate) fn residual(h: &mut [f32], a: &[f32], m: &[f32]) {
    h[..a.len()]
        .par_chunks_mut(1 << 14)
        .enumerate()
        .for_each(|(c, hs)| {
            let o = c << 14;
            let a = &a[o..o + hs.len()];
            vectorized(|| {
                if m.is_empty() {
                    for (h, a) in hs.iter_mut().zip(a) {
                        *h += a;
                    }
                } else {
                    let m = &m[o..o + hs.len()];
                    for ((h, a), m) in hs.iter_mut().zip(a).zip(m) {
                        *h += a * m;
                    }
                }
            })
        });
}

/// `y ∘= m` (`m` empty: nothing).
pub(crate) fn mask_in_place(y: &mut [f32], m: &[f32]) {
    if m.is_empty() {
        return;
    }
    y[..m.len()]
        .par_chunks_mut(1 << 14)
        .zip(m.par_chunks(1 << 14))
        .for_each(|(ys, ms)| {
            vectorized(|| {
                for (y, m) in ys.iter_mut().zip(ms) {
                    *y *= m;
                }
            })
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// erf, GELU, Mish and their derivatives against float64 references and central
    /// differences.
    #[test]
    fn activations_match_their_definitions() {
        fn erf64(x: f64) -> f64 {
            // Taylor series (converges everywhere; enough terms for |x| ≤ 4).
            let mut sum = 0.0;
            let mut term = x;
            for n in 0..200 {
                sum += term / (2 * n + 1) as f64;
                term *= -x * x / (n + 1) as f64;
            }
            sum * 2.0 / std::f64::consts::PI.sqrt()
        }
        for i in -400..=400 {
            let x = i as f64 / 100.0;
            let e = erf64(x);
            assert!((f64::from(erf(x as f32)) - e).abs() < 4e-7, "erf({x})");
            let g = 0.5 * x * (1.0 + erf64(x / 2f64.sqrt()));
            assert!((f64::from(gelu_erf(x as f32)) - g).abs() < 1e-6 * x.abs().max(1.0));
            let sp = (1.0 + x.exp()).ln();
            let m = x * sp.tanh();
            assert!((f64::from(mish(x as f32)) - m).abs() < 1e-6 * x.abs().max(1.0));
            let h = 1e-3f32;
            let xf = x as f32;
            let fd = |f: fn(f32) -> f32| (f(xf + h) - f(xf - h)) / (2.0 * h);
            assert!(
                (fd(gelu_erf) - gelu_erf_grad(xf)).abs() < 2e-3,
                "gelu'({x})"
            );
            assert!((fd(mish) - mish_grad(xf)).abs() < 2e-3, "mish'({x})");
        }
        assert_eq!(mish(100.0), 100.0);
        // The vectorizable exp against libm's over the range that matters and past its ends.
        let mut worst = 0f32;
        for i in -87_000..=88_000 {
            let x = i as f32 / 1000.0;
            let (a, b) = (exp(x), x.exp());
            worst = worst.max(((a - b) / b).abs());
        }
        assert!(worst < 2.5e-7, "exp: relative error {worst}");
        assert!(exp(-200.0) < 2e-38, "the smallest normal or less");
        assert!(exp(200.0) > 1e38);
        assert!(mish(-100.0).abs() < 1e-30);
    }
}
