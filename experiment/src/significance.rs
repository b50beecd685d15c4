//! Whether an arm's test successes differ from the recipe arm's (ScaleDP-Ti's) on the same
//! seeds: Fisher's exact test on the 2×2 table of successes and failures — the test for two
//! small binomial samples — and, because both arms ran the same seeds, McNemar's exact test on
//! the episodes where they disagree (the paired test: an exact binomial test of the discordant
//! seeds against one half), with the claim each pairing puts to the test and whose it is (the
//! paper's, or this repo's own hypothesis).
//!
//! Each pairing is one training run against another, so p speaks to the evaluation's sampling
//! noise only, not to the spread between training seeds (replicates, `--train-seed`, show that);
//! the tables say so.

use crate::arms::arm;
use crate::figures::EvalFigures;

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

/// The paired test of `a` against `b` on the seeds both ran: the seeds only `a` passed, those
/// only `b` passed, and McNemar's exact two-sided p (binomial, n = the discordant seeds,
/// p = ½); `None` when the files hold no per-episode outcomes or no seed in common.
pub(crate) fn mcnemar_exact(a: &EvalFigures, b: &EvalFigures) -> Option<(u64, u64, f64)> {
    let theirs: std::collections::BTreeMap<u64, bool> =
        b.outcomes.iter().map(|o| (o.seed, o.success)).collect();
    let (mut only_a, mut only_b, mut shared) = (0u64, 0u64, 0u64);
    for o in &a.outcomes {
        if let Some(&other) = theirs.get(&o.seed) {
            shared += 1;
            match (o.success, other) {
                (true, false) => only_a += 1,
                (false, true) => only_b += 1,
                _ => {}
            }
        }
    }
    if shared == 0 {
        return None;
    }
    Some((
        only_a,
        only_b,
        binomial_two_sided(only_a.min(only_b), only_a + only_b),
    ))
}

/// Two-sided exact binomial p of `k` or fewer in `n` at p = ½ (`k` ≤ n/2): twice the lower
/// tail, at most 1. Summed in logs, so large `n` does not underflow.
fn binomial_two_sided(k: u64, n: u64) -> f64 {
    if n == 0 {
        return 1.0;
    }
    let half_n = n as f64 * std::f64::consts::LN_2;
    let (mut ln_c, mut tail) = (0.0f64, 0.0f64);
    for i in 0..=k {
        if i > 0 {
            ln_c += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        tail += (ln_c - half_n).exp();
    }
    (2.0 * tail).min(1.0)
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
pub(crate) fn p_cell(p: Option<f64>) -> String {
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
         two-sided, and McNemar's exact test on the seeds where the two disagree (paired: \
         only `{RECIPE}` passed / only the arm passed). Each p holds one training run against \
         another, so it measures the evaluation's sampling noise, not the spread between \
         training seeds.\n\n|{} arm | the claim it tests (whose) | `{RECIPE}` | \
         arm | arm − `{RECIPE}` | Fisher p | discordant | McNemar p |\n|{}---|---|---|---|---|---|---|---|\n",
        if with_task { " task |" } else { "" },
        if with_task { "---|" } else { "" },
    );
    for p in pairings {
        let claim = arm(p.arm).and_then(|a| a.claim()).unwrap_or("–");
        let diff = 100.0 * (p.other.success_rate - p.recipe.success_rate);
        let paired = mcnemar_exact(p.recipe, p.other);
        md.push_str(&format!(
            "|{} {}{} | {claim} | {}/{} | {}/{} | {diff:+.0} points | {} | {} | {} |\n",
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
            paired.map_or("–".into(), |(a, b, _)| format!("{a} / {b}")),
            p_cell(paired.map(|(_, _, p)| p)),
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

    /// Against `scipy.stats.binomtest(min(b, c), b + c, 0.5)` (SciPy, `.venv-sims`).
    #[test]
    fn paired_p_values_match_scipy() {
        for (b, c, want) in [
            (3, 14, 0.012725830078125),
            (0, 5, 0.0625),
            (10, 10, 1.0),
            (1, 0, 1.0),
            (20, 33, 0.09837064844049181),
        ] {
            let p = binomial_two_sided(b.min(c), b + c);
            assert!((p - want).abs() < 1e-12, "{b} / {c}: {p} != {want}");
        }
        // Paired by seed: 4 seeds, Ti passes 0 and 1, the arm 1, 2 and 3.
        let ti = EvalFigures::pattern(&[true, true, false, false]);
        let arm = EvalFigures::pattern(&[false, true, true, true]);
        let (only_ti, only_arm, p) = mcnemar_exact(&ti, &arm).unwrap();
        assert_eq!((only_ti, only_arm), (1, 2));
        assert!((p - 1.0).abs() < 1e-12, "{p}");
        // No outcomes (a file from before the audit): no paired test.
        let mut bare = figures(3, 4);
        bare.outcomes.clear();
        assert_eq!(mcnemar_exact(&ti, &bare), None);
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
        // The fixtures pass their first seeds: every discordant seed is one only Ti passed.
        assert!(
            md.contains("| 18/50 | 6/50 | -24 points | 0.009 | 12 / 0 | < 0.001 |"),
            "{md}"
        );
        assert!(
            md.contains("| 18/50 | 0/50 | -36 points | < 0.001 | 18 / 0 | < 0.001 |"),
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
