//! Per-channel pixel statistics of an episode's resized frames (LeRobot's image stats), kept as
//! exact histograms so that min, max, mean, std and quantiles aggregate over episodes exactly.

use super::rgb::Rgb;

/// Per-channel histogram of an episode's frames: exact min, max, mean, std and quantiles.
#[derive(Debug, Clone)]
pub struct ChannelHistogram {
    counts: [[u64; 256]; 3],
    frames: u64,
}

impl Default for ChannelHistogram {
    fn default() -> Self {
        Self {
            counts: [[0; 256]; 3],
            frames: 0,
        }
    }
}

impl ChannelHistogram {
    /// Adds one frame.
    pub fn add(&mut self, rgb: &Rgb) {
        // Two sets of bins, for even and odd pixels: neighbouring pixels mostly share a value,
        // and one set would make every increment wait for the previous one.
        let mut bins = [[0u32; 256]; 6];
        let (even, odd) = bins.split_at_mut(3);
        for two in rgb.data.chunks(6) {
            for (c, &v) in two.iter().enumerate() {
                match c {
                    0..=2 => even[c][v as usize] += 1,
                    _ => odd[c - 3][v as usize] += 1,
                }
            }
        }
        for (c, counts) in self.counts.iter_mut().enumerate() {
            for (v, n) in counts.iter_mut().enumerate() {
                *n += u64::from(even[c][v]) + u64::from(odd[c][v]);
            }
        }
        self.frames += 1;
    }

    /// Adds another histogram (a frame used by several ticks counts once per tick).
    pub fn absorb(&mut self, other: &ChannelHistogram) {
        for (mine, theirs) in self.counts.iter_mut().zip(&other.counts) {
            for (a, b) in mine.iter_mut().zip(theirs) {
                *a += b;
            }
        }
        self.frames += other.frames;
    }

    /// Frames added.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// (min, max, mean, std, quantiles at `qs`) of channel `c`, values scaled to [0, 1].
    pub fn channel(&self, c: usize, qs: &[f64]) -> (f64, f64, f64, f64, Vec<f64>) {
        let h = &self.counts[c];
        let n: u64 = h.iter().sum();
        if n == 0 {
            return (0.0, 0.0, 0.0, 0.0, vec![0.0; qs.len()]);
        }
        let min = h.iter().position(|&k| k > 0).unwrap_or(0) as f64 / 255.0;
        let max = h.iter().rposition(|&k| k > 0).unwrap_or(0) as f64 / 255.0;
        let (mut s, mut s2) = (0.0, 0.0);
        for (v, &k) in h.iter().enumerate() {
            let x = v as f64 / 255.0;
            s += x * k as f64;
            s2 += x * x * k as f64;
        }
        let mean = s / n as f64;
        let std = (s2 / n as f64 - mean * mean).max(0.0).sqrt();
        let quantiles = qs
            .iter()
            .map(|q| {
                let target = (q * n as f64).ceil().max(1.0) as u64;
                let mut acc = 0;
                for (v, &k) in h.iter().enumerate() {
                    acc += k;
                    if acc >= target {
                        return v as f64 / 255.0;
                    }
                }
                max
            })
            .collect();
        (min, max, mean, std, quantiles)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_stats() {
        let mut h = ChannelHistogram::default();
        h.add(&Rgb {
            width: 2,
            height: 1,
            data: vec![0, 255, 51, 255, 255, 51],
        });
        let (min, max, mean, std, q) = h.channel(0, &[0.01, 0.5, 0.99]);
        assert_eq!((min, max, mean, std), (0.0, 1.0, 0.5, 0.5));
        assert_eq!(q, vec![0.0, 0.0, 1.0]);
        assert_eq!(h.channel(2, &[0.5]).2, 0.2);
    }
}
