//! The image path's unit tests: encodings and step, resizing, the fused resize.

use super::*;
use scaledp_schema::msg::Image;

fn raw(encoding: &str, w: u32, h: u32, step: u32, data: Vec<u8>) -> Frame {
    Frame::Raw(Image {
        encoding: encoding.into(),
        width: w,
        height: h,
        step,
        data,
        ..Default::default()
    })
}

#[test]
fn encodings_and_step_are_honoured() {
    // 2×2 bgra8 with 4 bytes of padding per row.
    let data = vec![
        1, 2, 3, 255, 4, 5, 6, 255, 0, 0, 0, 0, 7, 8, 9, 255, 10, 11, 12, 255, 0, 0, 0, 0,
    ];
    let rgb = to_rgb(&raw("bgra8", 2, 2, 12, data)).unwrap();
    assert_eq!(rgb.data, vec![3, 2, 1, 6, 5, 4, 9, 8, 7, 12, 11, 10]);
    let mono = to_rgb(&raw("mono8", 2, 1, 2, vec![5, 6])).unwrap();
    assert_eq!(mono.data, vec![5, 5, 5, 6, 6, 6]);
    let e = |f: Frame| to_rgb(&f).unwrap_err().to_string();
    assert!(e(raw("rgb8", 2, 2, 5, vec![0; 12])).contains("step 5"));
    assert!(e(raw("rgb8", 2, 2, 6, vec![0; 11])).contains("need 12"));
    assert!(matches!(
        to_rgb(&raw("16UC1", 2, 2, 4, vec![0; 8])),
        Err(ImageError::Encoding(enc)) if enc == "16UC1"
    ));
}

#[test]
fn resize_and_jpeg_round_trip() {
    let src = Rgb {
        width: 64,
        height: 48,
        data: (0..64 * 48 * 3).map(|i| (i % 251) as u8).collect(),
    };
    let small = resize(&src, 32, 24).unwrap();
    assert_eq!(small.data.len(), 32 * 24 * 3);
    let bytes = jpeg(&small, 90).unwrap();
    let back = image::load_from_memory(&bytes).unwrap().to_rgb8();
    assert_eq!((back.width(), back.height()), (32, 24));
}

#[test]
fn fused_resize_matches_rgb_then_resize() {
    // bgra8 and rgb8 frames resized as stored equal conversion to RGB then resizing with
    // the library's own Lanczos3, bit for bit (cached filter and alpha left alone).
    let (w, h) = (257u32, 131u32);
    let px: Vec<u8> = (0..w * h * 4)
        .map(|i| ((i * 7919) % 251) as u8 ^ (i / 1031) as u8)
        .collect();
    for (enc, ch) in [("bgra8", 4), ("rgba8", 4), ("bgr8", 3), ("rgb8", 3)] {
        let data = &px[..(w * h * ch) as usize];
        let view = ImageView {
            width: w,
            height: h,
            encoding: enc,
            step: w * ch,
            data,
        };
        let fused = resized_rgb(&view, 64, 37).unwrap();
        let rgb = view_to_rgb(&view).unwrap();
        let from = fr::images::ImageRef::new(w, h, &rgb.data, fr::PixelType::U8x3).unwrap();
        let mut to = fr::images::Image::new(64, 37, fr::PixelType::U8x3);
        let options = fr::ResizeOptions::new()
            .resize_alg(fr::ResizeAlg::Convolution(fr::FilterType::Lanczos3));
        fr::Resizer::new().resize(&from, &mut to, &options).unwrap();
        assert_eq!(fused.data, to.buffer(), "{enc}");
    }
}
