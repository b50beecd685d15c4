//! Winograd's convolution and both gradients against the im2col kernels they replace.

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
            (x - y).abs() <= 2e-5 * scale,
            "{what}[{i}]: winograd {x} vs im2col {y} (scale {scale})"
        );
    }
}

/// Forward, input gradient (overwritten and accumulated) and weight gradient of one geometry
/// equal im2col's, within f32 rounding.
fn check(b: usize, (h, w): (usize, usize), (ci, co): (usize, usize)) {
    let g = Geom::new(&[b, h, w, ci], &[co, ci, 3, 3], 1, 1).unwrap();
    assert!(fits(&g));
    let (x, wp, dy) = (
        values(b * h * w * ci, 1),
        values(co * 9 * ci, 2),
        values(b * h * w * co, 3),
    );
    let (mut ours, mut theirs) = (vec![0f32; b * h * w * co], vec![0f32; b * h * w * co]);
    forward(&g, &x, &wp, &mut ours, false);
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
