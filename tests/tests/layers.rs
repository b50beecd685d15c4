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

/// No circle of imports between the files of a crate's main path: a reader can take a crate's
/// files in an order where each one only uses what came before.
#[test]
fn no_import_circle_between_files() {
    let circles = scaledp_tests::house::import_circles(&scaledp_tests::workspace());
    assert!(
        circles.is_empty(),
        "{} import circles:\n{}",
        circles.len(),
        circles.join("\n")
    );
}

/// No source file over 500 lines (tests included): a long file is a module that wants splitting.
#[test]
fn no_file_over_500_lines() {
    let long = scaledp_tests::house::long_files(&scaledp_tests::workspace(), 500);
    assert!(
        long.is_empty(),
        "files over 500 lines:\n{}",
        long.join("\n")
    );
}
