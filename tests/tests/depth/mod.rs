//! Depth and intrinsics through `scaledp convert`, the loader and LeRobot: a recording with
//! registered depth (raw 16UC1 and `compressedDepth` 32FC1) and `camera_info` (see
//! [`recording`]) becomes `observation.depth.<camera>` features holding exactly the published
//! values resized by nearest neighbour (holes kept), intrinsics scaled to the stored size in
//! `info.json`, a warning for a camera_info of another size; an episode whose depth is not in
//! the declared encoding fails alone; the loader yields the depth with its unit; LeRobot 0.4.4
//! opens the dataset and returns the same depth, and the episode's task, operator, label and
//! recorder's verdict from `meta/episodes/`.
#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

mod lerobot;
mod recording;

use std::ffi::OsStr;
use std::path::Path;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, UInt16Type};
use arrow_array::Array;
use scaledp_datasets::LoaderOptions;
use scaledp_tests::{check_dataset, convert_cli, read_json, write_rig_file};

use recording::{colour_level, front_m, front_q, wrist_mm, H, W};

/// Stored size: half the recorded one.
const SW: u32 = 32;
const SH: u32 = 24;

/// The source pixel nearest-neighbour resizing takes for stored pixel `i` of `to` (from
/// `from`): the one under its centre.
fn nearest(i: u32, from: u32, to: u32) -> u32 {
    ((2 * i + 1) * from) / (2 * to)
}

/// Every row's values of a depth column `list<list<T>>`, flattened row-major.
fn depth_rows<T: arrow_array::ArrowPrimitiveType>(ds: &Path, key: &str) -> Vec<Vec<T::Native>> {
    let file = std::fs::File::open(ds.join("data/chunk-000/file-000.parquet")).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap();
    let mut out = Vec::new();
    for batch in reader {
        let batch = batch.unwrap();
        let col = batch.column_by_name(key).unwrap().as_list::<i32>().clone();
        for r in 0..col.len() {
            let rows = col.value(r);
            let rows = rows.as_list::<i32>();
            assert_eq!(rows.len(), SH as usize);
            // The child values of this row alone (`values()` is the whole column's).
            let offsets = rows.value_offsets();
            let (first, last) = (offsets[0] as usize, offsets[rows.len()] as usize);
            let v = rows.values().slice(first, last - first);
            let v = v.as_primitive::<T>();
            assert_eq!(v.len(), (SW * SH) as usize);
            out.push(v.values().to_vec());
        }
    }
    out
}

/// The frame index whose resized depth `row` is, checked value by value (`f` makes frame k's
/// expected values).
fn frame_of<V: PartialEq + Copy>(
    row: &[V],
    f: impl Fn(u64, u32, u32) -> V,
    same: impl Fn(V, V) -> bool,
) -> u64 {
    (0..200)
        .find(|&k| {
            (0..SH).all(|y| {
                (0..SW).all(|x| {
                    let want = f(k, nearest(x, W, SW), nearest(y, H, SH));
                    same(row[(y * SW + x) as usize], want)
                })
            })
        })
        .unwrap_or_else(|| panic!("a stored depth frame equals no published frame resized"))
}

fn convert(inputs: &[&Path], out: &Path, rig: &Path) -> std::process::Output {
    let mut args: Vec<&OsStr> = inputs.iter().map(|p| p.as_os_str()).collect();
    args.extend([
        OsStr::new("--out"),
        out.as_os_str(),
        OsStr::new("--rig"),
        rig.as_os_str(),
    ]);
    args.extend(
        ["--size", "32x24", "--unlabeled", "keep"]
            .iter()
            .map(OsStr::new),
    );
    convert_cli(&args)
}

#[test]
fn depth_and_intrinsics_are_converted_exactly_and_loaded_with_their_unit() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    std::fs::create_dir_all(&rec).unwrap();
    let good = rec.join("episode_000000.mcap");
    let bad = rec.join("episode_000001.mcap");
    recording::write(&good, 3.0, "16UC1");
    recording::write(&bad, 3.0, "32FC1");
    let rig = write_rig_file(dir.path(), &recording::rig("16UC1"));
    let ds = dir.path().join("ds");
    let out = convert(&[&good, &bad], &ds, &rig);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    // One bad episode fails alone, in one line naming the topic and both encodings.
    assert!(
        stdout.contains("1 converted") && stdout.contains("1 failed"),
        "{stdout}\n{stderr}"
    );
    let failed: Vec<&str> = stdout
        .lines()
        .filter(|l| l.starts_with("failed:"))
        .collect();
    assert_eq!(failed.len(), 1, "{stdout}");
    assert!(
        failed[0].contains("episode_000001.mcap")
            && failed[0].contains("/camera/aligned_depth_to_color/image_raw")
            && failed[0].contains("32FC1 images, the rig declares 16UC1"),
        "{}",
        failed[0]
    );
    // A camera_info of another size: one warning line per episode, naming its file, the topic
    // and both sizes.
    let warned: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("/zed/zed_node/rgb/color/rect/camera_info"))
        .collect();
    assert_eq!(warned.len(), 2, "{stderr}");
    for file in ["episode_000000.mcap", "episode_000001.mcap"] {
        let line = warned.iter().find(|l| l.contains(file));
        assert!(
            line.is_some_and(
                |l| l.contains("is 1280×720, the images are 64×48: intrinsics left out")
            ),
            "{file}: {stderr}"
        );
    }

    // info.json: the features, and intrinsics scaled by 1/2 under scaledp.cameras.
    let info = read_json(&ds.join("meta/info.json"));
    let f = &info["features"];
    assert_eq!(
        f["observation.depth.wrist"],
        serde_json::json!({"dtype": "uint16", "shape": [24, 32], "names": ["height", "width"]})
    );
    assert_eq!(f["observation.depth.front"]["dtype"], "float32");
    let cams = &info["scaledp"]["cameras"];
    let k = &cams["wrist"]["intrinsics"]["k"];
    assert_eq!(
        k,
        &serde_json::json!([30.0, 0.0, 15.75, 0.0, 30.5, 11.875, 0.0, 0.0, 1.0])
    );
    let wrist = &cams["wrist"]["intrinsics"];
    assert_eq!(
        (wrist["width"].as_u64(), wrist["height"].as_u64()),
        (Some(32), Some(24))
    );
    assert_eq!(
        (
            wrist["source_width"].as_u64(),
            wrist["source_height"].as_u64()
        ),
        (Some(64), Some(48))
    );
    assert_eq!(
        wrist["d"],
        serde_json::json!([0.12, -0.25, 0.001, -0.002, 0.05])
    );
    assert_eq!(wrist["distortion_model"], "plumb_bob");
    assert_eq!(cams["wrist"]["depth"]["intrinsics"]["k"], *k);
    assert_eq!(cams["wrist"]["depth"]["unit"], "mm");
    assert_eq!(cams["front"]["depth"]["unit"], "m");
    assert!(
        cams["front"].get("intrinsics").is_none(),
        "{}",
        cams["front"]
    );
    check_dataset(&ds);

    // The stored depth: exactly the published frames resized by nearest neighbour, holes kept,
    // the frame each tick picked the one captured with the colour frame it picked.
    let mm = depth_rows::<UInt16Type>(&ds, "observation.depth.wrist");
    let m = depth_rows::<Float32Type>(&ds, "observation.depth.front");
    assert!(mm.len() > 20, "{} frames", mm.len());
    let mut holes = (0, 0);
    let mut ks = Vec::new();
    for (row_mm, row_m) in mm.iter().zip(&m) {
        let k = frame_of(row_mm, wrist_mm, |a, b| a == b);
        let kf = frame_of(
            row_m,
            |k, x, y| front_m(front_q(k, x, y)),
            |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
        );
        assert_eq!(k, kf, "both cameras' depth from the same capture");
        holes.0 += row_mm.iter().filter(|&&v| v == 0).count();
        holes.1 += row_m.iter().filter(|v| v.is_nan()).count();
        ks.push(k);
    }
    assert!(holes.0 > 0 && holes.1 > 0, "holes kept: {holes:?}");
    assert!(
        ks.windows(2).all(|w| w[1] == w[0] + 3),
        "30 Hz frames at 10 Hz ticks: {ks:?}"
    );

    // The loader yields the same depth, opt-in, with its unit; the colour frame beside each
    // depth frame is the one captured with it.
    let mut l = LoaderOptions::default()
        .obs_horizon(1)
        .action_chunk(1)
        .shuffle(false)
        .batch_size(4096)
        .depth(true)
        .open(ds.to_str().unwrap())
        .unwrap();
    let info = l.info().clone();
    assert_eq!(
        info.depth_cameras,
        vec!["observation.depth.front", "observation.depth.wrist"]
    );
    assert_eq!(info.depth_units, vec!["m", "mm"]);
    let (b, depth) = l.next_with_depth().unwrap().unwrap();
    let depth = depth.unwrap();
    assert_eq!(
        (depth.cameras.clone(), depth.units.clone()),
        (info.depth_cameras.clone(), info.depth_units.clone())
    );
    assert_eq!((depth.width, depth.height), (SW, SH));
    assert_eq!(b.len, mm.len());
    let plane = (SW * SH) as usize;
    let cams = b.cameras.len();
    for i in 0..b.len {
        let f = b.frame_index[i] as usize;
        let got = |d: usize| &depth.values[(i * 2 + d) * plane..][..plane];
        assert!(got(0)
            .iter()
            .zip(&m[f])
            .all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())));
        assert!(got(1).iter().zip(&mm[f]).all(|(a, &b)| *a == f32::from(b)));
        let wrist = b
            .cameras
            .iter()
            .position(|c| c == "observation.images.wrist")
            .unwrap();
        let r = b.images[(i * cams + wrist) * 3 * plane];
        assert!(
            r.abs_diff(colour_level(ks[f])) <= 2,
            "frame {f}: colour {r} vs k {}",
            ks[f]
        );
    }
    // Without depth(true), nothing of it is read.
    let mut plain = LoaderOptions::default()
        .obs_horizon(1)
        .action_chunk(1)
        .batch_size(8)
        .open(ds.to_str().unwrap())
        .unwrap();
    let (_, none) = plain.next_with_depth().unwrap().unwrap();
    assert!(none.is_none() && plain.info().depth_cameras.is_empty());

    lerobot::opens_depth_and_intrinsics(&ds, dir.path(), &mm, &m);
}

/// What depth costs: a 10 s recording of two 640×480 cameras with depth, converted at
/// 320×240 with and without it (seconds, frames/s, bytes per depth frame in the data file).
/// `cargo test --release -p scaledp-tests --test e2e -- depth:: --ignored --nocapture`
#[test]
#[ignore = "a measurement, not a check"]
fn measure_depth_conversion() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("episode_000000.mcap");
    recording::write_sized(&rec, 10.0, "16UC1", (640, 480));
    let rig = write_rig_file(dir.path(), &recording::rig_sized("16UC1", (640, 480)));
    let mut sizes = Vec::new();
    for (name, extra) in [("with depth", None), ("without depth", Some("--no-depth"))] {
        let ds = dir.path().join(name.replace(' ', "_"));
        let mut args: Vec<&OsStr> = vec![rec.as_os_str(), "--out".as_ref(), ds.as_os_str()];
        args.extend([
            "--rig".as_ref(),
            rig.as_os_str(),
            "--jobs".as_ref(),
            "1".as_ref(),
            "--unlabeled".as_ref(),
            "keep".as_ref(),
        ]);
        args.extend(extra.iter().map(OsStr::new));
        let start = std::time::Instant::now();
        let out = convert_cli(&args);
        let secs = start.elapsed().as_secs_f64();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let frames = read_json(&ds.join("meta/info.json"))["total_frames"]
            .as_u64()
            .unwrap();
        let bytes = std::fs::metadata(ds.join("data/chunk-000/file-000.parquet"))
            .unwrap()
            .len();
        eprintln!(
            "{name}: {secs:.2} s, {:.1} frames/s, data file {bytes} bytes for {frames} frames",
            frames as f64 / secs
        );
        sizes.push((bytes, frames));
    }
    let _ = sizes;
    let file = std::fs::File::open(
        dir.path()
            .join("with_depth/data/chunk-000/file-000.parquet"),
    )
    .unwrap();
    let r = parquet::file::reader::SerializedFileReader::new(file).unwrap();
    use parquet::file::reader::FileReader;
    let md = r.metadata();
    for key in [
        "observation.depth.wrist",
        "observation.depth.front",
        "observation.images.wrist",
    ] {
        let mut bytes = 0;
        for rg in md.row_groups() {
            for c in rg.columns() {
                if c.column_path().string().starts_with(key) {
                    bytes += c.compressed_size();
                }
            }
        }
        let rows = md.file_metadata().num_rows();
        eprintln!(
            "{key}: {} bytes per frame at 320×240 (raw {} ), {rows} frames",
            bytes / rows,
            320 * 240 * if key.ends_with("front") { 4 } else { 2 }
        );
    }
}
