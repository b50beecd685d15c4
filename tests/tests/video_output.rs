//! `convert --video av1|h264`: cameras stored as LeRobot v3 video features. The dataset holds
//! the same rows as its JPEG twin, the MP4 layout and metadata LeRobot expects, and LeRobot
//! 0.4.4 itself (`LeRobotDataset`, pyav backend) returns, for every frame of every camera,
//! exactly the pixels our loader returns — across two video files (a second run appends to a
//! dataset whose first file is closed). Bad settings fail their input with one line.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::Path;

use crate::convert_common::{convert_cli, convert_ok};
use scaledp_datasets::LoaderOptions;
use scaledp_testkit::lerobot_video;
use scaledp_tests::{f32_rows, small_franka, synth_episode};

const CAMERAS: [&str; 2] = ["observation.images.front", "observation.images.wrist"];
const SIZE: (usize, usize) = (64, 48);

/// Every frame of `dataset` as our loader returns it, in index order: (episode, frame) and
/// per camera (sorted) H×W×3 RGB.
fn our_frames(dataset: &Path) -> (Vec<(i64, i64)>, Vec<Vec<u8>>) {
    let keys: Vec<String> = CAMERAS.iter().map(|s| s.to_string()).collect();
    let mut l = LoaderOptions::default()
        .obs_horizon(1)
        .action_chunk(1)
        .shuffle(false)
        .batch_size(4096)
        .cameras(keys.clone())
        .open(dataset.to_str().unwrap())
        .unwrap();
    let b = l.next_batch().unwrap().unwrap();
    let plane = SIZE.0 * SIZE.1;
    let mut index = Vec::new();
    let mut frames = Vec::new();
    for i in 0..b.len {
        index.push((b.episode_index[i], b.frame_index[i]));
        for c in 0..keys.len() {
            let chw = &b.images[(i * keys.len() + c) * 3 * plane..][..3 * plane];
            frames.push(
                (0..3 * plane)
                    .map(|j| chw[(j % 3) * plane + j / 3])
                    .collect(),
            );
        }
    }
    let mut order: Vec<usize> = (0..index.len()).collect();
    order.sort_by_key(|&i| index[i]);
    let frames = order
        .iter()
        .flat_map(|&i| frames[i * keys.len()..][..keys.len()].to_vec())
        .collect();
    (order.iter().map(|&i| index[i]).collect(), frames)
}

fn mean_abs_diff(a: &[u8], b: &[u8]) -> f64 {
    let sum: u64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| u64::from(p.abs_diff(*q)))
        .sum();
    sum as f64 / a.len() as f64
}

fn episodes(dir: &Path, name: &str, seeds: &[u64]) -> std::path::PathBuf {
    let rec = dir.join(name);
    std::fs::create_dir_all(&rec).unwrap();
    for &seed in seeds {
        synth_episode(
            &rec.join(format!("episode_{seed:06}.mcap")),
            &small_franka(),
            seed,
            3.0,
        );
    }
    rec
}

fn convert(rec: &Path, out: &Path, extra: &[&str], converted: &str) {
    let mut args: Vec<&std::ffi::OsStr> = vec![rec.as_os_str(), "--out".as_ref(), out.as_os_str()];
    args.extend(["--size", "64x48"].iter().map(std::ffi::OsStr::new));
    args.extend(extra.iter().map(std::ffi::OsStr::new));
    convert_ok(&args, converted);
}

fn video_dataset_matches_its_jpeg_twin_and_lerobot(codec: &str, bound: f64) {
    let dir = tempfile::tempdir().unwrap();
    let first = episodes(dir.path(), "first", &[4, 5]);
    let second = episodes(dir.path(), "second", &[6]);
    let (images, video) = (dir.path().join("images"), dir.path().join("video"));
    for rec in [&first, &second] {
        convert(rec, &images, &[], "converted");
        // A run reopening the dataset starts a new video file: the third episode is in file 1.
        convert(rec, &video, &["--video", codec], "converted");
    }

    // Layout and metadata.
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(video.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(
        info["video_path"],
        "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    );
    for key in CAMERAS {
        let f = &info["features"][key];
        assert_eq!(f["dtype"], "video", "{key}: {f}");
        assert_eq!(f["shape"], serde_json::json!([48, 64, 3]), "{key}");
        assert_eq!(f["info"]["video.codec"], codec, "{key}");
        assert_eq!(f["info"]["video.pix_fmt"], "yuv420p", "{key}");
        for file in 0..2 {
            let mp4 = video.join(format!("videos/{key}/chunk-000/file-{file:03}.mp4"));
            assert!(mp4.exists(), "{}", mp4.display());
        }
    }
    let names: Vec<String> = {
        use parquet::file::reader::{FileReader, SerializedFileReader};
        let file = std::fs::File::open(video.join("data/chunk-000/file-000.parquet")).unwrap();
        let r = SerializedFileReader::new(file).unwrap();
        let fields = r.metadata().file_metadata().schema().get_fields();
        fields.iter().map(|f| f.name().to_string()).collect()
    };
    assert!(
        names.iter().all(|n| !n.starts_with("observation.images.")),
        "image columns beside video features: {names:?}"
    );
    for column in ["observation.state", "action"] {
        assert_eq!(
            f32_rows(&images, column),
            f32_rows(&video, column),
            "{column}"
        );
    }

    // Pixels: within the codec's loss of the JPEG twin's (the same resized frames at q90):
    // the worst frame measured 6.10 levels on average for H.264, 6.23 for AV1.
    let (index, ours) = our_frames(&video);
    let (twin_index, twin) = our_frames(&images);
    assert_eq!(index, twin_index);
    assert!(
        index.iter().filter(|(e, _)| *e == 2).count() >= 20,
        "{index:?}"
    );
    let worst = ours
        .iter()
        .zip(&twin)
        .map(|(a, b)| mean_abs_diff(a, b))
        .fold(0.0, f64::max);
    eprintln!("{codec}: the worst frame is {worst:.2} levels from its JPEG twin on average");
    assert!(worst < bound, "{codec}: a frame is {worst:.2} levels off");

    // LeRobot 0.4.4 reads the dataset unchanged, and its pixels are ours, bit for bit.
    let bin = dir.path().join("frames.bin");
    let theirs = lerobot_video(
        &["read", video.to_str().unwrap(), bin.to_str().unwrap()],
        dir.path(),
    );
    let frames = std::fs::read(&bin).unwrap();
    let n = theirs["frames"].as_u64().unwrap() as usize;
    assert_eq!(n, index.len());
    assert_eq!(theirs["keys"], serde_json::json!(CAMERAS));
    let per = SIZE.0 * SIZE.1 * 3;
    for i in 0..n {
        let at = (
            theirs["episode_index"][i].as_i64().unwrap(),
            theirs["frame_index"][i].as_i64().unwrap(),
        );
        let k = index.iter().position(|&x| x == at).unwrap();
        for c in 0..CAMERAS.len() {
            let lerobot = &frames[(i * CAMERAS.len() + c) * per..][..per];
            let max = ours[k * CAMERAS.len() + c]
                .iter()
                .zip(lerobot)
                .map(|(p, q)| p.abs_diff(*q))
                .max()
                .unwrap();
            assert_eq!(
                max, 0,
                "{at:?} {}: LeRobot's pixels differ by {max}",
                CAMERAS[c]
            );
        }
    }
}

#[test]
fn h264_video_features_match_their_jpeg_twin_and_lerobot_reads_them_as_we_do() {
    video_dataset_matches_its_jpeg_twin_and_lerobot("h264", 9.0);
}

#[test]
fn av1_video_features_match_their_jpeg_twin_and_lerobot_reads_them_as_we_do() {
    video_dataset_matches_its_jpeg_twin_and_lerobot("av1", 9.0);
}

#[test]
fn video_settings_that_cannot_work_fail_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let rec = episodes(dir.path(), "rec", &[4]);
    // H.264 4:2:0 needs even sides: the input fails, naming the file and the camera.
    let out = convert_cli(&[
        rec.as_os_str(),
        "--out".as_ref(),
        dir.path().join("odd").as_os_str(),
        "--size".as_ref(),
        "63x47".as_ref(),
        "--video".as_ref(),
        "h264".as_ref(),
    ]);
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{text}");
    assert!(
        text.contains("episode_000004.mcap")
            && text.contains("camera 'front'")
            && text.contains("even"),
        "{text}"
    );
    // Video into a dataset of JPEG images: refused, the dataset unchanged.
    let images = dir.path().join("images");
    convert(&rec, &images, &[], "1 converted");
    let before = std::fs::read(images.join("meta/info.json")).unwrap();
    let more = episodes(dir.path(), "more", &[5]);
    let out = convert_cli(&[
        more.as_os_str(),
        "--out".as_ref(),
        images.as_os_str(),
        "--size".as_ref(),
        "64x48".as_ref(),
        "--video".as_ref(),
        "av1".as_ref(),
    ]);
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(
        text.contains("cameras as av1 video, the dataset has them as JPEG images"),
        "{text}"
    );
    assert_eq!(
        std::fs::read(images.join("meta/info.json")).unwrap(),
        before
    );
}
