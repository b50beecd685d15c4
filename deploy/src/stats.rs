//! Small statistics for reports: the Wilson score interval of a success rate, latency
//! percentiles, and how many episodes reached each stage of a task whose reward counts stages.

use serde::{Deserialize, Serialize};

/// Episodes that reached one stage of a staged task (their highest stage at least `number`),
/// as ACT's evaluation counts them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageCount {
    /// What the stage is (`lifted`).
    pub stage: String,
    /// Its number (1, 2, …; gym-aloha's reward that marks it). Read as `reward` too, the
    /// name results written before MetaWorld had stages use.
    #[serde(alias = "reward")]
    pub number: u32,
    /// Episodes whose highest stage was at least `number`.
    pub episodes: u64,
    /// Of all episodes (0–1).
    pub rate: f64,
    /// 95 % Wilson interval of `rate`.
    pub wilson_95: [f64; 2],
}

/// Per stage (`names[i]` is stage i + 1), the episodes whose highest stage reached it;
/// episodes without one count as reaching none.
pub fn stage_counts(names: &[String], highest: &[Option<f64>]) -> Vec<StageCount> {
    let n = highest.len() as u64;
    names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let number = i as u32 + 1;
            let k = highest
                .iter()
                .filter(|h| h.is_some_and(|h| h >= f64::from(number)))
                .count() as u64;
            let (lo, hi) = wilson_interval(k, n);
            StageCount {
                stage: name.clone(),
                number,
                episodes: k,
                rate: k as f64 / n.max(1) as f64,
                wilson_95: [lo, hi],
            }
        })
        .collect()
}

/// The 95 % Wilson score interval of `k` successes in `n` trials ((0, 1) without trials).
pub fn wilson_interval(k: u64, n: u64) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let (k, n, z) = (k as f64, n as f64, 1.959_964);
    let p = k / n;
    let centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let half = z / (1.0 + z * z / n) * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

/// The `q`-quantile (0…1, nearest rank) of `values`; `None` when empty.
pub fn percentile(values: &[f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = (q.clamp(0.0, 1.0) * v.len() as f64).ceil() as usize;
    Some(v[rank.clamp(1, v.len()) - 1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_intervals_match_the_textbook() {
        // 80 of 100: 71.1–86.7 %; 100 of 100: 96.3–100 %.
        let (lo, hi) = wilson_interval(80, 100);
        assert!(
            (lo - 0.7112).abs() < 1e-3 && (hi - 0.8666).abs() < 1e-3,
            "{lo} {hi}"
        );
        let (lo, hi) = wilson_interval(100, 100);
        assert!((lo - 0.9630).abs() < 1e-3 && hi == 1.0, "{lo} {hi}");
        assert_eq!(wilson_interval(0, 0), (0.0, 1.0));
    }

    #[test]
    fn stages_count_episodes_whose_highest_stage_reached_them() {
        let names: Vec<String> = ["touched", "lifted", "transferred"]
            .map(String::from)
            .to_vec();
        // Furthest stages 0, 1, 3, 2, none: touched by 3, lifted by 2, transferred by 1.
        let highest = [Some(0.0), Some(1.0), Some(3.0), Some(2.0), None];
        let c = stage_counts(&names, &highest);
        let got: Vec<(&str, u32, u64)> = c
            .iter()
            .map(|s| (s.stage.as_str(), s.number, s.episodes))
            .collect();
        assert_eq!(
            got,
            [("touched", 1, 3), ("lifted", 2, 2), ("transferred", 3, 1)]
        );
        assert!((c[1].rate - 0.4).abs() < 1e-12);
        assert_eq!(c[1].wilson_95, {
            let (lo, hi) = wilson_interval(2, 5);
            [lo, hi]
        });
        assert!(stage_counts(&[], &highest).is_empty());
        // Results written before the field was renamed (`reward`) still read.
        let old: StageCount = serde_json::from_str(
            r#"{"stage":"lifted","reward":2,"episodes":19,"rate":0.38,"wilson_95":[0.2,0.5]}"#,
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((old.number, old.episodes), (2, 19));
    }

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.5), Some(50.0));
        assert_eq!(percentile(&v, 0.99), Some(99.0));
        assert_eq!(percentile(&[3.0], 0.99), Some(3.0));
        assert_eq!(percentile(&[], 0.5), None);
    }
}
