//! Each arm's training seeds pooled, held against the recipe's arm by the reading rule of
//! `docs/experiments.md`: "X above Y" is a finding only when Fisher's exact test on the pooled
//! counts gives p < 0.05 (two-sided) *and* X passes at least as many test seeds as Y on every
//! training seed both have, with at least two seeds each; significant but with fewer seeds it
//! reads "on seed N"; significant with the seeds disagreeing, "the seeds disagree"; otherwise
//! "no difference shown". The test and its reading use the training seeds both arms have, so
//! an arm with one seed is held against the recipe's same seed, not the recipe's seeds pooled.
//! An arm a registered reading also holds against another arm ([`crate::Arm::also_against`])
//! gets a second table, read by the same rule, with the paired test on each shared seed.
//! The README's results summary is these tables.

use super::files::TaskResult;
use super::replicates::replicates;
use crate::figures::EvalFigures;
use crate::significance::{fisher_two_sided, mcnemar_exact, p_cell, RECIPE};

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

/// The reading of an arm (its results `rs`) against the arm `against` (its results `base`,
/// the recipe's unless a registered reading names another) on one task, both holding only the
/// training seeds they share.
fn reading(rs: &[&TaskResult], base: &[&TaskResult], against: &str, p: Option<f64>) -> String {
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
        format!("{word} `{against}`, on seed {} only", seeds.join(", "))
    } else if agree {
        format!(
            "**{word} `{against}`** (a finding: {} seeds agree)",
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
            let all = pooled(&rs);
            let (mine, theirs) = (shared(&rs, &base), shared(&base, &rs));
            let (p, read) = if *arm == RECIPE || base.is_empty() {
                (None, "–".to_string())
            } else if mine.is_empty() {
                (None, format!("no training seed in common with `{RECIPE}`"))
            } else {
                let p = fisher_two_sided(&pooled(&mine), &pooled(&theirs));
                (p, reading(&mine, &theirs, RECIPE, p))
            };
            rows.push_str(&format!(
                "| {task} | `{arm}` | {} | {}/{} ({:.0} %, {:.0}–{:.0} %) | {} | {read} |\n",
                per_seed(&rs),
                all.successes,
                all.episodes,
                100.0 * all.success_rate,
                100.0 * all.wilson_low,
                100.0 * all.wilson_high,
                p_cell(p),
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

/// Successes per training seed: `49/50, 47/50`.
fn per_seed(rs: &[&TaskResult]) -> String {
    rs.iter()
        .map(|r| format!("{}/{}", r.test.successes, r.test.episodes))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The section (its lead and table) of the arms (of `arms`) that a registered reading holds
/// against an arm other than the recipe's, on the training seeds both have; empty when no such
/// pair has landed.
pub(super) fn against_others(tasks: &[String], arms: &[&str], results: &[TaskResult]) -> String {
    let mut rows = String::new();
    for task in tasks {
        for arm in arms {
            let Some(against) = crate::arms::arm(arm).and_then(|a| a.also_against()) else {
                continue;
            };
            let (rs, base) = (
                replicates(results, task, arm),
                replicates(results, task, against),
            );
            let (mine, theirs) = (shared(&rs, &base), shared(&base, &rs));
            if mine.is_empty() {
                continue;
            }
            let p = fisher_two_sided(&pooled(&mine), &pooled(&theirs));
            let paired: Vec<String> = mine
                .iter()
                .filter_map(|r| {
                    let o = theirs.iter().find(|o| o.train_seed == r.train_seed)?;
                    let (only_arm, only_other, p) = mcnemar_exact(&r.test, &o.test)?;
                    Some(format!(
                        "seed {}: {only_other} / {only_arm} ({})",
                        r.train_seed,
                        p_cell(Some(p))
                    ))
                })
                .collect();
            let (a, b) = (pooled(&mine), pooled(&theirs));
            rows.push_str(&format!(
                "| {task} | `{arm}` | `{against}` | {} | {} | {}/{} against {}/{} | {} | {} | {} |\n",
                per_seed(&mine),
                per_seed(&theirs),
                a.successes,
                a.episodes,
                b.successes,
                b.episodes,
                p_cell(p),
                if paired.is_empty() { "–".to_string() } else { paired.join("; ") },
                reading(&mine, &theirs, against, p),
            ));
        }
    }
    if rows.is_empty() {
        return String::new();
    }
    format!(
        "\nArms a registered reading of `docs/experiments.md` also holds against another arm \
         (reading 2, the budget: `ti-causal-x3` against `ti-x3`), by the same rule, on the \
         training seeds both have:\n\n\
         | task | arm | against | arm, per training seed | against, per training seed | pooled | Fisher p | paired per seed: only `against` / only the arm (McNemar p) | reading |\n\
         |---|---|---|---|---|---|---|---|---|\n{rows}"
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

    #[test]
    fn a_registered_second_reference_is_read_by_the_same_rule() {
        let tasks = vec!["transfer-cube".to_string()];
        let arms = ["ti", "ti-x3", "ti-causal-x3"];
        // One seed each: 45/50 against 49/50, paired 4 / 0 (the fixtures pass their first seeds).
        let one = vec![
            result("ti", 0, 20),
            result("ti-x3", 0, 49),
            result("ti-causal-x3", 0, 45),
        ];
        let md = against_others(&tasks, &arms, &one);
        assert!(
            md.contains("| transfer-cube | `ti-causal-x3` | `ti-x3` | 45/50 | 49/50 | 45/50 against 49/50 | 0.204 | seed 0: 4 / 0 (0.125) | no difference shown |"),
            "{md}"
        );
        // Two agreeing seeds, far apart: a finding, worded against `ti-x3`, not `ti`.
        let two = vec![
            result("ti-x3", 0, 20),
            result("ti-x3", 1, 25),
            result("ti-causal-x3", 0, 49),
            result("ti-causal-x3", 1, 48),
            result("ti-causal-x3", 2, 48),
        ];
        let md = against_others(&tasks, &arms, &two);
        assert!(
            md.contains("| 49/50, 48/50 | 20/50, 25/50 | 97/100 against 45/100 |"),
            "{md}"
        );
        assert!(
            md.contains("seed 0: 0 / 29 (< 0.001); seed 1: 0 / 23 (< 0.001) | **above `ti-x3`** (a finding: 2 seeds agree) |"),
            "{md}"
        );
        // Nothing to hold it against yet, and arms without a second reference: no table.
        assert!(against_others(&tasks, &arms, &[result("ti-causal-x3", 0, 45)]).is_empty());
        assert!(against_others(&tasks, &["ti", "ti-x3"], &two).is_empty());
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
