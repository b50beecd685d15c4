//! Resampling helpers for [`crate::images`]: Lanczos3 with its filter values cached, one
//! resizer per thread, and the reordering of small resized frames to RGB.

use fast_image_resize as fr;

/// `C`-byte pixels → RGB, taking R, G, B from bytes `R`, `G`, `B` of each pixel.
pub(crate) fn reorder<const C: usize, const R: usize, const G: usize, const B: usize>(
    src: &[u8],
    dst: &mut [u8],
) {
    for (d, s) in dst.chunks_exact_mut(3).zip(src.chunks_exact(C)) {
        d[0] = s[R];
        d[1] = s[G];
        d[2] = s[B];
    }
}

/// fast_image_resize's Lanczos3, with the filter's values remembered: it recomputes the
/// convolution coefficients for every frame (two `sin` per tap, ~15 % of a frame's resize), yet
/// a given pair of sizes only ever asks for the same few values (24 for 1280 → 320).
pub(crate) fn lanczos3() -> fr::FilterType {
    fr::Filter::new("Lanczos3", cached_lanczos3, 3.0)
        .map_or(fr::FilterType::Lanczos3, fr::FilterType::Custom)
}

/// `fast_image_resize`'s `lanczos_filter`, bit for bit (so the coefficients are the same).
fn lanczos3_filter(x: f64) -> f64 {
    fn sinc(mut x: f64) -> f64 {
        if x == 0.0 {
            1.0
        } else {
            x *= std::f64::consts::PI;
            x.sin() / x
        }
    }
    if (-3.0..3.0).contains(&x) {
        sinc(x) * sinc(x / 3.)
    } else {
        0.0
    }
}

/// Slots of the per-thread cache of [`cached_lanczos3`] (direct-mapped by the argument's bits).
const LANCZOS_SLOTS: usize = 1 << 12;

thread_local! {
    static LANCZOS: std::cell::RefCell<Vec<(u64, f64)>> =
        std::cell::RefCell::new(vec![(u64::MAX, 0.0); LANCZOS_SLOTS]);
}

fn cached_lanczos3(x: f64) -> f64 {
    let bits = x.to_bits();
    let slot = (bits.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 52) as usize % LANCZOS_SLOTS;
    LANCZOS.with(|cache| {
        let Ok(mut cache) = cache.try_borrow_mut() else {
            return lanczos3_filter(x);
        };
        match cache.get(slot) {
            Some(&(b, v)) if b == bits => v,
            _ => {
                let v = lanczos3_filter(x);
                if let Some(e) = cache.get_mut(slot) {
                    *e = (bits, v);
                }
                v
            }
        }
    })
}

thread_local! {
    /// One resizer per thread: it keeps its scratch buffer (a 1280×240 frame for ZED images)
    /// from one frame to the next instead of allocating and zeroing it each time.
    static RESIZER: std::cell::RefCell<fr::Resizer> = std::cell::RefCell::new(fr::Resizer::new());
}

pub(crate) fn with_resizer<T>(f: impl FnOnce(&mut fr::Resizer) -> T) -> T {
    RESIZER.with(|r| match r.try_borrow_mut() {
        Ok(mut r) => f(&mut r),
        Err(_) => f(&mut fr::Resizer::new()),
    })
}
