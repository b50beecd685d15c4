//! The loader's parts on their own, through the crate's API: windows and their padding, the
//! train/validation split, the streaming order, normalization, LeRobot's video path template,
//! image decoding into the channel-first layout, and image sizes from `info.json`. (They were
//! unit tests: as integration tests they spare CI a second, test-mode compile of the crate.)
#![allow(clippy::unwrap_used)]

use std::collections::BTreeMap;

use scaledp_datasets::{
    decode_image, samples, split_episodes, streaming_order, video_path, window, Affine, Feature,
    Norm, Split, StreamSpec, DEFAULT_VIDEO_PATH,
};

#[test]
fn windows_pad_with_edge_frames() {
    let w = window(3, 0, 2, 4, 0);
    assert_eq!(w.obs, vec![0, 0]);
    assert_eq!(w.obs_is_pad, vec![true, false]);
    assert_eq!(w.action, vec![0, 1, 2, 2]);
    assert_eq!(w.action_is_pad, vec![false, false, false, true]);
    let w = window(1, 0, 3, 2, 1);
    assert_eq!((w.obs, w.action), (vec![0, 0, 0], vec![0, 0]));
    assert_eq!(w.action_is_pad, vec![true, true]);
}

#[test]
fn splits_are_disjoint_and_caps_nest() {
    let train = split_episodes(20, Split::Train, 0.25, 7, None);
    let val = split_episodes(20, Split::Val, 0.25, 7, None);
    assert_eq!((train.len(), val.len()), (15, 5));
    assert!(train.iter().all(|e| !val.contains(e)));
    let small = split_episodes(20, Split::Train, 0.25, 7, Some(4));
    let big = split_episodes(20, Split::Train, 0.25, 7, Some(10));
    assert!(small.iter().all(|e| big.contains(e) && train.contains(e)));
    assert_ne!(split_episodes(20, Split::Val, 0.25, 8, None), val);
}

#[test]
fn streaming_covers_every_sample_once_with_a_bounded_buffer() {
    let lens = [5, 1, 9, 0, 4, 7, 3];
    let all = samples(&lens, 0, 0);
    let spec = StreamSpec {
        drop_first: 0,
        drop_last: 0,
        buffer_episodes: 2,
        shuffle: true,
        seed: 3,
    };
    let (order, n) = streaming_order(&lens, &spec, 0, 0, 1);
    assert_eq!(n, order.len());
    let mut sorted = order.clone();
    sorted.sort_by_key(|s| (s.episode, s.t));
    assert_eq!(sorted, all);
    // At any point at most 2 episodes have been started and not finished.
    for i in 0..order.len() {
        let open = (0..lens.len() as u32)
            .filter(|&e| {
                order[..=i].iter().any(|s| s.episode == e)
                    && order[i + 1..].iter().any(|s| s.episode == e)
            })
            .count();
        assert!(open <= 2, "{open} open at {i}");
    }
    assert_ne!(order, streaming_order(&lens, &spec, 1, 0, 1).0);
}

fn stats() -> BTreeMap<String, BTreeMap<String, Vec<f64>>> {
    let mut s = BTreeMap::new();
    s.insert(
        "a".to_string(),
        [
            ("min", vec![-2.0, 0.5, 3.0]),
            ("max", vec![2.0, 0.5, 7.0]),
            ("mean", vec![0.1, 0.5, 5.0]),
            ("std", vec![1.5, 0.0, 0.7]),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect(),
    );
    s
}

#[test]
fn every_mode_round_trips_and_min_max_spans_minus_one_to_one() {
    let raw = vec![-2.0f32, 0.5, 3.0, 2.0, 0.5, 7.0, 0.3, 0.5, 4.2];
    for norm in [Norm::MinMax, Norm::MeanStd, Norm::None] {
        let a = Affine::new(norm, "a", 3, &stats(), "stats.json").unwrap();
        let mut x = raw.clone();
        a.apply(&mut x);
        if norm == Norm::MinMax {
            // Dimension 1 never varies (min = max = 0.5): centred, not scaled.
            assert_eq!(&x[0..3], &[-1.0, 0.0, -1.0]);
            assert_eq!((x[3], x[5]), (1.0, 1.0));
            assert_eq!((x[4], x[7]), (0.0, 0.0));
        }
        if norm == Norm::MeanStd {
            // std 0: x − mean, so a deviation of 0.01 stays 0.01 (not 10⁶).
            let mut d = vec![0.0f32, 0.51, 0.0];
            a.apply(&mut d);
            assert!((d[1] - 0.01).abs() < 1e-6, "{}", d[1]);
        }
        if norm == Norm::None {
            assert_eq!(x, raw);
        }
        a.invert(&mut x);
        for (got, want) in x.iter().zip(&raw) {
            assert!(
                (got - want).abs() <= 1e-5 * want.abs().max(1.0),
                "{norm:?}: {got} vs {want}"
            );
        }
    }
}

#[test]
fn missing_or_misshapen_stats_name_the_file() {
    let e = Affine::new(Norm::MinMax, "b", 3, &stats(), "meta/stats.json").unwrap_err();
    assert!(e.to_string().contains("meta/stats.json") && e.to_string().contains("b/min"));
    let e = Affine::new(Norm::MeanStd, "a", 4, &stats(), "meta/stats.json").unwrap_err();
    assert!(e.to_string().contains("3 values"));
}

#[test]
fn lerobot_video_path_template_is_filled() {
    assert_eq!(
        video_path(DEFAULT_VIDEO_PATH, "observation.images.top", 0, 12).unwrap(),
        "videos/observation.images.top/chunk-000/file-012.mp4"
    );
    assert_eq!(
        video_path("v/{chunk_index}/{file_index:05d}.mp4", "k", 3, 7).unwrap(),
        "v/3/00007.mp4"
    );
    assert!(video_path("v/{oops}.mp4", "k", 0, 0).is_err());
    assert!(video_path("v/{chunk_index.mp4", "k", 0, 0).is_err());
    assert!(video_path(DEFAULT_VIDEO_PATH, "k", -1, 0).is_err());
}

fn jpeg(w: u32, h: u32) -> Vec<u8> {
    let mut img = image::RgbImage::new(w, h);
    for (x, y, p) in img.enumerate_pixels_mut() {
        *p = image::Rgb([(x * 255 / w) as u8, (y * 255 / h) as u8, 128]);
    }
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Jpeg).unwrap();
    out.into_inner()
}

#[test]
fn jpeg_decodes_channel_first_and_resizes() {
    let enc = jpeg(64, 48);
    let mut dst = vec![0u8; 3 * 64 * 48];
    decode_image(&enc, 64, 48, &mut dst).unwrap();
    // Red grows along x, green along y, blue constant (JPEG is lossy: tolerances).
    let at = |c: usize, y: usize, x: usize| i32::from(dst[c * 64 * 48 + y * 64 + x]);
    assert!(at(0, 10, 60) - at(0, 10, 2) > 200);
    assert!(at(1, 45, 30) - at(1, 2, 30) > 200);
    assert!((at(2, 20, 20) - 128).abs() < 8);
    let mut small = vec![0u8; 3 * 32 * 24];
    decode_image(&enc, 32, 24, &mut small).unwrap();
    let at = |c: usize, y: usize, x: usize| i32::from(small[c * 32 * 24 + y * 32 + x]);
    assert!(at(0, 5, 30) - at(0, 5, 1) > 200);
    assert!(decode_image(b"not an image", 64, 48, &mut dst).is_err());
}

#[test]
fn channel_first_layout_is_exact_for_any_width() {
    // Widths that are and are not multiples of the channel shuffle's block, so its tail is
    // covered too; PNG is lossless, so every byte must land exactly.
    for (w, h) in [(64usize, 2usize), (7, 3), (33, 5), (1, 1)] {
        let hwc: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
        let img = image::RgbImage::from_raw(w as u32, h as u32, hwc.clone()).unwrap();
        let mut png = std::io::Cursor::new(Vec::new());
        img.write_to(&mut png, image::ImageFormat::Png).unwrap();
        let mut chw = vec![0u8; w * h * 3];
        decode_image(png.get_ref(), w as u32, h as u32, &mut chw).unwrap();
        for p in 0..w * h {
            for c in 0..3 {
                assert_eq!(
                    chw[c * w * h + p],
                    hwc[p * 3 + c],
                    "{w}×{h} pixel {p} channel {c}"
                );
            }
        }
    }
}

fn image(shape: &[usize], names: serde_json::Value) -> Feature {
    Feature {
        dtype: "image".into(),
        shape: shape.to_vec(),
        names: Some(names),
    }
}

#[test]
fn image_sizes_follow_names_then_the_channel_axis() {
    let hwc = serde_json::json!(["height", "width", "channels"]);
    assert_eq!(image(&[240, 320, 3], hwc).image_size(), Some((320, 240)));
    let chw = serde_json::json!(["channels", "height", "width"]);
    assert_eq!(image(&[3, 240, 320], chw).image_size(), Some((320, 240)));
    // No names: the axis holding 1, 3 or 4 channels decides.
    let none = serde_json::Value::Null;
    assert_eq!(
        image(&[3, 96, 128], none.clone()).image_size(),
        Some((128, 96))
    );
    assert_eq!(
        image(&[96, 128, 3], none.clone()).image_size(),
        Some((128, 96))
    );
    assert_eq!(image(&[96, 128, 7], none.clone()).image_size(), None);
    assert_eq!(image(&[96, 128], none).image_size(), None);
}
