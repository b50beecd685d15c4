//! image_transport's `compressedDepth` transport, decoded as its own subscriber decodes it
//! (ros-perception/image_transport_plugins, `compressed_depth_image_transport/src/codec.cpp`).
//!
//! `format` is `<encoding>; compressedDepth <png|rvl>` (older publishers: `<encoding>;
//! compressedDepth`, meaning PNG). `data` is a 12-byte `ConfigHeader` — an `int32` format
//! (0, `INV_DEPTH`) and two `float32` quantisation parameters A and B, in the publisher's byte
//! order (little-endian on every platform ROS 2 runs on) — followed by the image:
//!
//! - `16UC1`: a 16-bit grey PNG (or RVL stream) of the millimetres themselves (the publisher
//!   zeroed values beyond its `depth_max`): decoded exactly.
//! - `32FC1`: a 16-bit grey PNG (or RVL stream) of quantised inverse depth q, which the
//!   publisher computed as q = A / depth + B (A = z0·(z0 + 1), B = 1 − A / depth_max); the
//!   depth is A / (q − B) in `float32` for q ≠ 0 and NaN for q = 0. The quantisation happened
//!   at the publisher: what is stored is exactly what its own subscriber would hand a node.
//!
//! RVL (Wilson 2017) streams are `u32` columns, `u32` rows, then little-endian 32-bit words of
//! 4-bit nibbles (3 value bits and a continuation bit, first nibble in the top bits) coding runs
//! of zeros and of zigzag-coded deltas between non-zero values.

use scaledp_schema::rig::DepthEncoding;

use super::image::{DepthImage, DepthPixels, MAX_PIXELS};

/// Bytes of the `ConfigHeader` before the image.
const HEADER_BYTES: usize = 12;

/// Decodes a `compressedDepth` `CompressedImage` (`format`, `data`) to its depth values.
pub fn decode_compressed_depth(format: &str, data: &[u8]) -> Result<DepthImage, String> {
    let (encoding, codec) = parse_format(format)?;
    if data.len() <= HEADER_BYTES {
        return Err(format!(
            "compressedDepth image of {} bytes: no image after its {HEADER_BYTES}-byte header",
            data.len()
        ));
    }
    let f32_at =
        |at: usize| f32::from_le_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]]);
    let (a, b) = (f32_at(4), f32_at(8));
    let body = &data[HEADER_BYTES..];
    let (width, height, q) = match codec {
        Codec::Png => png16(body)?,
        Codec::Rvl => rvl(body)?,
    };
    let pixels = match encoding {
        DepthEncoding::U16Millimetres => DepthPixels::U16(q),
        DepthEncoding::F32Metres => DepthPixels::F32(
            q.into_iter()
                .map(|q| {
                    if q == 0 {
                        f32::NAN
                    } else {
                        a / (f32::from(q) - b)
                    }
                })
                .collect(),
        ),
    };
    Ok(DepthImage {
        width,
        height,
        pixels,
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Codec {
    Png,
    Rvl,
}

/// `16UC1; compressedDepth png` → (16UC1, PNG).
fn parse_format(format: &str) -> Result<(DepthEncoding, Codec), String> {
    let (encoding, rest) = format.split_once(';').unwrap_or((format, ""));
    let encoding = match encoding.trim() {
        "16UC1" | "mono16" => DepthEncoding::U16Millimetres,
        "32FC1" => DepthEncoding::F32Metres,
        other => {
            return Err(format!(
                "compressedDepth of '{other}' images (format '{format}'): only 16UC1 and 32FC1 are depth"
            ))
        }
    };
    let codec = match rest.trim() {
        "compressedDepth" | "compressedDepth png" | "" => Codec::Png,
        "compressedDepth rvl" => Codec::Rvl,
        _ => {
            return Err(format!(
                "compressedDepth format '{format}' is not png or rvl"
            ))
        }
    };
    Ok((encoding, codec))
}

/// A 16-bit grey PNG → (width, height, values).
fn png16(png: &[u8]) -> Result<(u32, u32, Vec<u16>), String> {
    let reader =
        image::ImageReader::with_format(std::io::Cursor::new(png), image::ImageFormat::Png);
    let (w, h) = reader
        .into_dimensions()
        .map_err(|e| format!("compressedDepth PNG: {e}"))?;
    check_size(w, h)?;
    let img = image::load_from_memory_with_format(png, image::ImageFormat::Png)
        .map_err(|e| format!("compressedDepth PNG: {e}"))?;
    match img {
        image::DynamicImage::ImageLuma16(g) => Ok((w, h, g.into_raw())),
        other => Err(format!(
            "compressedDepth PNG of {:?} pixels, not 16-bit grey",
            other.color()
        )),
    }
}

fn check_size(w: u32, h: u32) -> Result<(), String> {
    if w == 0 || h == 0 || u64::from(w) * u64::from(h) > MAX_PIXELS {
        return Err(format!(
            "compressedDepth image of {w}×{h} pixels (1 to {} M are decoded)",
            MAX_PIXELS >> 20
        ));
    }
    Ok(())
}

/// An RVL stream (`u32` cols, `u32` rows, words) → (width, height, values).
fn rvl(body: &[u8]) -> Result<(u32, u32, Vec<u16>), String> {
    let u32_at = |at: usize| {
        body.get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or("RVL stream shorter than its size fields")
    };
    let (w, h) = (u32_at(0)?, u32_at(4)?);
    check_size(w, h)?;
    let n = w as usize * h as usize;
    // At most 2 pixels per nibble-bearing byte: a size no stream of this length can fill is
    // refused before allocating for it.
    if n > body.len().saturating_mul(16) {
        return Err(format!(
            "RVL stream of {} bytes claims {w}×{h} pixels",
            body.len()
        ));
    }
    let mut nibbles = Nibbles {
        words: body[8..].chunks_exact(4),
        word: 0,
        left: 0,
    };
    let mut out = Vec::with_capacity(n);
    let mut previous: u16 = 0;
    while out.len() < n {
        let zeros = nibbles.vle()? as usize;
        if zeros > n - out.len() {
            return Err("RVL run of zeros past the image's end".into());
        }
        out.resize(out.len() + zeros, 0);
        let nonzeros = nibbles.vle()? as usize;
        if nonzeros > n - out.len() {
            return Err("RVL run of values past the image's end".into());
        }
        for _ in 0..nonzeros {
            let positive = nibbles.vle()? as i32;
            let delta = (positive >> 1) ^ -(positive & 1);
            // uint16 arithmetic, wrapping as the C++ decoder's does.
            let current = (i32::from(previous) + delta) as u16;
            out.push(current);
            previous = current;
        }
    }
    Ok((w, h, out))
}

/// RVL's nibble reader: 32-bit little-endian words, nibbles from the top.
struct Nibbles<'a> {
    words: std::slice::ChunksExact<'a, u8>,
    word: u32,
    left: u32,
}

impl Nibbles<'_> {
    fn nibble(&mut self) -> Result<u32, String> {
        if self.left == 0 {
            let w = self.words.next().ok_or("RVL stream ends early")?;
            self.word = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
            self.left = 8;
        }
        let n = self.word >> 28;
        self.word <<= 4;
        self.left -= 1;
        Ok(n)
    }

    /// A variable-length value: 3 bits per nibble, least significant first, while the
    /// nibble's top bit says more follow.
    fn vle(&mut self) -> Result<u32, String> {
        let (mut value, mut shift) = (0u32, 0u32);
        loop {
            let n = self.nibble()?;
            if shift > 30 {
                return Err("RVL value longer than 32 bits".into());
            }
            value |= (n & 7) << shift;
            shift += 3;
            if n & 8 == 0 {
                return Ok(value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// A compressedDepth payload: header (INV_DEPTH, A, B) and a 16-bit grey PNG of `q`.
    fn payload(a: f32, b: f32, w: u32, h: u32, q: &[u16]) -> Vec<u8> {
        let mut out = vec![0u8; 4];
        out.extend(a.to_le_bytes());
        out.extend(b.to_le_bytes());
        let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, q.to_vec()).unwrap();
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        out.extend(png);
        out
    }

    #[test]
    fn millimetres_come_back_exactly() {
        let q = [0u16, 1, 1000, 65535, 4242, 0];
        let d = decode_compressed_depth("16UC1; compressedDepth png", &payload(0.0, 0.0, 3, 2, &q))
            .unwrap();
        assert_eq!((d.width, d.height), (3, 2));
        assert_eq!(d.pixels, DepthPixels::U16(q.to_vec()));
        // The old format string without a codec is PNG too.
        let old = decode_compressed_depth("16UC1; compressedDepth", &payload(0.0, 0.0, 3, 2, &q));
        assert_eq!(old.unwrap().pixels, DepthPixels::U16(q.to_vec()));
    }

    #[test]
    fn inverse_depth_follows_the_subscribers_formula() {
        // The publisher's defaults: depth_quantization z0 = 100, depth_max = 10 m.
        let a = 100.0f32 * (100.0 + 1.0);
        let b = 1.0f32 - a / 10.0;
        let depths = [0.5f32, 1.0, 2.25, 9.0];
        let mut q: Vec<u16> = depths.iter().map(|d| (a / d + b) as u16).collect();
        q.push(0);
        let d = decode_compressed_depth("32FC1; compressedDepth png", &payload(a, b, 5, 1, &q))
            .unwrap();
        let DepthPixels::F32(v) = d.pixels else {
            panic!("f32")
        };
        for (k, &qk) in q[..4].iter().enumerate() {
            assert_eq!(v[k], a / (f32::from(qk) - b));
            assert!(
                (v[k] - depths[k]).abs() < 0.01 * depths[k],
                "{} vs {}",
                v[k],
                depths[k]
            );
        }
        assert!(v[4].is_nan(), "q = 0 is a hole");
    }

    /// RVL-encodes `input` as the C++ `CompressRVL` does.
    fn rvl_encode(input: &[u16]) -> Vec<u8> {
        struct W {
            out: Vec<u8>,
            word: u32,
            n: u32,
        }
        impl W {
            fn vle(&mut self, mut value: u32) {
                loop {
                    let mut nibble = value & 7;
                    value >>= 3;
                    if value != 0 {
                        nibble |= 8;
                    }
                    self.word = (self.word << 4) | nibble;
                    self.n += 1;
                    if self.n == 8 {
                        self.out.extend(self.word.to_le_bytes());
                        self.n = 0;
                        self.word = 0;
                    }
                    if value == 0 {
                        break;
                    }
                }
            }
        }
        let mut w = W {
            out: Vec::new(),
            word: 0,
            n: 0,
        };
        let (mut i, mut previous) = (0usize, 0i32);
        while i < input.len() {
            let zeros = input[i..].iter().take_while(|&&v| v == 0).count();
            w.vle(zeros as u32);
            i += zeros;
            let nonzeros = input[i..].iter().take_while(|&&v| v != 0).count();
            w.vle(nonzeros as u32);
            for &v in &input[i..i + nonzeros] {
                let delta = i32::from(v) - previous;
                w.vle(((delta << 1) ^ (delta >> 31)) as u32);
                previous = i32::from(v);
            }
            i += nonzeros;
        }
        if w.n > 0 {
            let last = w.word << (4 * (8 - w.n));
            w.out.extend(last.to_le_bytes());
        }
        w.out
    }

    #[test]
    fn rvl_round_trips_and_bad_streams_are_errors() {
        let q: Vec<u16> = vec![0, 0, 0, 1200, 1201, 1199, 0, 65535, 3, 0, 0, 7];
        let mut data = vec![0u8; HEADER_BYTES];
        data.extend(4u32.to_le_bytes());
        data.extend(3u32.to_le_bytes());
        data.extend(rvl_encode(&q));
        let d = decode_compressed_depth("16UC1; compressedDepth rvl", &data).unwrap();
        assert_eq!(d.pixels, DepthPixels::U16(q));
        for cut in [HEADER_BYTES, HEADER_BYTES + 5, data.len() - 4] {
            assert!(decode_compressed_depth("16UC1; compressedDepth rvl", &data[..cut]).is_err());
        }
        let mut huge = data.clone();
        huge[HEADER_BYTES..HEADER_BYTES + 4].copy_from_slice(&60000u32.to_le_bytes());
        let e = decode_compressed_depth("16UC1; compressedDepth rvl", &huge).unwrap_err();
        assert!(e.contains("claims"), "{e}");
    }

    #[test]
    fn other_formats_and_short_payloads_are_errors() {
        let e = decode_compressed_depth("rgb8; compressedDepth png", &[0; 40]).unwrap_err();
        assert!(e.contains("'rgb8'"), "{e}");
        let e = decode_compressed_depth("16UC1; compressedDepth zstd", &[0; 40]).unwrap_err();
        assert!(e.contains("not png or rvl"), "{e}");
        let e = decode_compressed_depth("16UC1; compressedDepth png", &[0; 12]).unwrap_err();
        assert!(e.contains("12-byte header"), "{e}");
        let e = decode_compressed_depth("16UC1; compressedDepth png", &[0; 40]).unwrap_err();
        assert!(e.starts_with("compressedDepth PNG"), "{e}");
        // An 8-bit PNG is not depth.
        let img = image::GrayImage::from_raw(2, 1, vec![1, 2]).unwrap();
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let mut with_header = vec![0u8; HEADER_BYTES];
        with_header.extend(png);
        let e = decode_compressed_depth("16UC1; compressedDepth png", &with_header).unwrap_err();
        assert!(e.contains("not 16-bit grey"), "{e}");
    }
}
