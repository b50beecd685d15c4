//! The layering rule: `schema` and `datasets` never pull in zenoh, rerun or mcap; `schema` no
//! async runtime either (`datasets` has tokio only as the runtime of object_store's S3 client).

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
