//! A decoded depth image: its values in the camera's unit, and nearest-neighbour resizing
//! (the only resizing depth gets: no value is ever interpolated).

use scaledp_schema::rig::DepthEncoding;

/// Most pixels of a depth image decoded (as for colour frames: a header claiming more is
/// refused before anything is allocated for it).
pub(crate) const MAX_PIXELS: u64 = 64 << 20;

/// A depth image's values, row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum DepthPixels {
    /// `16UC1`: millimetres, 0 where unknown.
    U16(Vec<u16>),
    /// `32FC1`: metres, NaN or ±inf where unknown.
    F32(Vec<f32>),
}

/// A decoded depth image.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthImage {
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height` values.
    pub pixels: DepthPixels,
}

impl DepthImage {
    /// The encoding its values are in.
    pub fn encoding(&self) -> DepthEncoding {
        match self.pixels {
            DepthPixels::U16(_) => DepthEncoding::U16Millimetres,
            DepthPixels::F32(_) => DepthEncoding::F32Metres,
        }
    }

    /// Resized to `width × height` by nearest neighbour: output pixel (x, y) takes source pixel
    /// (⌊(x + ½)·W/w⌋, ⌊(y + ½)·H/h⌋), the source pixel under its centre. No value is ever
    /// interpolated, so every output value is one the camera measured (or a hole it reported).
    pub fn resized(&self, width: u32, height: u32) -> DepthImage {
        if (width, height) == (self.width, self.height) {
            return self.clone();
        }
        let xs = nearest_indices(self.width, width);
        let ys = nearest_indices(self.height, height);
        let src_w = self.width as usize;
        fn pick<T: Copy>(src: &[T], xs: &[usize], ys: &[usize], src_w: usize) -> Vec<T> {
            let mut out = Vec::with_capacity(xs.len() * ys.len());
            for &y in ys {
                let row = &src[y * src_w..(y + 1) * src_w];
                out.extend(xs.iter().map(|&x| row[x]));
            }
            out
        }
        let pixels = match &self.pixels {
            DepthPixels::U16(v) => DepthPixels::U16(pick(v, &xs, &ys, src_w)),
            DepthPixels::F32(v) => DepthPixels::F32(pick(v, &xs, &ys, src_w)),
        };
        DepthImage {
            width,
            height,
            pixels,
        }
    }

    /// The values as little-endian bytes (2 or 4 per pixel), as the dataset stores them.
    pub fn to_le_bytes(&self) -> Vec<u8> {
        match &self.pixels {
            DepthPixels::U16(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            DepthPixels::F32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
}

/// For each of `to` output positions, the source position (of `from`) under its centre.
pub fn nearest_indices(from: u32, to: u32) -> Vec<usize> {
    let (from, to) = (u64::from(from), u64::from(to));
    (0..to)
        .map(|i| (((2 * i + 1) * from) / (2 * to)).min(from.saturating_sub(1)) as usize)
        .collect()
}
