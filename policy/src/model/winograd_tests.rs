//! Winograd's convolution and both gradients against the im2col kernels they replace.

use super::*;
use crate::model::conv::check::{against_im2col, values, Kernels};

const WINOGRAD: Kernels = Kernels {
    name: "winograd",
    forward: |g, x, wp, out| forward(g, x, wp, out, false),
    grad_input,
    grad_weight,
};

/// One 3×3, stride-1, padding-1 geometry against im2col.
fn check(b: usize, (h, w): (usize, usize), (ci, co): (usize, usize)) {
    let g = Geom::new(&[b, h, w, ci], &[co, ci, 3, 3], 1, 1).unwrap();
    assert!(fits(&g));
    against_im2col(&g, &WINOGRAD, 2e-5);
}

/// Odd and even maps (overhanging tiles), channel counts off the vector width, one sample
/// and a batch, on one thread and on two (chunks side by side).
#[test]
fn matches_im2col() {
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            check(1, (4, 4), (1, 1));
            check(2, (5, 7), (3, 5));
            check(3, (10, 10), (16, 8));
            check(9, (19, 19), (17, 33));
            check(12, (6, 5), (32, 32));
        });
    }
}

/// The weight gradient of a batch run side by side repeats to the last bit.
#[test]
fn weight_gradient_repeats_bit_for_bit() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    pool.install(|| {
        let g = Geom::new(&[11, 9, 9, 8], &[6, 8, 3, 3], 1, 1).unwrap();
        assert!(plan(&g, tiles(&g) * 16 * 14).1, "must run side by side");
        let (x, dy) = (values(11 * 81 * 8, 5), values(11 * 81 * 6, 6));
        let runs: Vec<Vec<f32>> = (0..3)
            .map(|_| {
                let mut dw = vec![0f32; 6 * 9 * 8];
                grad_weight(&g, &x, &dy, &mut dw);
                dw
            })
            .collect();
        assert!(runs.windows(2).all(|r| r[0] == r[1]));
    });
}

/// Where Winograd does not pay (a 3×3 map, few channels, few tiles), and for any other
/// geometry, the im2col kernels stay.
#[test]
fn applies_only_where_it_pays() {
    let g = |b: usize, h: usize, c: usize, (k, s, p): (usize, usize, usize)| {
        Geom::new(&[b, h, h, c], &[c, c, k, k], s, p).unwrap()
    };
    let same = (3, 1, 1);
    // The 84×84 bench's layers 1 and 2 (128 images of a camera).
    assert!(applies(&g(128, 19, 64, same)) && applies(&g(128, 10, 128, same)));
    assert!(!applies(&g(128, 3, 512, same)), "a 3×3 map wastes tiles");
    assert!(!applies(&g(128, 15, 32, same)), "32 channels");
    assert!(!applies(&g(128, 2, 256, same)), "128 tiles");
    assert!(!applies(&g(128, 10, 64, (3, 2, 1))) && !applies(&g(128, 10, 64, (1, 1, 0))));
    assert!(!applies(&g(128, 10, 64, (7, 1, 3))) && !fits(&g(1, 10, 4, (7, 1, 3))));
}
