//! Each arm's training seeds pooled, held against the recipe's arm by the reading rule of
//! `docs/experiments.md`: "X above Y" is a finding only when Fisher's exact test on the pooled
//! counts gives p < 0.05 (two-sided) *and* X passes at least as many test seeds as Y on every
//! training seed both have, with at least two seeds each; significant but with fewer seeds it
//! reads "on seed N"; significant with the seeds disagreeing, "the seeds disagree"; otherwise
//! "no difference shown". The test and its reading use the training seeds both arms have, so
//! an arm with one seed is held against the recipe's same seed, not the recipe's seeds pooled.
//! The README's results summary is this table.

use super::files::TaskResult;
use super::replicates::replicates;
use crate::figures::EvalFigures;
use crate::significance::{fisher_two_sided, RECIPE};

/// Successes and episodes of `rs` together.
fn pooled(rs: &[&TaskResult]) -> EvalFigures {
    let (k, n) = rs.iter().fold((0, 0), |(k, n), r| {
        (k + r.test.successes, n + r.test.episodes)
    });
    let mut f = EvalFigures::empty();
    f.successes = k;
    f.episodes = n;
    f.success_rate = k as f64 / n.max(1) as f64;
    let (lo, hi) = scaledp_deploy::wilson_interval(k, n);
    (f.wilson_low, f.wilson_high) = (lo, hi);
    f
}

/// The results of `rs` whose training seed `other` also has.
fn shared<'a>(rs: &[&'a TaskResult], other: &[&TaskResult]) -> Vec<&'a TaskResult> {
    rs.iter()
        .filter(|r| other.iter().any(|o| o.train_seed == r.train_seed))
        .copied()
        .collect()
}

/// The reading of `arm` (its results `rs`) against the recipe's `base` on one task, both
/// holding only the training seeds they share.
fn reading(rs: &[&TaskResult], base: &[&TaskResult], p: Option<f64>) -> String {
    if !p.is_some_and(|p| p < 0.05) {
        return "no difference shown".into();
    }
    let (a, b) = (pooled(rs), pooled(base));
    let above = a.success_rate > b.success_rate;
    let word = if above { "above" } else { "below" };
    let common: Vec<(u64, u64)> = rs
        .iter()
        .filter_map(|r| {
            base.iter()
                .find(|o| o.train_seed == r.train_seed)
                .map(|o| (r.test.successes, o.test.successes))
        })
        .collect();
    let agree = common
        .iter()
        .all(|&(x, y)| if above { x >= y } else { x <= y });
    if common.len() < 2 {
        let seeds: Vec<String> = rs.iter().map(|r| r.train_seed.to_string()).collect();
        format!("{word} `{RECIPE}`, on seed {} only", seeds.join(", "))
    } else if agree {
        format!(
            "**{word} `{RECIPE}`** (a finding: {} seeds agree)",
            common.len()
        )
    } else {
        "the seeds disagree".into()
    }
}

/// The pooled table of every task and arm (`arms` in their order), or empty when no arm has
/// a result beside the recipe's.
pub(super) fn table(tasks: &[String], arms: &[&str], results: &[TaskResult]) -> String {
    let mut rows = String::new();
    for task in tasks {
        let base = replicates(results, task, RECIPE);
        for arm in arms {
            let rs = replicates(results, task, arm);
            if rs.is_empty() {
                continue;
            }
            let seeds: Vec<String> = rs
                .iter()
                .map(|r| format!("{}/{}", r.test.successes, r.test.episodes))
                .collect();
            let all = pooled(&rs);
            let (mine, theirs) = (shared(&rs, &base), shared(&base, &rs));
            let (p, read) = if *arm == RECIPE || base.is_empty() {
                (None, "–".to_string())
            } else if mine.is_empty() {
                (None, format!("no training seed in common with `{RECIPE}`"))
            } else {
                let p = fisher_two_sided(&pooled(&mine), &pooled(&theirs));
                (p, reading(&mine, &theirs, p))
            };
            rows.push_str(&format!(
                "| {task} | `{arm}` | {} | {}/{} ({:.0} %, {:.0}–{:.0} %) | {} | {read} |\n",
                seeds.join(", "),
                all.successes,
                all.episodes,
                100.0 * all.success_rate,
                100.0 * all.wilson_low,
                100.0 * all.wilson_high,
                p.map_or("–".into(), |p| if p < 0.001 {
                    "< 0.001".to_string()
                } else {
                    format!("{p:.3}")
                }),
            ));
        }
    }
    if rows.is_empty() {
        return String::new();
    }
    format!(
        "| task | arm | per training seed (0, 1, …) | pooled (95 % Wilson) | Fisher p against `{RECIPE}`, the seeds both have pooled | reading |\n\
         |---|---|---|---|---|---|\n{rows}"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(arm: &str, seed: u64, k: u64) -> TaskResult {
        TaskResult::fixture(arm, seed, k)
    }

    #[test]
    fn the_reading_needs_two_agreeing_seeds() {
        let tasks = vec!["transfer-cube".to_string()];
        let arms = ["ti", "ti-causal", "ti-sincos", "s"];
        let rs = vec![
            result("ti", 0, 14),
            result("ti", 1, 34),
            result("ti-causal", 0, 47),
            result("ti-causal", 1, 49),
            result("ti-sincos", 0, 3),
            result("ti-sincos", 1, 40),
            result("s", 0, 47),
        ];
        let md = table(&tasks, &arms, &rs);
        assert!(md.contains("| `ti` | 14/50, 34/50 | 48/100"), "{md}");
        assert!(
            md.contains("**above `ti`** (a finding: 2 seeds agree)"),
            "{md}"
        );
        // Pooled 43/100 against 48/100: nothing to read.
        assert!(md.contains("| `ti-sincos` | 3/50, 40/50 | 43/100"), "{md}");
        assert!(md.contains("no difference shown"), "{md}");
        assert!(md.contains("above `ti`, on seed 0 only"), "{md}");
        // The one-seed arm is tested against `ti` seed 0 (47/50 against 14/50).
        assert!(
            md.contains("| `s` | 47/50 | 47/50 (94 %, 84–98 %) | < 0.001 |"),
            "{md}"
        );
        // Significant pooled, seeds pulling apart.
        let split = vec![
            result("ti", 0, 10),
            result("ti", 1, 40),
            result("ti-causal", 0, 49),
            result("ti-causal", 1, 35),
        ];
        let md = table(&tasks, &arms, &split);
        assert!(md.contains("the seeds disagree"), "{md}");
    }

    /// Held against the recipe's same seed: 30/50 is not above `ti` seed 0's 20/50 (p = 0.06),
    /// though against `ti`'s two seeds pooled (24/100) it would be (p < 0.001).
    #[test]
    fn a_one_seed_arm_meets_the_recipe_on_its_own_seed() {
        let tasks = vec!["transfer-cube".to_string()];
        let rs = vec![
            result("ti", 0, 20),
            result("ti", 1, 4),
            result("ti-causal", 0, 30),
            result("s", 2, 45),
        ];
        let md = table(&tasks, &["ti", "ti-causal", "s"], &rs);
        assert!(
            md.contains(
                "| `ti-causal` | 30/50 | 30/50 (60 %, 46–72 %) | 0.071 | no difference shown |"
            ),
            "{md}"
        );
        assert!(
            md.contains("| `s` | 45/50 | 45/50 (90 %, 79–96 %) | – | no training seed in common with `ti` |"),
            "{md}"
        );
    }
}
