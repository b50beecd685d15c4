//! Compressed cameras end to end: the simulated rig publishes its cameras as H.264
//! (`foxglove_msgs/msg/CompressedVideo`, what `sim --camera-codec h264` does), `scaledp record`
//! records them, is killed with SIGKILL mid-episode, `scaledp recover` repairs the file — and
//! every camera's recorded stream starts at a keyframe and decodes frame by frame to the
//! camera's size, up to the last frame that survived.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::time::Duration;

use scaledp_recorder::net;
use scaledp_schema::msg::CompressedVideo;
use scaledp_schema::RosMessage;
use scaledp_sim::SimOptions;
use scaledp_tests::{free_endpoint, scaledp_bin, small_franka};

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
