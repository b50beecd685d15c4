//! Each arm's training seeds pooled, held against the recipe's arm by the reading rule of
//! `docs/experiments.md`: "X above Y" is a finding only when Fisher's exact test on the pooled
//! counts gives p < 0.05 (two-sided) *and* X passes at least as many test seeds as Y on every
//! training seed both have, with at least two seeds each; significant but with fewer seeds it
//! reads "on seed N"; significant with the seeds disagreeing, "the seeds disagree"; otherwise
//! "no difference shown". The README's results summary is this table.

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

/// The reading of `arm` (its results `rs`) against the recipe's `base` on one task.
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
    if rs.len() < 2 || base.len() < 2 || common.len() < 2 {
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
            let (p, read) = if *arm == RECIPE || base.is_empty() {
                (None, "–".to_string())
            } else {
                let p = fisher_two_sided(&all, &pooled(&base));
                (p, reading(&rs, &base, p))
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
        "| task | arm | per training seed (0, 1, …) | pooled (95 % Wilson) | Fisher p against `{RECIPE}`, pooled | reading |\n\
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
}
