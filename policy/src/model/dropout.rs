//! Dropout masks, drawn from the training step's generator so both implementations of a model
//! (the candle modules and the CPU engine) drop the same units in the same order, and a resumed
//! run drops what an uninterrupted one would.
//!
//! A DP-T step drops tens of millions of units (attention weights, residual branches, the
//! FFN's hidden units of every layer): one ChaCha8 draw per unit took a sixth of the step. Each
//! mask takes one 64-bit draw from the step's generator instead, and that seeds SplitMix64
//! streams (one per block of 65 536 units, filled in parallel) whose outputs give four 16-bit
//! uniforms each; a unit is dropped when its uniform is below `round(p · 2¹⁶)`.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Units per independently seeded block.
const BLOCK: usize = 1 << 16;

/// SplitMix64 (Steele, Lea and Flood 2014): a fast 64-bit generator, good enough for masks.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Where a training pass draws its dropout masks (none at inference or with `p` = 0).
pub(crate) struct Dropout<'a> {
    rng: &'a mut ChaCha8Rng,
    p: f64,
}

impl<'a> Dropout<'a> {
    /// Masks at rate `p` from `rng`; `None` when nothing would be dropped.
    pub fn new(rng: &'a mut ChaCha8Rng, p: f64) -> Option<Self> {
        (p > 0.0).then_some(Dropout { rng, p })
    }

    /// `n` multipliers in the order of the masked tensor's elements: 0 for a dropped unit,
    /// `1 / (1 − p)` for a kept one (PyTorch's inverted dropout). The drop probability is `p`
    /// rounded to a multiple of 2⁻¹⁶ (0.3 → 0.300003).
    pub fn mask(&mut self, n: usize) -> Vec<f32> {
        let seed = self.rng.random::<u64>();
        let keep = (1.0 / (1.0 - self.p)) as f32;
        let threshold = (self.p * 65536.0).round() as u64;
        let mut out = vec![0f32; n];
        out.par_chunks_mut(BLOCK)
            .enumerate()
            .for_each(|(b, chunk)| {
                let mut g = SplitMix64(seed ^ (b as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
                for quad in chunk.chunks_mut(4) {
                    let r = g.next();
                    for (i, v) in quad.iter_mut().enumerate() {
                        *v = if (r >> (16 * i)) & 0xFFFF < threshold {
                            0.0
                        } else {
                            keep
                        };
                    }
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The share dropped is the rate (within 4 standard deviations of a binomial draw), kept
    /// units are scaled by 1 / (1 − p) so the mean multiplier is 1, masks differ from one call
    /// to the next and repeat for the same generator, and p = 0 draws nothing.
    #[test]
    fn masks_drop_at_the_rate_and_keep_the_expectation() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for p in [0.1, 0.3, 0.5] {
            let n = 400_000;
            let m = Dropout::new(&mut rng, p).unwrap().mask(n);
            let dropped = m.iter().filter(|v| **v == 0.0).count() as f64 / n as f64;
            let sd = (p * (1.0 - p) / n as f64).sqrt();
            assert!((dropped - p).abs() < 4.0 * sd, "p {p}: dropped {dropped}");
            let keep = (1.0 / (1.0 - p)) as f32;
            assert!(m.iter().all(|v| *v == 0.0 || *v == keep));
            let mean = m.iter().map(|v| f64::from(*v)).sum::<f64>() / n as f64;
            assert!(
                (mean - 1.0).abs() < 4.0 * sd / (1.0 - p),
                "p {p}: mean {mean}"
            );
            // Neighbouring units and blocks are not correlated: drops of units i and i + 1.
            let both = m.windows(2).filter(|w| w[0] == 0.0 && w[1] == 0.0).count() as f64;
            let pairs = (n - 1) as f64;
            assert!(
                (both / pairs - p * p).abs() < 5.0 * (p * p / pairs).sqrt(),
                "p {p}"
            );
        }
        let mut d = Dropout::new(&mut rng, 0.3).unwrap();
        assert_ne!(d.mask(1000), d.mask(1000), "a new mask each call");
        let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(9), ChaCha8Rng::seed_from_u64(9));
        assert_eq!(
            Dropout::new(&mut a, 0.3).unwrap().mask(70_000),
            Dropout::new(&mut b, 0.3).unwrap().mask(70_000),
            "the same generator, the same mask"
        );
        let before = rng.clone();
        assert!(Dropout::new(&mut rng, 0.0).is_none());
        assert_eq!(rng, before, "no draws without dropout");
    }
}
