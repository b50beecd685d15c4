//! Helpers for scaledp's end-to-end and interop tests: the built `scaledp` binary, small rigs
//! that keep recordings tiny, synthetic episodes and messages, and checks of converted datasets.
//! The helpers the crates' own tests and the benchmarks share (the workspace root, the venv
//! Python and its scripts, free loopback endpoints, the bag fixtures) live in
//! `scaledp-testkit` and are re-exported here.

use std::path::{Path, PathBuf};
use std::process::Command;

pub mod child;
pub mod house;
pub mod s3;

pub use scaledp_testkit::{
    free_endpoint, make_bags, python, run_python, workspace_root as workspace,
};

/// The `scaledp` binary of the profile these tests were built in (`cargo build --bins` first).
pub fn scaledp_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>");
    let bin = dir.join("scaledp");
    assert!(
        bin.exists(),
        "{} is missing: cargo build --release --bins first",
        bin.display()
    );
    bin
}

/// Start of the first synthetic episode (ns); episode `seed` starts `seed` × 100 s later.
pub const T0: u64 = 1_700_000_000_000_000_000;

/// A recorder-style episode of `rig` at `path`, rendered by the simulator (task "stack the
/// cubes").
pub fn synth_episode(path: &Path, rig: &scaledp_schema::Rig, seed: u64, seconds: f64) {
    scaledp_sim::synth::write_episode(
        path,
        rig,
        seed,
        seconds,
        T0 + seed * 100_000_000_000,
        "stack the cubes",
        &mut |_, _, _, _| {},
    )
    .expect("a synthetic episode");
}

/// The Franka rig with the real topics, encodings and rates but 64×48 images, and only its
/// training streams (colour, joints, gripper: what the tests that compare every message with
/// what was published expect); [`full_rig`] keeps depth, `camera_info` and tf.
pub fn small_franka() -> scaledp_schema::Rig {
    full_rig("franka_2zed", 64, 48).training_streams()
}

/// The bimanual UR5 rig (rgb8 RealSense) with 32×24 images, training streams only.
pub fn small_bimanual() -> scaledp_schema::Rig {
    full_rig("bimanual_ur5_3rs", 32, 24).training_streams()
}

/// A shipped rig with every camera at `width` × `height`, everything it records kept.
pub fn full_rig(name: &str, width: u32, height: u32) -> scaledp_schema::Rig {
    scaledp_schema::Rig::builtin(name)
        .expect("shipped rig")
        .with_image_size(width, height)
}

/// The record batches of a dataset's first data file.
fn first_data_file(dataset: &Path) -> Vec<arrow_array::RecordBatch> {
    let file =
        std::fs::File::open(dataset.join("data/chunk-000/file-000.parquet")).expect("a data file");
    parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .expect("parquet")
        .build()
        .expect("reader")
        .map(|b| b.expect("a batch"))
        .collect()
}

/// Every row of a float32 list column (`observation.state`, `action`, ...) of a dataset's first
/// data file.
pub fn f32_rows(dataset: &Path, column: &str) -> Vec<Vec<f32>> {
    use arrow_array::{Array, FixedSizeListArray, Float32Array};
    let mut rows = Vec::new();
    for batch in first_data_file(dataset) {
        let a = batch
            .column_by_name(column)
            .unwrap_or_else(|| panic!("no column {column}"))
            .as_any()
            .downcast_ref::<FixedSizeListArray>()
            .expect("a fixed-size list")
            .clone();
        for i in 0..a.len() {
            let v = a.value(i);
            let f = v.as_any().downcast_ref::<Float32Array>().expect("float32");
            rows.push(f.values().to_vec());
        }
    }
    rows
}

/// Runs `scaledp convert ARGS -q` and returns its output.
pub fn convert_cli(args: &[&std::ffi::OsStr]) -> std::process::Output {
    Command::new(scaledp_bin())
        .arg("convert")
        .args(args)
        .arg("-q")
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("running scaledp convert: {e}"))
}

/// Checks a dataset with `check_lerobot.py` against LeRobot's own example; panics on any error.
/// Returns the script's report.
pub fn check_dataset(ds: &Path) -> serde_json::Value {
    let v = run_python(
        "check_lerobot.py",
        &[ds, &workspace().join("tests/fixtures/lerobot_v3_example")],
    );
    assert_eq!(v["errors"], serde_json::json!([]), "{}", ds.display());
    v
}

/// Writes `rig` as `<dir>/<name>.toml` and returns the path.
pub fn write_rig_file(dir: &Path, rig: &scaledp_schema::Rig) -> PathBuf {
    let p = dir.join(format!("{}.toml", rig.name));
    std::fs::write(&p, toml::to_string(rig).expect("rig TOML")).expect("a rig file");
    p
}

/// A JSON file, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Message `k` of `topic` as a publisher of [`small_franka`] could send it: a 64×48 bgra8
/// image filled with `k`, or a one-joint state at `k`; stamped `k` ms after [`T0`], so every
/// message of a topic is distinct.
pub fn numbered_message(topic: &scaledp_schema::rig::TopicSpec, k: u64) -> Vec<u8> {
    use scaledp_schema::msg::{Header, Image, JointState, Time};
    use scaledp_schema::RosMessage;
    let header = Header {
        stamp: Time::from_ns(T0 + k * 1_000_000),
        frame_id: String::new(),
    };
    if topic.is_image {
        Image {
            header,
            height: 48,
            width: 64,
            encoding: "bgra8".into(),
            is_bigendian: 0,
            step: 64 * 4,
            data: vec![k as u8; 64 * 48 * 4],
        }
        .to_cdr()
    } else {
        JointState {
            header,
            name: vec!["j".into()],
            position: vec![k as f64],
            velocity: vec![0.0],
            effort: vec![],
        }
        .to_cdr()
    }
}

/// Runs `scaledp convert ARGS -q`, asserts it succeeded with `converted` ("1 converted", ...) in
/// its summary, and returns its stdout.
pub fn convert_ok(args: &[&std::ffi::OsStr], converted: &str) -> String {
    let out = convert_cli(args);
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success() && stdout.contains(converted),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

/// Every value of a float32 scalar column (`timestamp`, ...) of a dataset's first data file.
pub fn f32_column(dataset: &Path, column: &str) -> Vec<f32> {
    use arrow_array::{Array, Float32Array};
    let mut out = Vec::new();
    for batch in first_data_file(dataset) {
        let a = batch
            .column_by_name(column)
            .unwrap_or_else(|| panic!("no column {column}"));
        let a = a.as_any().downcast_ref::<Float32Array>().expect("float32");
        out.extend((0..a.len()).map(|i| a.value(i)));
    }
    out
}

/// The `scaledp.episode` metadata record of a recorded episode.
pub fn episode_metadata(path: &Path) -> std::collections::BTreeMap<String, String> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let summary = mcap::Summary::read(&bytes)
        .expect("an MCAP file")
        .expect("a summary section");
    let idx = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == scaledp_schema::episode::END_RECORD)
        .expect("an end-of-episode metadata record");
    mcap::read::metadata(&bytes, idx)
        .expect("a metadata record")
        .metadata
}

/// Waits until `path` exists, at most `limit` (polled every 20 ms).
///
/// # Panics
/// When it does not appear in time, saying `what` was awaited.
pub fn await_file(path: &std::path::Path, limit: std::time::Duration, what: &str) {
    let deadline = std::time::Instant::now() + limit;
    while !path.exists() {
        assert!(std::time::Instant::now() < deadline, "{what}");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Runs the `scaledp` binary with `args` in `cwd`, its standard input closed.
pub fn run_scaledp(args: &[&str], cwd: &Path) -> std::process::Output {
    std::process::Command::new(scaledp_bin())
        .args(args)
        .current_dir(cwd)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", scaledp_bin().display()))
}

/// The standard output of `out`, which must have succeeded (else the test fails with `what`,
/// its exit status, its standard error (where the reason is) and then its standard output).
pub fn cli_ok(out: &std::process::Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what} ({}); its standard error:\n{}\nits standard output:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// One `scaledp eval --live` episode (validation split) of the run `run`, `seconds` long, from
/// `cwd`, with `extra` arguments (controller options): its report, checked to be a live one.
pub fn live_episode(cwd: &Path, run: &str, seconds: &str, extra: &[&str]) -> serde_json::Value {
    let report = cwd.join("live.json");
    let mut args = vec![
        "eval",
        run,
        "--live",
        "--episodes",
        "1",
        "--split",
        "val",
        "--max-seconds",
        seconds,
        "--report",
        report.to_str().unwrap_or("live.json"),
    ];
    args.extend_from_slice(extra);
    let out = cli_ok(&run_scaledp(&args, cwd), "eval --live");
    let r = read_json(&report);
    assert_eq!(r["mode"], "live", "{out}\n{r}");
    r
}

/// A column of a dataset's episodes table (`meta/episodes/chunk-000/file-000.parquet`), as JSON
/// values: strings, booleans, float64 and int64; a null is `Null`.
pub fn episode_column(ds: &Path, column: &str) -> Vec<serde_json::Value> {
    use arrow_array::cast::AsArray;
    use arrow_array::types::{Float64Type, Int64Type};
    use arrow_array::Array;
    use arrow_schema::DataType;
    let path = ds.join("meta/episodes/chunk-000/file-000.parquet");
    let file = std::fs::File::open(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .and_then(|b| b.build())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut out = Vec::new();
    for batch in reader {
        let batch = batch.unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let a = batch
            .column_by_name(column)
            .unwrap_or_else(|| panic!("no episode column {column}"));
        let value = |i: usize| -> serde_json::Value {
            if a.is_null(i) {
                return serde_json::Value::Null;
            }
            match a.data_type() {
                DataType::Utf8 => a.as_string::<i32>().value(i).into(),
                DataType::Boolean => a.as_boolean().value(i).into(),
                DataType::Float64 => a.as_primitive::<Float64Type>().value(i).into(),
                DataType::Int64 => a.as_primitive::<Int64Type>().value(i).into(),
                t => panic!("episode column {column}: {t}"),
            }
        };
        out.extend((0..a.len()).map(value));
    }
    out
}
