//! Test support: a convolution's kernels held to the im2col ones ([`super`]) on one geometry.

use super::{forward_im2col, grad_input_im2col, grad_weight_im2col, Geom};

/// Deterministic values in [−1, 1).
pub(crate) fn values(n: usize, seed: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (((i * 7919 + seed * 104_729) % 2003) as f32 / 1001.0) - 1.0)
        .collect()
}

/// A convolution's three kernels, the OHWI kernel `wp` as in [`super::forward`].
pub(crate) struct Kernels {
    pub name: &'static str,
    /// `(g, x, wp, out)`: `out` overwritten.
    pub forward: fn(&Geom, &[f32], &[f32], &mut [f32]),
    /// `(g, dy, wp, dx, accumulate)`.
    pub grad_input: fn(&Geom, &[f32], &[f32], &mut [f32], bool),
    /// `(g, x, dy, dwp)`: `dwp` overwritten.
    pub grad_weight: fn(&Geom, &[f32], &[f32], &mut [f32]),
}

fn close(what: &str, k: &Kernels, a: &[f32], b: &[f32], tol: f32) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(1f32, |m, v| m.max(v.abs()));
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= tol * scale,
            "{what}[{i}]: {} {x} vs im2col {y} (scale {scale})",
            k.name
        );
    }
}

/// Forward, input gradient (overwritten and accumulated) and weight gradient of `g` by `k`
/// equal im2col's within `tol` of the largest value (f32 rounding).
pub(crate) fn against_im2col(g: &Geom, k: &Kernels, tol: f32) {
    let out = g.b * g.pixels() * g.c_out;
    let (x, wp, dy) = (
        values(g.b * g.per_in(), 1),
        values(g.c_out * g.k(), 2),
        values(out, 3),
    );
    let (mut ours, mut theirs) = (values(out, 7), vec![0f32; out]);
    (k.forward)(g, &x, &wp, &mut ours);
    forward_im2col(g, &x, &wp, false, &mut theirs);
    close("forward", k, &ours, &theirs, tol);
    let start = values(g.b * g.per_in(), 4);
    for acc in [false, true] {
        let (mut ours, mut theirs) = (start.clone(), start.clone());
        (k.grad_input)(g, &dy, &wp, &mut ours, acc);
        grad_input_im2col(g, &dy, &wp, &mut theirs, acc);
        close("input gradient", k, &ours, &theirs, tol);
    }
    let (mut ours, mut theirs) = (vec![1f32; wp.len()], vec![0f32; wp.len()]);
    (k.grad_weight)(g, &x, &dy, &mut ours);
    grad_weight_im2col(g, &x, &dy, &mut theirs);
    close("weight gradient", k, &ours, &theirs, tol);
}
