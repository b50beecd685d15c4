//! Dropout masks, drawn from the training step's generator so both implementations of a model
//! (the candle modules and the CPU engine) drop the same units in the same order, and a resumed
//! run drops what an uninterrupted one would.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

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
    /// `1 / (1 − p)` for a kept one (PyTorch's inverted dropout: the expectation is unchanged).
    /// One uniform draw per unit, dropped when it falls below `p`.
    pub fn mask(&mut self, n: usize) -> Vec<f32> {
        let keep = (1.0 / (1.0 - self.p)) as f32;
        let p = self.p as f32;
        (0..n)
            .map(|_| {
                if self.rng.random::<f32>() < p {
                    0.0
                } else {
                    keep
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The share dropped is the rate (within 4 standard deviations of a binomial draw), kept
    /// units are scaled by 1 / (1 − p) so the mean multiplier is 1, and p = 0 draws nothing.
    #[test]
    fn masks_drop_at_the_rate_and_keep_the_expectation() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for p in [0.1, 0.3, 0.5] {
            let n = 200_000;
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
        }
        let before = rng.clone();
        assert!(Dropout::new(&mut rng, 0.0).is_none());
        assert_eq!(rng, before, "no draws without dropout");
    }
}
