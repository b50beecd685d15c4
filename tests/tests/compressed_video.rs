//! Compressed cameras end to end: the simulated rig publishes its cameras as H.264
//! (`foxglove_msgs/msg/CompressedVideo`, what `sim --camera-codec h264` does), `scaledp record`
//! records them, is killed with SIGKILL mid-episode, `scaledp recover` repairs the file — and
//! every camera's recorded stream starts at a keyframe and decodes frame by frame to the
//! camera's size, up to the last frame that survived. And `convert` reads such recordings:
//! an H.264 episode converts to the dataset of its raw-image twin (same states, actions and
//! frame choice; pictures within the codec's loss).

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::convert_common::convert_ok;
use scaledp_recorder::net;
use scaledp_schema::msg::CompressedVideo;
use scaledp_schema::RosMessage;
use scaledp_sim::SimOptions;
use scaledp_tests::{f32_rows, free_endpoint, scaledp_bin, small_franka, synth_episode};

#[test]
fn h264_cameras_record_recover_and_decode() {
    let mut rig = small_franka();
    for c in &mut rig.cameras {
        c.encoding = Some("h264".into());
    }
    let endpoint = free_endpoint();
    let sim_session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let sim = SimOptions::new(rig.clone())
        .seed(3)
        .spawn(&sim_session)
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let rig_path = dir.path().join("rig.toml");
    std::fs::write(&rig_path, toml::to_string(&rig).unwrap()).unwrap();
    let out = dir.path().join("rec");
    let mut child = Command::new(scaledp_bin())
        .args([
            "record",
            "--task",
            "video",
            "--duration",
            "60",
            "--no-keyboard",
            "-q",
        ])
        .args(["--connect", &endpoint])
        .arg("--rig")
        .arg(&rig_path)
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let partial = out.join("episode_000000.mcap.partial");
    scaledp_tests::await_file(
        &partial,
        Duration::from_secs(20),
        "recorder never opened an episode",
    );
    std::thread::sleep(Duration::from_millis(2500));
    child.kill().unwrap();
    child.wait().unwrap();
    sim.stop();
    let status = Command::new(scaledp_bin())
        .arg("recover")
        .arg(&partial)
        .status()
        .unwrap();
    assert!(matches!(status.code(), Some(0 | 3)), "recover: {status}");
    let bytes = std::fs::read(out.join("episode_000000.mcap")).unwrap();

    let mut frames: BTreeMap<String, Vec<CompressedVideo>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        if schema.name == "foxglove_msgs/msg/CompressedVideo" {
            assert_eq!(schema.encoding, "ros2msg");
            assert_eq!(m.channel.message_encoding, "cdr");
            frames
                .entry(m.channel.topic.clone())
                .or_default()
                .push(CompressedVideo::from_cdr(&m.data).unwrap());
        }
    }
    assert_eq!(frames.len(), 2, "both cameras: {:?}", frames.keys());
    for (topic, stream) in &frames {
        // Seconds of 30 fps video, beginning at a keyframe (earlier frames are left out).
        assert!(stream.len() >= 30, "{topic}: {} frames", stream.len());
        assert!(stream[0].is_keyframe(), "{topic} starts with a keyframe");
        assert!(stream.iter().all(|f| f.format == "h264"));
        let mut dec = openh264::decoder::Decoder::new().unwrap();
        let mut pictures = 0;
        for (i, f) in stream.iter().enumerate() {
            let got = dec
                .decode(&f.data)
                .unwrap_or_else(|e| panic!("{topic} frame {i}: {e}"));
            if let Some(p) = got {
                use openh264::formats::YUVSource;
                assert_eq!(p.dimensions(), (64, 48), "{topic} frame {i}");
                pictures += 1;
            }
        }
        pictures += dec.flush_remaining().unwrap().len();
        assert_eq!(pictures, stream.len(), "{topic}: every frame decodes");
    }
}

/// Every JPEG of each `observation.images.*` column of a dataset's first data file, decoded.
fn pictures(dataset: &std::path::Path) -> BTreeMap<String, Vec<image::RgbImage>> {
    use arrow_array::{Array, BinaryArray, StructArray};
    let file = std::fs::File::open(dataset.join("data/chunk-000/file-000.parquet")).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap();
    let mut out: BTreeMap<String, Vec<image::RgbImage>> = BTreeMap::new();
    for batch in reader {
        let batch = batch.unwrap();
        for (field, col) in batch.schema().fields().iter().zip(batch.columns()) {
            if !field.name().starts_with("observation.images.") {
                continue;
            }
            let s = col.as_any().downcast_ref::<StructArray>().unwrap();
            let bytes = s
                .column_by_name("bytes")
                .unwrap()
                .as_any()
                .downcast_ref::<BinaryArray>()
                .unwrap();
            for i in 0..bytes.len() {
                let img = image::load_from_memory(bytes.value(i)).unwrap().to_rgb8();
                out.entry(field.name().clone()).or_default().push(img);
            }
        }
    }
    out
}

#[test]
fn an_h264_recording_converts_to_the_dataset_of_its_raw_twin() {
    let dir = tempfile::tempdir().unwrap();
    let raw_rig = small_franka();
    let mut video_rig = raw_rig.clone();
    for c in &mut video_rig.cameras {
        c.encoding = Some("h264".into());
    }
    let mut datasets = Vec::new();
    for (name, rig) in [("raw", &raw_rig), ("h264", &video_rig)] {
        let rec = dir.path().join(name);
        std::fs::create_dir_all(&rec).unwrap();
        synth_episode(&rec.join("episode_000000.mcap"), rig, 4, 4.0);
        let ds = dir.path().join(format!("{name}-ds"));
        convert_ok(
            &[rec.as_os_str(), "--out".as_ref(), ds.as_os_str()],
            "1 converted",
        );
        datasets.push(ds);
    }
    let (raw, video) = (&datasets[0], &datasets[1]);
    for column in ["observation.state", "action"] {
        let a = f32_rows(raw, column);
        assert!(a.len() >= 30, "{column}: {} rows", a.len());
        assert_eq!(a, f32_rows(video, column), "{column}");
    }
    let (a, b) = (pictures(raw), pictures(video));
    assert_eq!(a.len(), 2, "two cameras: {:?}", a.keys());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (camera, frames) in &a {
        let other = &b[camera];
        assert_eq!(frames.len(), other.len(), "{camera}");
        let mut worst = 0.0f64;
        for (x, y) in frames.iter().zip(other) {
            assert_eq!(x.dimensions(), y.dimensions(), "{camera}");
            let diff: u64 = x
                .as_raw()
                .iter()
                .zip(y.as_raw())
                .map(|(p, q)| u64::from(p.abs_diff(*q)))
                .sum();
            worst = worst.max(diff as f64 / x.as_raw().len() as f64);
        }
        // H.264 at the simulator's bitrate, then JPEG: a few levels (3.4 and 4.0 measured);
        // swapped channels or a wrong size fail above.
        eprintln!("{camera}: worst frame differs by {worst:.2} levels on average");
        assert!(
            worst < 8.0,
            "{camera}: a frame differs by {worst:.2} levels on average"
        );
    }
}

/// `src` rewritten with `corrupt(topic, ordinal, frame)` applied to every CompressedVideo
/// message (metadata records kept).
fn rewrite(
    src: &std::path::Path,
    dst: &std::path::Path,
    corrupt: &dyn Fn(&str, usize, &mut Vec<u8>),
) {
    let bytes = std::fs::read(src).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(std::fs::File::create(dst).unwrap()))
        .unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    for idx in &summary.metadata_indexes {
        w.write_metadata(&mcap::read::metadata(&bytes, idx).unwrap())
            .unwrap();
    }
    let mut ordinals: BTreeMap<String, usize> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let mut m = m.unwrap();
        let video = m.channel.schema.as_ref().unwrap().name == "foxglove_msgs/msg/CompressedVideo";
        if video {
            let o = ordinals.entry(m.channel.topic.clone()).or_default();
            let mut f = CompressedVideo::from_cdr(&m.data).unwrap();
            corrupt(&m.channel.topic, *o, &mut f.data);
            m.data = f.to_cdr().into();
            *o += 1;
        }
        w.write(&m).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn corrupt_h264_in_a_recording_drops_frames_to_the_next_keyframe_or_fails_only_its_input() {
    let dir = tempfile::tempdir().unwrap();
    let mut rig = small_franka();
    for c in &mut rig.cameras {
        c.encoding = Some("h264".into());
    }
    let good = dir.path().join("good.mcap");
    synth_episode(&good, &rig, 6, 4.0);
    let inputs = dir.path().join("inputs");
    std::fs::create_dir_all(&inputs).unwrap();
    // Frame 57 of one camera cut to its first bytes: it and the two after it up to the IDR at
    // 60 (30 fps, an IDR a second) are dropped, a stale frame at 1 tick of 40 at most.
    let damaged = inputs.join("episode_000000.mcap");
    rewrite(&good, &damaged, &|topic, o, data| {
        if topic.contains("zed_front") && o == 57 {
            data.truncate(8);
        }
    });
    // Every frame of one camera garbage: no picture at all.
    let ruined = inputs.join("episode_000001.mcap");
    rewrite(&good, &ruined, &|topic, _, data| {
        if topic.contains("zed_front") {
            data.iter_mut().for_each(|b| *b = 0x5A);
        }
    });
    let ds = dir.path().join("ds");
    let out = Command::new(scaledp_bin())
        .args(["convert", "--unlabeled", "keep"])
        .arg(&inputs)
        .arg("--out")
        .arg(&ds)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    eprintln!("{stdout}\n{stderr}");
    assert_eq!(out.status.code(), Some(3), "{stdout}\n{stderr}");
    assert!(stdout.contains("1 converted"), "{stdout}");
    let warned: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("episode_000000.mcap") && l.contains("gave no picture"))
        .collect();
    assert!(!warned.is_empty(), "{stderr}");
    assert!(warned[0].contains("front"), "{}", warned[0]);
    let failed: Vec<&str> = stdout
        .lines()
        .filter(|l| l.contains("episode_000001.mcap"))
        .collect();
    assert_eq!(failed.len(), 1, "{failed:?}");
    assert!(
        failed[0].contains("front") && failed[0].contains("h264 frame that decodes"),
        "{}",
        failed[0]
    );
    assert_eq!(
        f32_rows(&ds, "action").len(),
        f32_rows(&ds, "observation.state").len()
    );
}
