//! `scaledp bench load` in its smallest configuration and `scaledp demo` end to end (simulated
//! rig → recorder → converter → one loader epoch), both through the real binary.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::process::{Command, Stdio};

use scaledp_tests::{scaledp_bin, small_franka};

fn figure(line: &str, column: usize) -> f64 {
    line.split_whitespace()
        .nth(column)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no figure in column {column} of '{line}'"))
}

#[test]
fn bench_load_smallest_configuration_prints_every_row() {
    let dir = tempfile::tempdir().unwrap();
    let run = || {
        Command::new(scaledp_bin())
            .args([
                "bench",
                "load",
                "--episodes",
                "2",
                "--seconds",
                "2",
                "--no-python",
                "-q",
            ])
            .arg("--dir")
            .arg(dir.path())
            .stdin(Stdio::null())
            .output()
            .unwrap()
    };
    let out = run();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let row = |name: &str| {
        stdout
            .lines()
            .find(|l| l.starts_with(name))
            .unwrap_or_else(|| panic!("no '{name}' row in:\n{stdout}"))
    };
    // 2 episodes × 2 s at 10 Hz: about 40 samples, each To 2 × 3 cameras = 6 images.
    let ours = row("scaledp loader");
    let samples = figure(ours, 2);
    assert!((30.0..=40.0).contains(&samples), "{ours}");
    assert!(figure(ours, 5) > 0.0 && figure(ours, 7) > 0.0, "{ours}");
    assert!(figure(row("pure JPEG decode"), 7) > 0.0);
    // The streaming run reads 4 copies: 4 × the samples.
    assert_eq!(figure(row("loader streaming"), 3), 4.0 * samples);
    for line in ["decode ratio: ", "streaming: ", "LeRobot baseline: none"] {
        row(line);
    }
    assert!(stdout.contains("generated in"), "{stdout}");
    // The second run reuses the cached datasets.
    let again = run();
    assert!(again.status.success());
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(stdout.contains("reused from the cache"), "{stdout}");
}

#[test]
fn demo_records_converts_and_loads_one_epoch() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("small_franka.toml");
    std::fs::write(&rig, toml::to_string(&small_franka()).unwrap()).unwrap();
    let out = Command::new(scaledp_bin())
        .args([
            "demo",
            "--episodes",
            "2",
            "--duration",
            "3",
            "--batch-size",
            "8",
            // Two steps show the training and predict path as well as the README's thirty do
            // (those took ~30 s of this test's 42).
            "--train-steps",
            "2",
        ])
        .arg("--rig")
        .arg(&rig)
        .arg("--out")
        .arg(dir.path().join("demo"))
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("converted 2 of 2 episodes"), "{stdout}");
    let loader = stdout
        .lines()
        .find(|l| l.starts_with("loader: 2 episodes"))
        .unwrap_or_else(|| panic!("no loader summary in:\n{stdout}"));
    // 2 × 3 s at 10 Hz, ends trimmed to valid ticks: every frame is a sample.
    let frames: usize = loader.split_whitespace().nth(3).unwrap().parse().unwrap();
    let samples: usize = loader.split_whitespace().nth(5).unwrap().parse().unwrap();
    assert!((40..=60).contains(&frames), "{loader}");
    assert_eq!(samples, frames, "{loader}");
    // 64×48 cameras come out at the converter's default 320×240.
    assert!(
        loader.contains("images [8, 2, 2, 3, 240, 320] u8"),
        "{loader}"
    );
    assert!(dir.path().join("demo/dataset/meta/info.json").is_file());
    // Then a short ScaleDP-Ti run on that dataset, its checkpoint read back by one `predict`.
    let trained = stdout
        .lines()
        .find(|l| l.starts_with("trained ScaleDP-Ti for 2 steps"))
        .unwrap_or_else(|| panic!("no training summary in:\n{stdout}"));
    let checkpoint = trained.rsplit("checkpoint ").next().unwrap();
    assert!(
        std::path::Path::new(checkpoint)
            .join("config.json")
            .is_file(),
        "{trained}"
    );
    assert!(
        stdout
            .lines()
            .any(|l| l.starts_with("predict: episode 0, ")),
        "{stdout}"
    );
}
