//! The conversions against libswscale's fixed point, BT.601 limited range, and odd sizes.

use super::*;

#[test]
fn both_rows_give_swscales_fixed_point_for_every_yuv_triple() {
    let mulhi = |a: i32, b: i32| (a * b) >> 16;
    let want = |yv: u8, u: u8, v: u8| {
        let ys = mulhi((i32::from(yv) << 3) - 128, Y_COEFF);
        let u8_ = (i32::from(u) - 128) << 3;
        let v8 = (i32::from(v) - 128) << 3;
        [
            (ys + mulhi(v8, V2R)).clamp(0, 255) as u8,
            (ys + mulhi(u8_, U2G) + mulhi(v8, V2G)).clamp(0, 255) as u8,
            (ys + mulhi(u8_, U2B)).clamp(0, 255) as u8,
        ]
    };
    // Three pixels: a pair sharing the first chroma sample, then an odd one on its own.
    let mut px = [0u8; 9];
    for yv in 0..=255u8 {
        for u in 0..=255u8 {
            for v in 0..=255u8 {
                let ys = [yv, 255 - yv, yv ^ 0x55];
                convert_row(&ys, &[u, v], &[v, u], &mut px);
                let (mut r, mut g, mut b) = ([0u8; 3], [0u8; 3], [0u8; 3]);
                convert_row_planar(&ys, &[u, v], &[v, u], &mut r, &mut g, &mut b);
                for k in 0..3 {
                    assert_eq!([r[k], g[k], b[k]], px[3 * k..3 * k + 3], "planar {k}");
                }
                assert_eq!(px[..3], want(ys[0], u, v), "y {yv} u {u} v {v}");
                assert_eq!(px[3..6], want(ys[1], u, v), "y {} u {u} v {v}", ys[1]);
                assert_eq!(px[6..], want(ys[2], v, u), "y {} u {v} v {u}", ys[2]);
            }
        }
    }
}

#[test]
fn grey_and_primaries_convert_as_bt601_limited_range() {
    // 2×2 picture: one chroma sample.
    let rgb = |yv: u8, u: u8, v: u8| {
        let planes = Yuv420 {
            width: 2,
            height: 2,
            y: &[yv; 4],
            u: &[u],
            v: &[v],
            y_stride: 2,
            uv_stride: 1,
        };
        planes.check().unwrap();
        let mut out = Vec::new();
        planes.write_rgb(&mut out);
        assert!(out.chunks(3).all(|p| p == &out[..3]), "{out:?}");
        [out[0], out[1], out[2]]
    };
    assert_eq!(rgb(16, 128, 128), [0, 0, 0]);
    assert_eq!(rgb(235, 128, 128), [255, 255, 255]);
    assert_eq!(rgb(126, 128, 128), [128, 128, 128]);
    // BT.601 red (Y 81, Cb 90, Cr 240) comes back near (255, 0, 0).
    let [r, g, b] = rgb(81, 90, 240);
    assert!(r >= 253 && g <= 2 && b <= 2, "{r} {g} {b}");
}

/// RGB → 4:2:0 → RGB through [`Yuv420::write_rgb`].
fn round_trip(rgb: &[u8], w: usize, h: usize) -> Vec<u8> {
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let (mut y, mut u, mut v) = (vec![0; w * h], vec![0; cw * ch], vec![0; cw * ch]);
    rgb_to_yuv420(rgb, w, h, &mut y, &mut u, &mut v);
    let planes = Yuv420 {
        width: w,
        height: h,
        y: &y,
        u: &u,
        v: &v,
        y_stride: w,
        uv_stride: cw,
    };
    planes.check().unwrap();
    let mut out = Vec::new();
    planes.write_rgb(&mut out);
    out
}

#[test]
fn rgb_to_yuv420_is_bt601_limited_range_and_inverts_write_rgb() {
    let planes_of = |px: [u8; 3]| {
        let (mut y, mut u, mut v) = ([0; 4], [0; 1], [0; 1]);
        rgb_to_yuv420(&px.repeat(4), 2, 2, &mut y, &mut u, &mut v);
        assert!(y.iter().all(|&l| l == y[0]));
        [y[0], u[0], v[0]]
    };
    assert_eq!(planes_of([0, 0, 0]), [16, 128, 128]);
    assert_eq!(planes_of([255, 255, 255]), [235, 128, 128]);
    assert_eq!(planes_of([255, 0, 0]), [81, 90, 240]);
    for grey in 0..=255u8 {
        let [_, u, v] = planes_of([grey; 3]);
        assert_eq!((u, v), (128, 128), "grey {grey}");
        let back = round_trip(&[grey; 12], 2, 2);
        assert!(
            back.iter().all(|&c| c.abs_diff(grey) <= 1),
            "grey {grey}: {back:?}"
        );
    }
    let colours = [
        [255, 0, 0],
        [0, 255, 0],
        [0, 0, 255],
        [255, 255, 0],
        [0, 255, 255],
        [255, 0, 255],
        [200, 120, 40],
    ];
    for px in colours {
        let back = round_trip(&px.repeat(4), 2, 2);
        for (got, want) in back.iter().zip(px.iter().cycle()) {
            assert!(got.abs_diff(*want) <= 3, "{px:?} came back as {back:?}");
        }
    }
}

#[test]
fn rgb_to_yuv420_averages_each_2x2_block_and_odd_edges() {
    // 3×3: blocks of 4, 2 (right column), 2 (bottom row) and 1 pixel(s).
    let rgb: Vec<u8> = (0..9u8).flat_map(|i| [i * 20; 3]).collect();
    let (mut y, mut u, mut v) = ([0; 9], [0; 4], [0; 4]);
    rgb_to_yuv420(&rgb, 3, 3, &mut y, &mut u, &mut v);
    assert_eq!((u, v), ([128; 4], [128; 4]));
    // Blue only in the top left pixel: a quarter of pure blue's chroma offset.
    let mut rgb = [0u8; 12];
    rgb[2] = 255;
    let (mut y, mut u, mut v) = ([0; 4], [0; 1], [0; 1]);
    rgb_to_yuv420(&rgb, 2, 2, &mut y, &mut u, &mut v);
    assert_eq!((u[0], v[0]), (128 + 28, 128 - 5));
}

#[test]
fn odd_sizes_and_padded_strides_are_read_at_their_strides() {
    let (w, h) = (3usize, 3usize);
    let y: Vec<u8> = (0..4 * h)
        .map(|i| if i % 4 == 3 { 0 } else { 200 })
        .collect();
    let c = [128u8, 128, 0, 128, 128, 0];
    let planes = Yuv420 {
        width: w,
        height: h,
        y: &y,
        u: &c,
        v: &c,
        y_stride: 4,
        uv_stride: 3,
    };
    planes.check().unwrap();
    let mut out = Vec::new();
    planes.write_rgb(&mut out);
    assert_eq!(out.len(), 27);
    // Padding bytes (0) never reach the picture: every pixel is the same grey.
    assert!(out.iter().all(|&v| v == out[0]), "{out:?}");
    let short = Yuv420 {
        y: &y[..5],
        ..planes
    };
    assert!(short.check().is_err());
}

/// Pseudo-random planes of a `w × h` picture with padded strides.
struct Noise {
    w: usize,
    h: usize,
    y: Vec<u8>,
    u: Vec<u8>,
    v: Vec<u8>,
}

impl Noise {
    fn new(w: usize, h: usize, seed: u64) -> Self {
        let mut x = seed;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 56) as u8
        };
        let (ys, cs) = (w + 5, w.div_ceil(2) + 3);
        let y = (0..ys * h).map(|_| next()).collect();
        let u = (0..cs * h.div_ceil(2)).map(|_| next()).collect();
        let v = (0..cs * h.div_ceil(2)).map(|_| next()).collect();
        Self { w, h, y, u, v }
    }

    fn picture(&self) -> Yuv420<'_> {
        let p = Yuv420 {
            width: self.w,
            height: self.h,
            y: &self.y,
            u: &self.u,
            v: &self.v,
            y_stride: self.w + 5,
            uv_stride: self.w.div_ceil(2) + 3,
        };
        p.check().unwrap();
        p
    }
}

#[test]
fn channel_first_output_is_the_interleaved_one_transposed() {
    for (w, h) in [(1, 1), (3, 3), (7, 4), (64, 48), (321, 241)] {
        let noise = Noise::new(w, h, (w * h) as u64);
        let p = noise.picture();
        let mut hwc = Vec::new();
        p.write_rgb(&mut hwc);
        let mut chw = vec![0u8; 3 * w * h];
        p.write_chw(&mut chw);
        for i in 0..w * h {
            for c in 0..3 {
                assert_eq!(
                    chw[c * w * h + i],
                    hwc[3 * i + c],
                    "{w}×{h} pixel {i} channel {c}"
                );
            }
        }
    }
}

/// `cargo test --release -p scaledp-codec -- --ignored --nocapture yuv_speed`: ns per pixel
/// of the two layouts at 320×240.
#[test]
#[ignore = "a timing, not a check"]
fn yuv_speed() {
    let (w, h) = (320, 240);
    let noise = Noise::new(w, h, 7);
    let p = noise.picture();
    let (mut hwc, mut chw) = (Vec::new(), vec![0u8; 3 * w * h]);
    let n = 500;
    let t = std::time::Instant::now();
    for _ in 0..n {
        p.write_rgb(&mut hwc);
    }
    let rgb = t.elapsed().as_secs_f64() * 1e9 / (n * w * h) as f64;
    let t = std::time::Instant::now();
    for _ in 0..n {
        p.write_chw(&mut chw);
    }
    let planar = t.elapsed().as_secs_f64() * 1e9 / (n * w * h) as f64;
    eprintln!("write_rgb {rgb:.2} ns/pixel, write_chw {planar:.2} ns/pixel");
}
