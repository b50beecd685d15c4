//! The tap-by-tap convolution and both gradients against the im2col kernels they replace.

use super::*;
use crate::model::conv::check::{against_im2col, Kernels};

const TAPS: Kernels = Kernels {
    name: "taps",
    forward,
    grad_input,
    grad_weight,
};

/// One geometry (`k×k` kernel, stride `s`, padding `p`) against im2col.
fn check(
    b: usize,
    (h, w): (usize, usize),
    (ci, co): (usize, usize),
    (k, s, p): (usize, usize, usize),
) {
    let g = Geom::new(&[b, h, w, ci], &[co, ci, k, k], s, p).unwrap();
    against_im2col(&g, &TAPS, 1e-5);
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
