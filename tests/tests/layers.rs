//! The layering rule: `schema` and `datasets` never pull in zenoh, rerun or mcap; `schema` no
//! async runtime either (`datasets` has tokio only as the runtime of object_store's S3 client).
//! rerun stays in the viewer: no other library crate pulls it in, the CLI only through its
//! default `view` feature, and the workspace compiles one arrow, the one rerun uses.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::process::Command;

/// `cargo tree` of `krate`'s normal dependencies, one crate per line, with `extra` arguments.
fn tree(krate: &str, extra: &[&str]) -> String {
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "--offline",
            "-e",
            "normal",
            "--prefix",
            "none",
            "-p",
            krate,
        ])
        .args(extra)
        .current_dir(scaledp_tests::workspace())
        .output()
        .expect("cargo tree");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn low_level_crates_stay_light() {
    for krate in ["scaledp-schema", "scaledp-datasets"] {
        let tree = tree(krate, &[]);
        let heavies: &[&str] = match krate {
            "scaledp-schema" => &["zenoh", "rerun", "mcap ", "tokio"],
            _ => &["zenoh", "rerun", "mcap "],
        };
        for heavy in heavies {
            assert!(
                !tree.lines().any(|l| l.starts_with(heavy)),
                "{krate} depends on {heavy}:\n{tree}"
            );
        }
    }
}

#[test]
fn rerun_stays_in_the_viewer() {
    let has = |tree: &str, name: &str| tree.lines().any(|l| l.starts_with(name));
    for krate in [
        "scaledp-schema",
        "scaledp-datasets",
        "scaledp-converter",
        "scaledp-recorder",
        "scaledp-sim",
    ] {
        assert!(
            !has(&tree(krate, &[]), "rerun "),
            "{krate} depends on rerun"
        );
    }
    assert!(has(&tree("scaledp-viewer", &[]), "rerun "));
    assert!(
        !has(&tree("scaledp", &["--no-default-features"]), "rerun "),
        "the CLI without its `view` feature still pulls in rerun"
    );
}

#[test]
fn one_arrow_is_compiled() {
    let tree = tree("scaledp", &[]);
    let mut majors: Vec<&str> = tree
        .lines()
        .filter_map(|l| l.strip_prefix("arrow-array v"))
        .filter_map(|v| v.split('.').next())
        .collect();
    majors.sort_unstable();
    majors.dedup();
    assert_eq!(
        majors.len(),
        1,
        "arrow-array majors {majors:?}: the workspace's arrow must match rerun's"
    );
}
