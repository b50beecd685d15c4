//! Every committed results file carries its own proof: each JSON under `docs/results/` (but
//! `historical/`) passes the audit schema (`scaledp_experiment::audit::check_file`), and each
//! table and plot equals what `scaledp experiment report` rebuilds from the JSON beside it, so
//! no figure in them was typed by hand. No other file may sit there.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use scaledp_experiment::{audit, ExperimentCommand, ReportArgs};

fn results_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results")
}

/// The result directories (those holding JSON), `historical/` left out.
fn result_dirs(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        let mut has_json = false;
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                if p.file_name().is_some_and(|n| n != "historical") {
                    stack.push(p);
                }
            } else if p.extension().is_some_and(|x| x == "json") {
                has_json = true;
            }
        }
        if has_json {
            out.push(dir);
        }
    }
    out.sort();
    out
}

#[test]
fn every_committed_result_passes_the_schema_and_its_table_is_rebuilt_from_the_files() {
    let root = results_root();
    let mut faults = Vec::new();
    let mut checked = 0;
    for dir in result_dirs(&root) {
        let scratch = tempfile::tempdir().unwrap();
        let copy = scratch.path().join("r");
        std::fs::create_dir_all(&copy).unwrap();
        let mut derived = Vec::new();
        for e in std::fs::read_dir(&dir).unwrap().flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().to_string();
            if p.is_dir() {
                continue;
            }
            if name.ends_with(".json") {
                checked += 1;
                if let Err(err) = audit::check_file(&p) {
                    faults.push(format!("{err:#}"));
                }
                std::fs::copy(&p, copy.join(&name)).unwrap();
            } else if name == "table.md" || name.ends_with(".svg") {
                derived.push(name);
            } else if name != "README.md" {
                faults.push(format!(
                    "{}: neither a result, its table or plot, nor a README",
                    p.display()
                ));
            }
        }
        let stop = Arc::new(AtomicBool::new(false));
        let rebuilt = scaledp_experiment::run(
            ExperimentCommand::Report(ReportArgs {
                name: "r".into(),
                results: scratch.path().to_path_buf(),
                readme: None,
            }),
            &stop,
        );
        if let Err(e) = rebuilt {
            faults.push(format!("{}: the report fails: {e:#}", dir.display()));
            continue;
        }
        for name in derived {
            let committed = std::fs::read(dir.join(&name)).unwrap();
            let fresh = std::fs::read(copy.join(&name)).unwrap_or_default();
            if committed != fresh {
                faults.push(format!(
                    "{}: differs from what `scaledp experiment report` rebuilds from the files",
                    dir.join(&name).display()
                ));
            }
        }
    }
    assert!(
        faults.is_empty(),
        "{checked} files checked:\n{}",
        faults.join("\n")
    );
}

/// The README's results summary is what `scaledp experiment report --readme` writes from every
/// benchmark's results: no figure in it typed by hand.
#[test]
fn the_readme_summary_is_rebuilt_from_the_files() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let (start, end) = scaledp_experiment::SUMMARY_MARKERS;
    let a = readme
        .find(start)
        .expect("the README has a results summary");
    let b = readme[a..]
        .find(end)
        .map_or(a + start.len(), |k| a + k + end.len());
    let want = scaledp_experiment::readme_summary(&results_root()).unwrap();
    assert_eq!(
        &readme[a..b],
        want,
        "README.md's summary differs: run `scaledp experiment report --name aloha --readme README.md`"
    );
}

/// The schema refuses what the review found: no outcomes, a dirty revision, outcomes that do not
/// add up, the development seeds.
#[test]
fn the_schema_refuses_what_the_review_found() {
    let binary = serde_json::json!({
        "revision": "0123456789abcdef0123456789abcdef01234567",
        "sha256": "ab".repeat(32),
        "command": "scaledp experiment compare --benchmark aloha --tasks transfer-cube",
        "machine": "2 cores",
        "utc": "2026-11-28T22:00:00Z",
    });
    let outcome = |i: u64, success: bool| {
        serde_json::json!({
            "seed": 3_000_000 + i,
            "success": success,
            "highest_stage": if success { "transferred" } else { "lifted" },
            "steps_to_success": if success { Some(300) } else { None },
            "time_to_success_s": if success { Some(6.0) } else { None },
        })
    };
    let good = serde_json::json!({
        "task": "transfer-cube",
        "arm": "ti",
        "test": {
            "mode": "simulated-time",
            "first_seed": 3_000_000,
            "episodes": 4,
            "successes": 2,
            "outcomes": [outcome(0, true), outcome(1, false), outcome(2, true), outcome(3, false)],
        },
        "audit": {
            "schema": audit::SCHEMA,
            "trained_by": binary,
            "scored_by": binary,
            "simulator": {"gym_aloha": "0.1.1", "scaledp-bridge": "2"},
            "collection": {"seeds": [0, 1, 2], "failed_seeds": [], "command": "scaledp collect"},
            "train_seed": 0,
        },
    });
    audit::check_value(&good).unwrap();
    let fault = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = good.clone();
        edit(&mut v);
        audit::check_value(&v)
            .err()
            .map(|e| format!("{e:#}"))
            .unwrap_or_default()
    };
    let e = fault(&|v| {
        v["test"].as_object_mut().unwrap().remove("outcomes");
    });
    assert!(e.contains("outcomes"), "{e}");
    let e = fault(&|v| {
        v["audit"]["scored_by"]["revision"] =
            "0123456789abcdef0123456789abcdef01234567-dirty".into();
    });
    assert!(e.contains("not a clean commit"), "{e}");
    let e = fault(&|v| v["test"]["successes"] = 3.into());
    assert!(e.contains("another count of successes"), "{e}");
    let e = fault(&|v| {
        v["test"]["first_seed"] = 2_000_000.into();
        for (i, o) in v["test"]["outcomes"]
            .as_array_mut()
            .unwrap()
            .iter_mut()
            .enumerate()
        {
            o["seed"] = (2_000_000 + i as u64).into();
        }
    });
    assert!(e.contains("neither the test range"), "{e}");
    let e = fault(&|v| {
        v["audit"].as_object_mut().unwrap().remove("collection");
    });
    assert!(e.contains("collection"), "{e}");
    let e = fault(&|v| {
        v.as_object_mut().unwrap().remove("audit");
    });
    assert!(e.contains("audit"), "{e}");
}
