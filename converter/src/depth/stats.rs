//! Statistics of an episode's depth frames, as LeRobot keeps them per feature (one dimension:
//! every pixel is a sample of the same quantity), over the pixels that hold a measurement
//! (holes, 0 or NaN/±inf, left out), in the source's unit. Min, max, mean and std are exact;
//! quantiles come from a histogram of whole millimetres (exact for `16UC1`, to within half a
//! millimetre for `32FC1`).

use crate::stats::{Stats, QUANTILES};

/// Bins of the quantile histogram: one per millimetre, 0 to 65.535 m.
const BINS: usize = 1 << 16;

/// Accumulates the depth frames of an episode, one frame per tick.
#[derive(Debug, Clone)]
pub struct DepthStats {
    /// Millimetres per unit of the values (1 for mm, 1000 for m).
    mm_per_unit: f64,
    histogram: Vec<u64>,
    min: f64,
    max: f64,
    sum: f64,
    sum2: f64,
    valid: u64,
    frames: u64,
}

impl DepthStats {
    /// For values in millimetres (`16UC1`) or metres (`32FC1`).
    pub fn new(encoding: scaledp_schema::rig::DepthEncoding) -> Self {
        let mm_per_unit = match encoding {
            scaledp_schema::rig::DepthEncoding::U16Millimetres => 1.0,
            scaledp_schema::rig::DepthEncoding::F32Metres => 1000.0,
        };
        Self {
            mm_per_unit,
            histogram: vec![0; BINS],
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            sum: 0.0,
            sum2: 0.0,
            valid: 0,
            frames: 0,
        }
    }

    /// Adds a frame's values (holes are skipped).
    pub fn add(&mut self, values: impl Iterator<Item = f64>) {
        for v in values {
            if !(v.is_finite() && v > 0.0) {
                continue;
            }
            self.min = self.min.min(v);
            self.max = self.max.max(v);
            self.sum += v;
            self.sum2 += v * v;
            self.valid += 1;
            let bin = (v * self.mm_per_unit).round().clamp(0.0, (BINS - 1) as f64) as usize;
            self.histogram[bin] += 1;
        }
        self.frames += 1;
    }

    /// The statistics LeRobot keeps (`count` = frames, as for every feature).
    pub fn finish(&self) -> Stats {
        let one = |v: f64| vec![v];
        if self.valid == 0 {
            return Stats {
                min: one(0.0),
                max: one(0.0),
                mean: one(0.0),
                std: one(0.0),
                count: self.frames,
                quantiles: vec![one(0.0); QUANTILES.len()],
                image: false,
                integer: false,
            };
        }
        let n = self.valid as f64;
        let mean = self.sum / n;
        let std = (self.sum2 / n - mean * mean).max(0.0).sqrt();
        let quantiles = QUANTILES
            .iter()
            .map(|(q, _)| {
                let target = (q * n).ceil().max(1.0) as u64;
                let mut acc = 0;
                for (bin, &k) in self.histogram.iter().enumerate() {
                    acc += k;
                    if acc >= target {
                        let v = bin as f64 / self.mm_per_unit;
                        return one(v.clamp(self.min, self.max));
                    }
                }
                one(self.max)
            })
            .collect();
        Stats {
            min: one(self.min),
            max: one(self.max),
            mean: one(mean),
            std: one(std),
            count: self.frames,
            quantiles,
            image: false,
            integer: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scaledp_schema::rig::DepthEncoding;

    #[test]
    fn holes_are_left_out() {
        let mut s = DepthStats::new(DepthEncoding::U16Millimetres);
        s.add([0.0, 1000.0, 3000.0, 0.0].into_iter());
        s.add([2000.0, 0.0].into_iter());
        let st = s.finish();
        assert_eq!(st.count, 2);
        assert_eq!((st.min[0], st.max[0], st.mean[0]), (1000.0, 3000.0, 2000.0));
        assert_eq!(st.quantiles[2], vec![2000.0]);
        let mut m = DepthStats::new(DepthEncoding::F32Metres);
        m.add([f64::NAN, 0.5, f64::INFINITY, 1.5].into_iter());
        let st = m.finish();
        assert_eq!((st.min[0], st.max[0], st.mean[0]), (0.5, 1.5, 1.0));
        assert_eq!(st.quantiles[0], vec![0.5]);
        let empty = DepthStats::new(DepthEncoding::F32Metres).finish();
        assert_eq!((empty.count, empty.mean[0]), (0, 0.0));
    }
}
