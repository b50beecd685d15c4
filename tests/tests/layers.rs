//! The layering rule: `schema` and `datasets` never pull in zenoh or rerun.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::process::Command;

#[test]
fn low_level_crates_stay_light() {
    for krate in ["scaledp-schema", "scaledp-datasets"] {
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
            .current_dir(scaledp_tests::workspace())
            .output()
            .expect("cargo tree");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let tree = String::from_utf8_lossy(&out.stdout);
        for heavy in ["zenoh", "rerun", "mcap ", "tokio"] {
            assert!(
                !tree.lines().any(|l| l.starts_with(heavy)),
                "{krate} depends on {heavy}:\n{tree}"
            );
        }
    }
}
