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

    /// Writes channel-first RGB (the R plane, then G, then B; `width × height` bytes each) into
    /// `dst`, which must hold `3 × width × height` bytes: the same values as [`Self::write_rgb`].
    pub fn write_chw(self, dst: &mut [u8]) {
        let plane = self.width * self.height;
        let (r, rest) = dst[..3 * plane].split_at_mut(plane);
        let (g, b) = rest.split_at_mut(plane);
        let cw = self.width.div_ceil(2);
        for row in 0..self.height {
            let y = &self.y[row * self.y_stride..][..self.width];
            let c = (row / 2) * self.uv_stride;
            let at = row * self.width..(row + 1) * self.width;
            convert_row_planar(
                y,
                &self.u[c..c + cw],
                &self.v[c..c + cw],
                &mut r[at.clone()],
                &mut g[at.clone()],
                &mut b[at],
            );
        }
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

/// One row to planar R, G and B: the same integers as [`convert_row`], computed rather than
/// looked up, in a loop over pixel pairs that the compiler vectorizes (no gathers, contiguous
/// stores): the loader's channel-first layout without an interleaved copy in between.
#[multiversion::multiversion(targets("x86_64+avx2", "x86_64+ssse3", "aarch64+neon"))]
fn convert_row_planar(y: &[u8], u: &[u8], v: &[u8], r: &mut [u8], g: &mut [u8], b: &mut [u8]) {
    #[inline(always)]
    fn one(y: u8, [rv, gv, bv]: [i32; 3]) -> [u8; 3] {
        let ys = (((i32::from(y) << 3) - 128) * Y_COEFF) >> 16;
        [
            (ys + rv).clamp(0, 255) as u8,
            (ys + gv).clamp(0, 255) as u8,
            (ys + bv).clamp(0, 255) as u8,
        ]
    }
    #[inline(always)]
    fn chroma(u: u8, v: u8) -> [i32; 3] {
        let (u, v) = ((i32::from(u) - 128) << 3, (i32::from(v) - 128) << 3);
        [
            (v * V2R) >> 16,
            ((u * U2G) >> 16) + ((v * V2G) >> 16),
            (u * U2B) >> 16,
        ]
    }
    let pairs = y
        .chunks_exact(2)
        .zip(u.iter().zip(v))
        .zip(r.chunks_exact_mut(2).zip(g.chunks_exact_mut(2)))
        .zip(b.chunks_exact_mut(2));
    for (((ys, (&u, &v)), (rr, gg)), bb) in pairs {
        let c = chroma(u, v);
        let [r0, g0, b0] = one(ys[0], c);
        let [r1, g1, b1] = one(ys[1], c);
        rr.copy_from_slice(&[r0, r1]);
        gg.copy_from_slice(&[g0, g1]);
        bb.copy_from_slice(&[b0, b1]);
    }
    if y.len() % 2 == 1 {
        let x = y.len() - 1;
        let [rx, gx, bx] = one(y[x], chroma(u[x / 2], v[x / 2]));
        (r[x], g[x], b[x]) = (rx, gx, bx);
    }
}

/// swscale's fixed-point terms, one table per input: each is a function of one 8-bit value
/// only (`mulhi` of that value's scaled offset), so a pixel is three table sums — the same
/// integers as computing them, at a fraction of the cost (this was 20–30 % of a video epoch).
struct Terms {
    y: [i32; 256],
    v2r: [i32; 256],
    u2g: [i32; 256],
    v2g: [i32; 256],
    u2b: [i32; 256],
}

const fn terms() -> Terms {
    let mut t = Terms {
        y: [0; 256],
        v2r: [0; 256],
        u2g: [0; 256],
        v2g: [0; 256],
        u2b: [0; 256],
    };
    let mut i = 0;
    while i < 256 {
        let c = (i as i32 - 128) << 3;
        t.y[i] = ((((i as i32) << 3) - 128) * Y_COEFF) >> 16;
        t.v2r[i] = (c * V2R) >> 16;
        t.u2g[i] = (c * U2G) >> 16;
        t.v2g[i] = (c * V2G) >> 16;
        t.u2b[i] = (c * U2B) >> 16;
        i += 1;
    }
    t
}

static TERMS: Terms = terms();

/// One pixel from its luma term and its chroma pair's offsets.
#[inline(always)]
fn pixel(ys: i32, [r, g, b]: [i32; 3], px: &mut [u8]) {
    px[0] = (ys + r).clamp(0, 255) as u8;
    px[1] = (ys + g).clamp(0, 255) as u8;
    px[2] = (ys + b).clamp(0, 255) as u8;
}

/// One row: `y` luma, `u`/`v` the chroma row (one sample per two pixels), `dst` RGB.
pub(crate) fn convert_row(y: &[u8], u: &[u8], v: &[u8], dst: &mut [u8]) {
    let t = &TERMS;
    let offsets = |u: u8, v: u8| {
        let (u, v) = (usize::from(u), usize::from(v));
        [t.v2r[v], t.u2g[u] + t.v2g[v], t.u2b[u]]
    };
    let pairs = y.chunks_exact(2).zip(dst.chunks_exact_mut(6));
    for ((ys, px), (&u, &v)) in pairs.zip(u.iter().zip(v)) {
        let off = offsets(u, v);
        pixel(t.y[usize::from(ys[0])], off, &mut px[..3]);
        pixel(t.y[usize::from(ys[1])], off, &mut px[3..]);
    }
    if y.len() % 2 == 1 {
        let x = y.len() - 1;
        let off = offsets(u[x / 2], v[x / 2]);
        pixel(t.y[usize::from(y[x])], off, &mut dst[3 * x..3 * x + 3]);
    }
}

// RGB → Y'CbCr, BT.601 limited range, in 16-bit fixed point (×65536, rounded; each row of
// chroma coefficients sums to 0 so that greys get Cb = Cr = 128 exactly).
const R2Y: i32 = 16829; // 0.299 × 219/255
const G2Y: i32 = 33039; // 0.587 × 219/255
const B2Y: i32 = 6416; // 0.114 × 219/255
const R2U: i32 = -9714; // −0.168736 × 224/255
const G2U: i32 = -19070; // −0.331264 × 224/255
const B2U: i32 = 28784; // 0.5 × 224/255
const R2V: i32 = 28784; // 0.5 × 224/255
const G2V: i32 = -24103; // −0.418688 × 224/255
const B2V: i32 = -4681; // −0.081312 × 224/255

/// Packed RGB24 (`width × height × 3` bytes) → 4:2:0 planes without padding (`y`: `width` bytes a
/// row; `u`, `v`: half the width and height, rounded up), the inverse of
/// [`Yuv420::write_rgb`]: BT.601 limited range (libswscale's default for `rgb24 → yuv420p`), each
/// chroma sample the average of its 2×2 block (of the pixels there are, at an odd edge).
pub(crate) fn rgb_to_yuv420(
    rgb: &[u8],
    width: usize,
    height: usize,
    y: &mut [u8],
    u: &mut [u8],
    v: &mut [u8],
) {
    let (cw, ch) = (width.div_ceil(2), height.div_ceil(2));
    assert!(rgb.len() == width * height * 3 && y.len() == width * height);
    assert!(u.len() == cw * ch && v.len() == cw * ch);
    luma(rgb, y);
    let row = width * 3;
    for (cy, (u_row, v_row)) in u
        .chunks_exact_mut(cw)
        .zip(v.chunks_exact_mut(cw))
        .enumerate()
    {
        let top = &rgb[2 * cy * row..][..row];
        let bottom = &rgb[(2 * cy + 1).min(height - 1) * row..][..row];
        chroma_row(top, bottom, u_row, v_row);
    }
}

#[multiversion::multiversion(targets("x86_64+avx2", "x86_64+ssse3", "aarch64+neon"))]
fn luma(rgb: &[u8], y: &mut [u8]) {
    for (px, out) in rgb.chunks_exact(3).zip(y.iter_mut()) {
        let (r, g, b) = (i32::from(px[0]), i32::from(px[1]), i32::from(px[2]));
        *out = ((R2Y * r + G2Y * g + B2Y * b + (16 << 16) + (1 << 15)) >> 16) as u8;
    }
}

/// One chroma row from two RGB rows (the same row twice at an odd bottom edge).
#[multiversion::multiversion(targets("x86_64+avx2", "x86_64+ssse3", "aarch64+neon"))]
fn chroma_row(top: &[u8], bottom: &[u8], u: &mut [u8], v: &mut [u8]) {
    let blocks = top.chunks(6).zip(bottom.chunks(6));
    for ((t, b), (cu, cv)) in blocks.zip(u.iter_mut().zip(v.iter_mut())) {
        // An odd right edge: the last pixel stands for both columns.
        let k = t.len() - 3;
        let sum = |c: usize| {
            i32::from(t[c]) + i32::from(t[k + c]) + i32::from(b[c]) + i32::from(b[k + c])
        };
        let (r, g, b) = (sum(0), sum(1), sum(2));
        *cu = ((R2U * r + G2U * g + B2U * b + (128 << 18) + (1 << 17)) >> 18).clamp(0, 255) as u8;
        *cv = ((R2V * r + G2V * g + B2V * b + (128 << 18) + (1 << 17)) >> 18).clamp(0, 255) as u8;
    }
}

#[cfg(test)]
mod tests;
