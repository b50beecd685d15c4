//! Whether an arm's test successes differ from the recipe arm's (ScaleDP-Ti's) on the same
//! seeds: Fisher's exact test on the 2×2 table of successes and failures — the test for two
//! small binomial samples — with the claim each pairing puts to the test and whose it is (the
//! paper's, or this repo's own hypothesis).
//!
//! Each pairing is one training run against another, so p speaks to the evaluation's sampling
//! noise only, not to the spread between training seeds (replicates, `--train-seed`, show that);
//! the tables say so.

use crate::arms::arm;
use crate::results::EvalFigures;

/// The recipe arm every other arm is held against.
pub(crate) const RECIPE: &str = "ti";

/// Two-sided p of Fisher's exact test for `a`'s successes against `b`'s; `None` when the counts
/// do not fit the test (more than `u32::MAX` episodes, or none).
pub(crate) fn fisher_two_sided(a: &EvalFigures, b: &EvalFigures) -> Option<f64> {
    if a.episodes == 0 || b.episodes == 0 || a.successes > a.episodes || b.successes > b.episodes {
        return None;
    }
    let cell = |v: u64| u32::try_from(v).ok();
    let table = [
        cell(a.successes)?,
        cell(a.episodes - a.successes)?,
        cell(b.successes)?,
        cell(b.episodes - b.successes)?,
    ];
    fishers_exact::fishers_exact(&table)
        .ok()
        .map(|p| p.two_tail_pvalue.min(1.0))
}

/// One pairing: on `task`, arm `arm` against the recipe arm.
pub(crate) struct Pairing<'a> {
    pub task: &'a str,
    pub arm: &'a str,
    /// Both arms' training seed.
    pub seed: u64,
    pub recipe: &'a EvalFigures,
    pub other: &'a EvalFigures,
}

/// `` for the default training seed (0), else ` (seed N)`.
pub(crate) fn seed_suffix(seed: u64) -> String {
    if seed == 0 {
        String::new()
    } else {
        format!(" (seed {seed})")
    }
}

/// `0.009`, `< 0.001`.
fn p_cell(p: Option<f64>) -> String {
    match p {
        None => "–".into(),
        Some(p) if p < 0.001 => "< 0.001".into(),
        Some(p) => format!("{p:.3}"),
    }
}

/// The Markdown table of `pairings` (empty when there are none), with the task column when
/// `with_task`.
pub(crate) fn table(pairings: &[Pairing], with_task: bool) -> String {
    if pairings.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "\nEach arm against ScaleDP-Ti (`{RECIPE}`) on the same test seeds (each pair trained from the same seed): Fisher's exact test, \
         two-sided. Each p holds one training run against another, so it measures the \
         evaluation's sampling noise, not the spread between training seeds.\n\n|{} arm | the claim it tests (whose) | `{RECIPE}` | \
         arm | arm − `{RECIPE}` | p |\n|{}---|---|---|---|---|---|\n",
        if with_task { " task |" } else { "" },
        if with_task { "---|" } else { "" },
    );
    for p in pairings {
        let claim = arm(p.arm).and_then(|a| a.claim()).unwrap_or("–");
        let diff = 100.0 * (p.other.success_rate - p.recipe.success_rate);
        md.push_str(&format!(
            "|{} {}{} | {claim} | {}/{} | {}/{} | {diff:+.0} points | {} |\n",
            if with_task {
                format!(" {} |", p.task)
            } else {
                String::new()
            },
            p.arm,
            seed_suffix(p.seed),
            p.recipe.successes,
            p.recipe.episodes,
            p.other.successes,
            p.other.episodes,
            p_cell(fisher_two_sided(p.recipe, p.other)),
        ));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figures(successes: u64, episodes: u64) -> EvalFigures {
        EvalFigures::counts(successes, episodes)
    }

    /// Against `scipy.stats.fisher_exact` (SciPy, `.venv-sims`) on this project's own results.
    #[test]
    fn p_values_match_scipy() {
        let cases = [
            ((18, 50), (6, 50), 0.009115360042830927), // MetaWorld assembly, Ti vs DP-T
            ((45, 50), (50, 50), 0.05628449442882433), // the cube task, DP-T vs Ti
            ((17, 50), (4, 50), 0.002606834883637818), // ALOHA pilots, 45° vs 78°
        ];
        for ((a, n), (b, m), want) in cases {
            let p = fisher_two_sided(&figures(a, n), &figures(b, m)).unwrap();
            assert!((p - want).abs() < 1e-9, "{a}/{n} vs {b}/{m}: {p} != {want}");
            let q = fisher_two_sided(&figures(b, m), &figures(a, n)).unwrap();
            assert!((p - q).abs() < 1e-12, "not symmetric: {p} vs {q}");
        }
        let same = fisher_two_sided(&figures(50, 50), &figures(50, 50)).unwrap();
        assert!((same - 1.0).abs() < 1e-12, "{same}");
    }

    #[test]
    fn impossible_counts_have_no_p() {
        assert_eq!(fisher_two_sided(&figures(0, 0), &figures(3, 50)), None);
        assert_eq!(fisher_two_sided(&figures(51, 50), &figures(3, 50)), None);
    }

    #[test]
    fn the_table_names_each_claim_and_formats_p() {
        let (ti, dpt, causal) = (figures(18, 50), figures(6, 50), figures(0, 50));
        let md = table(
            &[
                Pairing {
                    task: "assembly",
                    arm: "dp-t",
                    seed: 0,
                    recipe: &ti,
                    other: &dpt,
                },
                Pairing {
                    task: "assembly",
                    arm: "ti-causal",
                    seed: 1,
                    recipe: &ti,
                    other: &causal,
                },
                Pairing {
                    task: "assembly",
                    arm: "ti-sincos",
                    seed: 0,
                    recipe: &ti,
                    other: &dpt,
                },
            ],
            true,
        );
        assert!(
            md.contains("| assembly | dp-t | the paper's: ScaleDP-Ti above DP-T"),
            "{md}"
        );
        assert!(md.contains("| 18/50 | 6/50 | -24 points | 0.009 |"), "{md}");
        assert!(
            md.contains("| 18/50 | 0/50 | -36 points | < 0.001 |"),
            "{md}"
        );
        // The repo's own hypotheses are not passed off as the paper's.
        assert!(
            md.contains("| assembly | ti-sincos | this repo's: fixed positions"),
            "{md}"
        );
        assert!(table(&[], true).is_empty());
    }
}
