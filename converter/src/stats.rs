//! Feature statistics as LeRobot keeps them: min, max, mean, std, count and the quantiles
//! q01, q10, q50, q90, q99 per dimension (per channel for images, scaled to [0, 1]); dataset
//! statistics are aggregated from the episodes' the way LeRobot's `aggregate_stats` does
//! (count-weighted means and quantiles, pooled variance), so a merge of shards equals one run.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// The quantiles kept.
pub const QUANTILES: [(f64, &str); 5] = [
    (0.01, "q01"),
    (0.10, "q10"),
    (0.50, "q50"),
    (0.90, "q90"),
    (0.99, "q99"),
];

/// Statistics of one feature, per dimension.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Minimum.
    pub min: Vec<f64>,
    /// Maximum.
    pub max: Vec<f64>,
    /// Mean.
    pub mean: Vec<f64>,
    /// Standard deviation (population).
    pub std: Vec<f64>,
    /// Frames counted.
    pub count: u64,
    /// Quantiles, in [`QUANTILES`] order.
    pub quantiles: Vec<Vec<f64>>,
    /// True for image features (each dimension is a channel, written as `[[v]]`).
    #[serde(default)]
    pub image: bool,
    /// True for integer features (min and max are written as integers).
    #[serde(default)]
    pub integer: bool,
}

/// Linear-interpolated quantile of sorted values (numpy's default).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let pos = q * (sorted.len() - 1) as f64;
    let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
    sorted[lo] + (pos - lo as f64) * (sorted[hi] - sorted[lo])
}

impl Stats {
    /// Statistics of `rows` rows of `dim` values each (row-major).
    pub fn of_rows(values: &[f64], dim: usize) -> Self {
        let rows = values.len().checked_div(dim).unwrap_or(0);
        let mut s = Stats {
            min: Vec::with_capacity(dim),
            max: Vec::with_capacity(dim),
            mean: Vec::with_capacity(dim),
            std: Vec::with_capacity(dim),
            count: rows as u64,
            quantiles: vec![Vec::with_capacity(dim); QUANTILES.len()],
            image: false,
            integer: false,
        };
        for d in 0..dim {
            let mut col: Vec<f64> = (0..rows).map(|r| values[r * dim + d]).collect();
            col.sort_by(f64::total_cmp);
            let mean = col.iter().sum::<f64>() / rows.max(1) as f64;
            let var = col.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / rows.max(1) as f64;
            s.min.push(col.first().copied().unwrap_or(0.0));
            s.max.push(col.last().copied().unwrap_or(0.0));
            s.mean.push(mean);
            s.std.push(var.sqrt());
            for (k, (q, _)) in QUANTILES.iter().enumerate() {
                s.quantiles[k].push(quantile(&col, *q));
            }
        }
        s
    }

    /// Statistics of an integer column (frame and episode indices).
    pub fn of_integers(values: &[i64]) -> Self {
        let v: Vec<f64> = values.iter().map(|&x| x as f64).collect();
        Self {
            integer: true,
            ..Self::of_rows(&v, 1)
        }
    }

    /// Image statistics from an episode's channel histogram.
    pub fn of_image(h: &crate::images::ChannelHistogram) -> Self {
        let qs: Vec<f64> = QUANTILES.iter().map(|q| q.0).collect();
        let mut s = Stats {
            min: vec![],
            max: vec![],
            mean: vec![],
            std: vec![],
            count: h.frames(),
            quantiles: vec![vec![]; QUANTILES.len()],
            image: true,
            integer: false,
        };
        for c in 0..3 {
            let (min, max, mean, std, q) = h.channel(c, &qs);
            s.min.push(min);
            s.max.push(max);
            s.mean.push(mean);
            s.std.push(std);
            for (k, v) in q.into_iter().enumerate() {
                s.quantiles[k].push(v);
            }
        }
        s
    }

    /// Aggregates per-episode statistics of one feature.
    pub fn aggregate<'a>(parts: impl IntoIterator<Item = &'a Stats>) -> Option<Stats> {
        let parts: Vec<&Stats> = parts.into_iter().collect();
        let first = parts.first()?;
        let dim = first.mean.len();
        let total: u64 = parts.iter().map(|p| p.count).sum();
        let w = |p: &Stats| p.count as f64 / total.max(1) as f64;
        let mut out = Stats {
            min: vec![f64::INFINITY; dim],
            max: vec![f64::NEG_INFINITY; dim],
            mean: vec![0.0; dim],
            std: vec![0.0; dim],
            count: total,
            quantiles: vec![vec![0.0; dim]; QUANTILES.len()],
            image: first.image,
            integer: first.integer,
        };
        for p in &parts {
            for d in 0..dim {
                out.min[d] = out.min[d].min(p.min[d]);
                out.max[d] = out.max[d].max(p.max[d]);
                out.mean[d] += w(p) * p.mean[d];
                for k in 0..QUANTILES.len() {
                    out.quantiles[k][d] += w(p) * p.quantiles[k][d];
                }
            }
        }
        for p in &parts {
            for d in 0..dim {
                let dm = p.mean[d] - out.mean[d];
                out.std[d] += w(p) * (p.std[d] * p.std[d] + dm * dm);
            }
        }
        for s in &mut out.std {
            *s = s.sqrt();
        }
        Some(out)
    }

    /// LeRobot's JSON form: `{min, max, mean, std, count: [n], q01, …}`; image stats nested
    /// per channel as `[[[v]], [[v]], [[v]]]`.
    pub fn to_lerobot_json(&self) -> serde_json::Value {
        let v = |x: &[f64]| -> serde_json::Value {
            if self.image {
                x.iter().map(|c| serde_json::json!([[c]])).collect()
            } else {
                serde_json::json!(x)
            }
        };
        let mut m = serde_json::Map::new();
        let int = |x: &[f64]| serde_json::json!(x.iter().map(|&v| v as i64).collect::<Vec<_>>());
        m.insert(
            "min".into(),
            if self.integer {
                int(&self.min)
            } else {
                v(&self.min)
            },
        );
        m.insert(
            "max".into(),
            if self.integer {
                int(&self.max)
            } else {
                v(&self.max)
            },
        );
        m.insert("mean".into(), v(&self.mean));
        m.insert("std".into(), v(&self.std));
        m.insert("count".into(), serde_json::json!([self.count]));
        for (k, (_, name)) in QUANTILES.iter().enumerate() {
            m.insert((*name).into(), v(&self.quantiles[k]));
        }
        serde_json::Value::Object(m)
    }
}

/// Aggregates a list of per-episode feature maps.
pub fn aggregate_all<'a>(
    episodes: impl IntoIterator<Item = &'a BTreeMap<String, Stats>>,
) -> BTreeMap<String, Stats> {
    let episodes: Vec<_> = episodes.into_iter().collect();
    let mut names: Vec<&String> = episodes.iter().flat_map(|e| e.keys()).collect();
    names.sort();
    names.dedup();
    names
        .into_iter()
        .filter_map(|n| {
            Stats::aggregate(episodes.iter().filter_map(|e| e.get(n))).map(|s| (n.clone(), s))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_dimension_and_aggregate() {
        let a = Stats::of_rows(&[0.0, 10.0, 1.0, 20.0, 2.0, 30.0], 2);
        assert_eq!(
            (a.min.clone(), a.max.clone(), a.mean.clone()),
            (vec![0.0, 10.0], vec![2.0, 30.0], vec![1.0, 20.0])
        );
        assert_eq!(a.quantiles[2], vec![1.0, 20.0]);
        let b = Stats::of_rows(&[4.0, 40.0], 2);
        let all = Stats::aggregate([&a, &b]).unwrap();
        let direct = Stats::of_rows(&[0.0, 10.0, 1.0, 20.0, 2.0, 30.0, 4.0, 40.0], 2);
        for d in 0..2 {
            assert!((all.mean[d] - direct.mean[d]).abs() < 1e-12);
            assert!(
                (all.std[d] - direct.std[d]).abs() < 1e-12,
                "pooled variance is exact"
            );
        }
        assert_eq!(all.count, 4);
        assert_eq!(all.min, vec![0.0, 10.0]);
    }
}
