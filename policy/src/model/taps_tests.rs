//! The tap-by-tap convolution and both gradients against the im2col kernels they replace.

use super::*;
use crate::model::conv;

fn values(n: usize, seed: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (((i * 7919 + seed * 104_729) % 2003) as f32 / 1001.0) - 1.0)
        .collect()
}

fn close(what: &str, a: &[f32], b: &[f32]) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    let scale = b.iter().fold(1f32, |m, v| m.max(v.abs()));
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= 1e-5 * scale,
            "{what}[{i}]: taps {x} vs im2col {y} (scale {scale})"
        );
    }
}

/// Forward, input gradient (overwritten and accumulated) and weight gradient equal im2col's.
fn check(
    b: usize,
    (h, w): (usize, usize),
    (ci, co): (usize, usize),
    (k, s, p): (usize, usize, usize),
) {
    let g = Geom::new(&[b, h, w, ci], &[co, ci, k, k], s, p).unwrap();
    let out = b * g.pixels() * co;
    let (x, wp, dy) = (
        values(b * h * w * ci, 1),
        values(co * g.k(), 2),
        values(out, 3),
    );
    let (mut ours, mut theirs) = (values(out, 7), vec![0f32; out]);
    forward(&g, &x, &wp, &mut ours);
    conv::forward_im2col(&g, &x, &wp, false, &mut theirs);
    close("forward", &ours, &theirs);
    let start = values(b * h * w * ci, 4);
    for acc in [false, true] {
        let (mut ours, mut theirs) = (start.clone(), start.clone());
        grad_input(&g, &dy, &wp, &mut ours, acc);
        conv::grad_input_im2col(&g, &dy, &wp, &mut theirs, acc);
        close("input gradient", &ours, &theirs);
    }
    let (mut ours, mut theirs) = (vec![1f32; wp.len()], vec![0f32; wp.len()]);
    grad_weight(&g, &x, &dy, &mut ours);
    conv::grad_weight_im2col(&g, &x, &dy, &mut theirs);
    close("weight gradient", &ours, &theirs);
}

/// The trunk's small maps (3×3 and 5×5 at stride 1, the strided convolutions into them), a
/// 2×2 and a non-square map, a 7×7 kernel whose taps mostly fall outside, on one thread and
/// on two (where batches of 8 or more run in chunks side by side).
#[test]
fn matches_im2col() {
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            check(3, (3, 3), (8, 5), (3, 1, 1));
            check(2, (5, 5), (3, 17), (3, 1, 1));
            check(4, (10, 10), (4, 6), (3, 2, 1));
            check(5, (2, 2), (16, 16), (3, 1, 1));
            check(2, (3, 4), (5, 3), (3, 1, 1));
            check(3, (6, 5), (2, 4), (7, 2, 3));
            // Batches large enough for chunks side by side (on two threads), one odd.
            check(9, (3, 3), (8, 5), (3, 1, 1));
            check(8, (5, 5), (4, 6), (3, 2, 1));
        });
    }
}

/// Only where 35 % of the taps or more fall on the padding: the trunk's 3×3 and 2×2 maps and
/// the stride-2 convolution into a 3×3 one, not its 5×5 and 4×4 maps nor large ones.
#[test]
fn applies_where_the_padding_is_a_third() {
    let g = |h: usize, (k, s, p): (usize, usize, usize)| {
        Geom::new(&[8, h, h, 16], &[16, 16, k, k], s, p).unwrap()
    };
    assert!(applies(&g(3, (3, 1, 1))) && applies(&g(2, (3, 1, 1))) && applies(&g(5, (3, 2, 1))));
    assert!(!applies(&g(5, (3, 1, 1))) && !applies(&g(4, (3, 1, 1))) && !applies(&g(4, (3, 2, 1))));
    assert!(
        !applies(&g(10, (3, 2, 1))) && !applies(&g(19, (3, 1, 1))) && !applies(&g(3, (1, 1, 0)))
    );
}
