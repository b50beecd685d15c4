//! LeRobot 0.4.4 (the venv of `scripts/setup-bench-python.sh`) opens a dataset with depth and
//! intrinsics: `LeRobotDataset` returns each depth feature as a tensor of the stored shape
//! holding exactly the stored values (holes as 0 and NaN), keeps depth out of its camera keys,
//! and its `meta.info` carries the intrinsics; its `meta.episodes` holds the episode's task,
//! operator, label and verdict.

use std::path::Path;
use std::process::Command;

use scaledp_tests::workspace;

use super::recording::{OPERATOR, TASK, VERDICT_LINE};

/// Runs `tests/py/lerobot_depth.py` on `ds` with LeRobot's Python; its report.
fn lerobot_depth(ds: &Path, bin: &Path, home: &Path) -> serde_json::Value {
    let py = scaledp_testkit::BENCH_VENV
        .python(None, Some(&workspace()))
        .unwrap_or_else(|e| panic!("{e} (scripts/test.sh does)"));
    let out = Command::new(py)
        .arg(workspace().join("tests/py/lerobot_depth.py"))
        .args([ds, bin])
        .env("HF_HOME", home)
        .env("HF_HUB_OFFLINE", "1")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "lerobot_depth.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(stdout.lines().last().unwrap_or_default())
        .unwrap_or_else(|e| panic!("lerobot_depth.py printed no JSON ({e}): {stdout}"))
}

/// `ds` holds the wrist depth `mm` and front depth `m` (one row per frame, index order).
pub fn opens_depth_and_intrinsics(ds: &Path, dir: &Path, mm: &[Vec<u16>], m: &[Vec<f32>]) {
    let bin = dir.join("depth.bin");
    let home = dir.join("hf");
    let theirs = lerobot_depth(ds, &bin, &home);
    assert_eq!(
        theirs["keys"],
        serde_json::json!(["observation.depth.front", "observation.depth.wrist"])
    );
    assert_eq!(
        theirs["camera_keys"],
        serde_json::json!(["observation.images.front", "observation.images.wrist"])
    );
    for k in ["observation.depth.front", "observation.depth.wrist"] {
        assert_eq!(theirs["shapes"][k], serde_json::json!([24, 32]), "{k}");
    }
    assert_eq!(
        theirs["intrinsics"]["wrist"],
        serde_json::json!([30.0, 0.0, 15.75, 0.0, 30.5, 11.875, 0.0, 0.0, 1.0])
    );
    let n = theirs["frames"].as_u64().unwrap() as usize;
    assert_eq!(n, mm.len());
    let bytes = std::fs::read(&bin).unwrap();
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let plane = 24 * 32;
    assert_eq!(values.len(), n * 2 * plane);
    for i in 0..n {
        let f = theirs["frame_index"][i].as_u64().unwrap() as usize;
        let front = &values[(2 * i) * plane..][..plane];
        let wrist = &values[(2 * i + 1) * plane..][..plane];
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        assert!(
            front.iter().zip(&m[f]).all(|(&a, &b)| same(a, b)),
            "frame {f}: LeRobot's front depth differs from the stored values"
        );
        assert!(
            wrist.iter().zip(&mm[f]).all(|(&a, &b)| a == f32::from(b)),
            "frame {f}: LeRobot's wrist depth differs from the stored millimetres"
        );
    }
    // The episode's metadata columns, as LeRobot loads meta/episodes.
    let eps = &theirs["episodes"];
    let one = |v: &str| serde_json::json!([v]);
    assert_eq!(eps["tasks"], serde_json::json!([[TASK]]));
    assert_eq!(eps["scaledp/operator"], one(OPERATOR));
    assert_eq!(eps["scaledp/label"], one("success"));
    assert_eq!(eps["scaledp/verdict"], one(VERDICT_LINE));
    assert_eq!(eps["scaledp/verdict_by"], one("record"));
    assert_eq!(eps["scaledp/verdict_accepted"], serde_json::json!([true]));
    assert_eq!(eps["scaledp/verdict_reason"], serde_json::json!([null]));
    eprintln!(
        "LeRobot returns depth as {} (wrist) and {} (front)",
        theirs["dtypes"]["observation.depth.wrist"], theirs["dtypes"]["observation.depth.front"]
    );
}
