//! Depth images, kept lossless: raw `sensor_msgs/Image` in `16UC1` (millimetres, 0 where
//! unknown; `mono16` read the same) or `32FC1` (metres, NaN or ±inf where unknown), and
//! image_transport's `compressedDepth` `sensor_msgs/CompressedImage` (see [`compressed`]),
//! decoded to their values, resized by nearest neighbour only (a hole is never blended into its
//! neighbours: it stays 0 or NaN) and stored as little-endian values.

mod compressed;
mod image;
mod stats;

use scaledp_schema::rig::DepthEncoding;
use scaledp_schema::CdrReader;

pub use compressed::decode_compressed_depth;
pub(crate) use image::MAX_PIXELS;
pub use image::{nearest_indices, DepthImage, DepthPixels};
pub use stats::DepthStats;

/// The depth encoding of a raw image's `encoding`, if it is one: `16UC1` and `mono16`
/// (millimetres), `32FC1` (metres).
pub fn raw_depth_encoding(encoding: &str) -> Option<DepthEncoding> {
    match encoding {
        "16UC1" | "mono16" => Some(DepthEncoding::U16Millimetres),
        "32FC1" => Some(DepthEncoding::F32Metres),
        _ => None,
    }
}

/// Whether a `CompressedImage` `format` is image_transport's `compressedDepth`
/// (`16UC1; compressedDepth png`, `32FC1; compressedDepth`, …).
pub fn is_compressed_depth(format: &str) -> bool {
    format.contains("compressedDepth")
}

/// A raw depth image's fields (`sensor_msgs/Image` without its header).
#[derive(Debug, Clone, Copy)]
pub struct RawDepth<'a> {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `16UC1`, `mono16` or `32FC1`.
    pub encoding: &'a str,
    /// 1 when the values are big-endian.
    pub is_bigendian: u8,
    /// Bytes per row (may exceed width × bytes per pixel).
    pub step: u32,
    /// The pixels.
    pub data: &'a [u8],
}

impl<'a> RawDepth<'a> {
    /// Parses a CDR `sensor_msgs/msg/Image` payload without copying its pixels.
    pub fn from_cdr(payload: &'a [u8]) -> Result<Self, String> {
        let mut r = CdrReader::new(payload).map_err(|e| e.to_string())?;
        let e = |e: scaledp_schema::Error| e.to_string();
        r.u32().map_err(e)?; // stamp.sec
        r.u32().map_err(e)?; // stamp.nanosec
        r.str().map_err(e)?; // frame_id
        Ok(Self {
            height: r.u32().map_err(e)?,
            width: r.u32().map_err(e)?,
            encoding: r.str().map_err(e)?,
            is_bigendian: r.u8().map_err(e)?,
            step: r.u32().map_err(e)?,
            data: r.bytes().map_err(e)?,
        })
    }

    /// The values, honouring `step` (row padding) and `is_bigendian`.
    pub fn decode(&self) -> Result<DepthImage, String> {
        let encoding = raw_depth_encoding(self.encoding)
            .ok_or_else(|| format!("'{}' is not a depth encoding", self.encoding))?;
        let (w, h, step) = (
            self.width as usize,
            self.height as usize,
            self.step as usize,
        );
        let bad = |problem: String| {
            format!(
                "{} image {}×{}: {problem}",
                self.encoding, self.width, self.height
            )
        };
        if w == 0 || h == 0 {
            return Err(bad("no pixels".into()));
        }
        if u64::from(self.width) * u64::from(self.height) > MAX_PIXELS {
            return Err(bad(format!(
                "more than the {} M pixels the converter decodes",
                MAX_PIXELS >> 20
            )));
        }
        let row = crate::raw_rows::checked_row_bytes(
            w,
            h,
            step,
            encoding.bytes_per_pixel(),
            self.data.len(),
        )
        .map_err(bad)?;
        let big = self.is_bigendian != 0;
        let rows = self.data.chunks(step).take(h).map(|r| &r[..row]);
        let pixels = match encoding {
            DepthEncoding::U16Millimetres => DepthPixels::U16(
                rows.flat_map(|r| r.chunks_exact(2))
                    .map(|b| {
                        let b = [b[0], b[1]];
                        if big {
                            u16::from_be_bytes(b)
                        } else {
                            u16::from_le_bytes(b)
                        }
                    })
                    .collect(),
            ),
            DepthEncoding::F32Metres => DepthPixels::F32(
                rows.flat_map(|r| r.chunks_exact(4))
                    .map(|b| {
                        let b = [b[0], b[1], b[2], b[3]];
                        if big {
                            f32::from_be_bytes(b)
                        } else {
                            f32::from_le_bytes(b)
                        }
                    })
                    .collect(),
            ),
        };
        Ok(DepthImage {
            width: self.width,
            height: self.height,
            pixels,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use scaledp_schema::msg::Image;
    use scaledp_schema::RosMessage;

    #[test]
    fn nearest_takes_the_pixel_under_each_centre() {
        assert_eq!(nearest_indices(4, 2), vec![1, 3]);
        assert_eq!(nearest_indices(2, 4), vec![0, 0, 1, 1]);
        assert_eq!(nearest_indices(5, 5), vec![0, 1, 2, 3, 4]);
        assert_eq!(nearest_indices(640, 320)[..3], [1, 3, 5]);
        assert_eq!(*nearest_indices(3, 7).last().unwrap(), 2);
    }

    #[test]
    fn holes_survive_resizing() {
        let img = DepthImage {
            width: 4,
            height: 2,
            pixels: DepthPixels::F32(vec![1.0, f32::NAN, 3.0, 4.0, 5.0, 6.0, 7.0, f32::NAN]),
        };
        let small = img.resized(2, 1);
        let DepthPixels::F32(v) = &small.pixels else {
            panic!("f32")
        };
        // Row 1 (y = ⌊0.5·2⌋), columns 1 and 3: 6 and the hole.
        assert_eq!(v[0], 6.0);
        assert!(v[1].is_nan());
        let mm = DepthImage {
            width: 2,
            height: 2,
            pixels: DepthPixels::U16(vec![0, 1000, 2000, 0]),
        };
        let big = mm.resized(4, 4);
        assert_eq!(
            big.pixels,
            DepthPixels::U16(vec![
                0, 0, 1000, 1000, 0, 0, 1000, 1000, 2000, 2000, 0, 0, 2000, 2000, 0, 0
            ])
        );
        assert_eq!(mm.to_le_bytes(), vec![0, 0, 232, 3, 208, 7, 0, 0]);
    }

    #[test]
    fn raw_images_honour_step_and_byte_order() {
        // 2×2 16UC1, big-endian, 2 bytes of padding per row.
        let msg = Image {
            width: 2,
            height: 2,
            encoding: "16UC1".into(),
            is_bigendian: 1,
            step: 6,
            data: vec![0x03, 0xe8, 0, 0, 9, 9, 0x07, 0xd0, 0x00, 0x01, 9, 9],
            ..Default::default()
        };
        let cdr = msg.to_cdr();
        let d = RawDepth::from_cdr(&cdr).unwrap().decode().unwrap();
        assert_eq!(d.pixels, DepthPixels::U16(vec![1000, 0, 2000, 1]));
        let short = Image {
            data: vec![0; 5],
            ..msg.clone()
        };
        let e = RawDepth::from_cdr(&short.to_cdr())
            .unwrap()
            .decode()
            .unwrap_err();
        assert!(e.contains("need 10"), "{e}");
        let f = Image {
            encoding: "32FC1".into(),
            is_bigendian: 0,
            step: 8,
            data: [1.5f32, f32::NAN, f32::INFINITY, 0.25]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            ..msg
        };
        let d = RawDepth::from_cdr(&f.to_cdr()).unwrap().decode().unwrap();
        let DepthPixels::F32(v) = d.pixels else {
            panic!("f32")
        };
        assert_eq!((v[0], v[2], v[3]), (1.5, f32::INFINITY, 0.25));
        assert!(v[1].is_nan());
    }
}
