//! Encoded image → the batch's channel-first RGB slot: JPEG with zune-jpeg (SIMD), anything
//! else through the `image` crate, resized with fast_image_resize (bilinear) when the stored
//! size differs from the requested one. Scratch buffers are kept per thread and reused.

use std::cell::RefCell;

use fast_image_resize as fr;
use zune_core::bytestream::ZCursor;
use zune_core::colorspace::ColorSpace;
use zune_core::options::DecoderOptions;
use zune_jpeg::JpegDecoder;

thread_local! {
    static SCRATCH: RefCell<(Vec<u8>, Vec<u8>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

/// Decodes `encoded` into `dst` (3 × height × width, channel-first RGB).
pub fn decode_into(encoded: &[u8], width: u32, height: u32, dst: &mut [u8]) -> Result<(), String> {
    SCRATCH.with(|s| {
        let (rgb, resized) = &mut *s.borrow_mut();
        let (w, h) = decode_rgb(encoded, rgb)?;
        let hwc: &[u8] = if (w, h) == (width, height) {
            rgb
        } else {
            resize(rgb, w, h, width, height, resized)?;
            resized
        };
        to_chw(hwc, width as usize, height as usize, dst);
        Ok(())
    })
}

/// Decodes to interleaved RGB in `out`; returns (width, height).
pub fn decode_rgb(encoded: &[u8], out: &mut Vec<u8>) -> Result<(u32, u32), String> {
    if encoded.starts_with(&[0xFF, 0xD8]) {
        let options = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::RGB);
        let mut d = JpegDecoder::new_with_options(ZCursor::new(encoded), options);
        d.decode_headers().map_err(|e| format!("JPEG: {e:?}"))?;
        let info = d.info().ok_or("JPEG without a frame header")?;
        check_pixels(u32::from(info.width), u32::from(info.height))?;
        let size = d.output_buffer_size().ok_or("JPEG too large")?;
        out.resize(size, 0);
        d.decode_into(out).map_err(|e| format!("JPEG: {e:?}"))?;
        let (w, h) = (u32::from(info.width), u32::from(info.height));
        if size != w as usize * h as usize * 3 {
            return Err(format!("JPEG decoded to {size} bytes for {w}×{h} RGB"));
        }
        Ok((w, h))
    } else {
        let reader = image::ImageReader::new(std::io::Cursor::new(encoded))
            .with_guessed_format()
            .map_err(|e| e.to_string())?;
        let (w, h) = reader.into_dimensions().map_err(|e| e.to_string())?;
        check_pixels(w, h)?;
        let img = image::load_from_memory(encoded)
            .map_err(|e| e.to_string())?
            .to_rgb8();
        let (w, h) = img.dimensions();
        out.clear();
        out.extend_from_slice(img.as_raw());
        Ok((w, h))
    }
}

/// Most pixels of a stored image decoded (8K UHD has 33 M): a header claiming more is refused
/// before anything is allocated for it.
const MAX_PIXELS: u64 = 36 << 20;

fn check_pixels(w: u32, h: u32) -> Result<(), String> {
    if w == 0 || h == 0 || u64::from(w) * u64::from(h) > MAX_PIXELS {
        return Err(format!(
            "image of {w}×{h} pixels (1 to {} M are decoded)",
            MAX_PIXELS >> 20
        ));
    }
    Ok(())
}

pub(crate) fn resize(
    src: &[u8],
    w: u32,
    h: u32,
    dw: u32,
    dh: u32,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let src =
        fr::images::ImageRef::new(w, h, src, fr::PixelType::U8x3).map_err(|e| e.to_string())?;
    out.resize(dw as usize * dh as usize * 3, 0);
    let mut dst = fr::images::Image::from_slice_u8(dw, dh, out, fr::PixelType::U8x3)
        .map_err(|e| e.to_string())?;
    let options =
        fr::ResizeOptions::new().resize_alg(fr::ResizeAlg::Convolution(fr::FilterType::Bilinear));
    fr::Resizer::new()
        .resize(&src, &mut dst, &options)
        .map_err(|e| e.to_string())
}

/// Interleaved RGB (H × W × 3) → planar (3 × H × W). A stride-3 deinterleave only vectorizes
/// with byte shuffles (SSSE3, AVX2, NEON), which baseline x86-64 lacks: compiled for it, this
/// loop took ~140 µs per 320×240 frame, a third of the time its JPEG decode takes; with AVX2
/// ~12 µs. So it is compiled for each and the CPU's best is picked at run time (zune-jpeg
/// does the same for its IDCT and colour conversion).
#[multiversion::multiversion(targets("x86_64+avx2", "x86_64+ssse3", "aarch64+neon"))]
pub(crate) fn to_chw(hwc: &[u8], width: usize, height: usize, dst: &mut [u8]) {
    let plane = width * height;
    let (r, rest) = dst.split_at_mut(plane);
    let (g, b) = rest.split_at_mut(plane);
    for (px, ((r, g), b)) in hwc
        .chunks_exact(3)
        .zip(r.iter_mut().zip(g.iter_mut()).zip(b.iter_mut()))
    {
        *r = px[0];
        *g = px[1];
        *b = px[2];
    }
}
