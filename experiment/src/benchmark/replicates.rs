//! Replicates: a (task, arm) trained from several seeds (`compare --train-seed`). Each seed's
//! result is its own file; the table shows them side by side, pairs arms trained from the same
//! seed, and averages seeds before tasks.

use super::cells::{marked, Level};
use super::files::TaskResult;
use crate::significance::{seed_suffix, Pairing, RECIPE};

/// Every result of (task, arm), one per training seed, the lowest seed first.
pub(super) fn replicates<'a>(
    results: &'a [TaskResult],
    task: &str,
    arm: &str,
) -> Vec<&'a TaskResult> {
    let mut v: Vec<&TaskResult> = results
        .iter()
        .filter(|r| r.task == task && r.arm == arm)
        .collect();
    v.sort_by_key(|r| r.train_seed);
    v
}

/// A table cell: one result as `pct` (marked when an older bridge than `newest` scored it),
/// replicates each with their training seed.
pub(super) fn cell(rs: &[&TaskResult], newest: u32) -> String {
    match rs {
        [] => "–".into(),
        [r] => format!("{}{}", marked(&r.test, newest), seed_suffix(r.train_seed)),
        _ => rs
            .iter()
            .map(|r| format!("seed {}: {}", r.train_seed, marked(&r.test, newest)))
            .collect::<Vec<_>>()
            .join("; "),
    }
}

/// Per task, each other arm against the recipe arm trained with the same seed.
pub(super) fn pairings<'a>(
    tasks: &'a [(Level, String)],
    arms: &[&'a str],
    results: &'a [TaskResult],
) -> Vec<Pairing<'a>> {
    let mut out = Vec::new();
    for (_, task) in tasks {
        for recipe in replicates(results, task, RECIPE) {
            for a in arms.iter().filter(|a| **a != RECIPE) {
                out.extend(
                    replicates(results, task, a)
                        .into_iter()
                        .filter(|o| o.train_seed == recipe.train_seed)
                        .map(|o| Pairing {
                            task,
                            arm: a,
                            seed: o.train_seed,
                            recipe: &recipe.test,
                            other: &o.test,
                        }),
                );
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::{rebuild, result_path};
    use super::*;

    fn result(arm: &str, seed: u64, successes: u64) -> TaskResult {
        TaskResult::fixture(arm, seed, successes)
    }

    #[test]
    fn replicates_sit_side_by_side_pair_by_seed_and_average_first() {
        let dir = tempfile::tempdir().unwrap();
        // Seed 0 written without the field, as results before `--train-seed` were.
        let mut old = serde_json::to_value(result("ti", 0, 14)).unwrap();
        old.as_object_mut().unwrap().remove("train_seed");
        std::fs::write(
            dir.path().join("transfer-cube--ti.json"),
            serde_json::to_vec(&old).unwrap(),
        )
        .unwrap();
        for (arm, seed, k) in [("ti", 1, 20), ("ti-causal", 0, 47), ("ti-causal", 1, 40)] {
            let path = result_path(dir.path(), "transfer-cube", arm, seed);
            let r = result(arm, seed, k);
            std::fs::write(path, serde_json::to_vec(&r).unwrap()).unwrap();
        }
        rebuild(dir.path()).unwrap();
        let md = std::fs::read_to_string(dir.path().join("table.md")).unwrap();
        assert!(
            md.contains("| seed 0: 28 % (14/50, 10–90); seed 1: 40 % (20/50, 10–90) |"),
            "{md}"
        );
        // Each pairing holds arms trained from the same seed.
        assert!(
            md.contains("| transfer-cube | ti-causal | the paper's: non-causal"),
            "{md}"
        );
        assert!(md.contains("| 14/50 | 47/50 | +66 points |"), "{md}");
        assert!(
            md.contains("| transfer-cube | ti-causal (seed 1) |"),
            "{md}"
        );
        assert!(md.contains("| 20/50 | 40/50 | +40 points |"), "{md}");
        // Seeds averaged within the task: (28 + 40) / 2 and (94 + 80) / 2.
        assert!(md.contains("| bimanual | 1 | 34.0 % | 87.0 % |"), "{md}");
        assert!(
            md.contains("| transfer-cube | ti (seed 1) | 2500 |"),
            "{md}"
        );
    }

    #[test]
    fn one_result_names_its_seed_only_when_not_the_default() {
        let (a, b) = (result("ti", 0, 14), result("ti", 2, 14));
        assert_eq!(cell(&[&a], 1), "28 % (14/50, 10–90)");
        assert_eq!(cell(&[&b], 1), "28 % (14/50, 10–90) (seed 2)");
        assert_eq!(cell(&[], 1), "–");
    }

    /// A result scored by an earlier bridge than the newest in the table is marked, with a
    /// note saying how to score it again; a table of one behaviour has no marks.
    #[test]
    fn results_of_an_older_bridge_are_marked() {
        let dir = tempfile::tempdir().unwrap();
        let write = |arm: &str, bridge: Option<&str>| {
            let mut r = result(arm, 0, 20);
            r.test.bridge = bridge.map(String::from);
            let path = result_path(dir.path(), "transfer-cube", arm, 0);
            std::fs::write(path, serde_json::to_vec(&r).unwrap()).unwrap();
        };
        write("ti", None);
        write("dp-t", None);
        rebuild(dir.path()).unwrap();
        let md = std::fs::read_to_string(dir.path().join("table.md")).unwrap();
        assert!(!md.contains('†'), "{md}");
        write("dp-t", Some("2"));
        rebuild(dir.path()).unwrap();
        let md = std::fs::read_to_string(dir.path().join("table.md")).unwrap();
        assert!(
            md.contains(
                "| bimanual | transfer-cube | 40 % (20/50, 10–90) † | 40 % (20/50, 10–90) |"
            ),
            "{md}"
        );
        assert!(
            md.contains("--benchmark aloha --tasks <task> --rescore"),
            "{md}"
        );
    }

    /// The plot names each level under its bars and draws every bar's 95 % interval (the
    /// MetaWorld plot had neither).
    #[test]
    fn the_plot_labels_each_level_and_draws_intervals() {
        let dir = tempfile::tempdir().unwrap();
        for (task, level, arm, k) in [
            ("reach", "easy", "ti", 40),
            ("reach", "easy", "dp-t", 30),
            ("assembly", "hard", "ti", 10),
            ("assembly", "hard", "dp-t", 20),
        ] {
            let mut r = result(arm, 0, k);
            r.benchmark = "metaworld".into();
            (r.task, r.level) = (task.into(), level.into());
            let path = result_path(dir.path(), task, arm, 0);
            std::fs::write(path, serde_json::to_vec(&r).unwrap()).unwrap();
        }
        rebuild(dir.path()).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("success_by_level.svg")).unwrap();
        assert!(svg.contains("\neasy (1 task)\n"), "{svg}");
        assert!(svg.contains("\nhard (1 task)\n"), "{svg}");
        // Four bars, four whiskers (the 2-px polylines; the axes are 1 px).
        let whiskers = svg.matches(r#"stroke-width="2" points"#).count();
        assert_eq!(whiskers, 4, "{svg}");
    }

    /// Per task (ALOHA), a task is drawn with the arms it has: insertion, where only `ti` has
    /// landed, was missing from the plot while the level means (which compare like with like)
    /// rightly leave it out.
    #[test]
    fn the_per_task_plot_draws_a_task_that_lacks_an_arm() {
        let dir = tempfile::tempdir().unwrap();
        for (task, arm, k) in [
            ("transfer-cube", "ti", 20),
            ("transfer-cube", "ti-sincos", 3),
            ("insertion", "ti", 4),
        ] {
            let mut r = result(arm, 0, k);
            r.task = task.into();
            let path = result_path(dir.path(), task, arm, 0);
            std::fs::write(path, serde_json::to_vec(&r).unwrap()).unwrap();
        }
        rebuild(dir.path()).unwrap();
        let svg = std::fs::read_to_string(dir.path().join("success_by_level.svg")).unwrap();
        assert!(svg.contains("\ninsertion\n"), "{svg}");
        assert!(svg.contains("\ntransfer-cube\n"), "{svg}");
        let whiskers = svg.matches(r#"stroke-width="2" points"#).count();
        assert_eq!(whiskers, 3, "{svg}");
        let md = std::fs::read_to_string(dir.path().join("table.md")).unwrap();
        assert!(md.contains("| bimanual | 1 | 40.0 % | 6.0 % |"), "{md}");
    }

    /// The README's summary holds every benchmark's pooled table under its name, in name order
    /// (it held ALOHA's alone, so MetaWorld's readings would not have reached the README).
    #[test]
    fn the_summary_holds_every_benchmark() {
        let root = tempfile::tempdir().unwrap();
        for (bench, task, k) in [("metaworld", "assembly", 30), ("aloha", "insertion", 4)] {
            let dir = root.path().join(bench);
            std::fs::create_dir(&dir).unwrap();
            let mut r = result("ti", 0, k);
            (r.benchmark, r.task) = (bench.into(), task.into());
            let path = result_path(&dir, task, "ti", 0);
            std::fs::write(path, serde_json::to_vec(&r).unwrap()).unwrap();
        }
        std::fs::create_dir(root.path().join("historical")).unwrap();
        let md = super::super::summaries(root.path()).unwrap();
        let (a, m) = (
            md.find("**ALOHA**").unwrap(),
            md.find("**MetaWorld**").unwrap(),
        );
        assert!(a < m, "{md}");
        assert!(md[a..m].contains("| insertion | `ti` | 4/50 |"), "{md}");
        assert!(md[m..].contains("| assembly | `ti` | 30/50 |"), "{md}");
        let empty = tempfile::tempdir().unwrap();
        assert!(super::super::summaries(empty.path()).is_err());
    }
}
