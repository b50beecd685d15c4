//! Frames encoded during the one read of an MCAP recording (picked ahead of alignment) give the
//! same episode as frames fetched by a second read, including when the guess is wrong, and a
//! recording whose chunks end with frames (left compressed until picked) reads whole. A
//! recording whose camera was zoomed does not join a dataset of the old pictures.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use scaledp_converter::frames::read_mcap_light;
use scaledp_converter::{convert, ConvertOptions, Episode, FrameStore, TopicInfo};
use scaledp_schema::msg::{Header, Image, JointState, Time};
use scaledp_schema::{Rig, RosMessage};

const T0: u64 = 1_700_000_000_000_000_000;

/// 2.5 s of the built-in Franka rig: two 640×480 bgra8 cameras at ~30 Hz with jittered stamps
/// (one camera drops a few frames), arm and gripper joint states at 200 Hz; LZ4 chunks of 2 MiB,
/// so most chunks end with a frame. The rig is stored as the recorder stores it.
fn record(path: &Path, rig: &Rig) {
    let file = std::fs::File::create(path).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .compression(Some(mcap::Compression::Lz4))
        .chunk_size(Some(2 << 20))
        .create(BufWriter::new(file))
        .unwrap();
    let image = w
        .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        .unwrap();
    let joints = w
        .add_schema("sensor_msgs/msg/JointState", "ros2msg", b"")
        .unwrap();
    let none = BTreeMap::new();
    let cams: Vec<u16> = rig
        .cameras
        .iter()
        .map(|c| w.add_channel(image, &c.topic, "cdr", &none).unwrap())
        .collect();
    let arm = &rig.arms[0];
    let grip = arm.gripper.as_ref().unwrap();
    let arm_ch = w
        .add_channel(joints, &arm.joint_state_topic, "cdr", &none)
        .unwrap();
    let grip_ch = w.add_channel(joints, &grip.topic, "cdr", &none).unwrap();
    w.write_metadata(&mcap::records::Metadata {
        name: scaledp_schema::episode::START_RECORD.into(),
        metadata: BTreeMap::from([
            ("rig".to_string(), toml::to_string(rig).unwrap()),
            ("task".to_string(), "stack the cubes".to_string()),
        ]),
    })
    .unwrap();
    // (log time, channel, camera index or None, sample index), written in log order; payloads
    // are made as they are written, so the test holds one frame at a time.
    let mut msgs: Vec<(u64, u16, Option<usize>, u64)> = Vec::new();
    for (ci, &ch) in cams.iter().enumerate() {
        for k in 0..75u64 {
            if ci == 1 && (30..32).contains(&k) {
                continue; // dropped frames
            }
            msgs.push((cam_stamp(ci, k) + 4_000_000, ch, Some(ci), k));
        }
    }
    for k in 0..500u64 {
        msgs.push((T0 + k * 5_000_000 + 500_000, arm_ch, None, k));
        msgs.push((T0 + k * 5_000_000 + 600_000, grip_ch, None, k));
    }
    msgs.sort_by_key(|m| m.0);
    for (i, &(log, ch, cam, k)) in msgs.iter().enumerate() {
        let data = match cam {
            Some(ci) => frame(ci, k),
            None if ch == arm_ch => joints_at(k, &arm.joint_names, true),
            None => joints_at(k, &grip.joint_names, false),
        };
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: i as u32,
            log_time: log,
            publish_time: log,
        };
        w.write_to_known_channel(&header, &data).unwrap();
    }
    w.finish().unwrap();
}

/// Capture stamp of frame `k` of camera `ci`: ~30 Hz with a few ms of jitter.
fn cam_stamp(ci: usize, k: u64) -> u64 {
    T0 + 3_000_000 * ci as u64 + k * 33_333_333 + (k * 7_919 % 5) * 1_000_000
}

/// Frame `k` of camera `ci`: 640×480 bgra8 (1.2 MB, so a chunk's last frame is left
/// compressed until picked), a moving gradient.
fn frame(ci: usize, k: u64) -> Vec<u8> {
    let (w, h) = (640u32, 480u32);
    let data = (0..w * h * 4)
        .map(|i| ((i / 4 % w + k as u32 * 3 + ci as u32 * 50) / 5 + (i / 4 / w) / 7 + i % 4) as u8)
        .collect();
    Image {
        header: Header {
            stamp: Time::from_ns(cam_stamp(ci, k)),
            frame_id: "cam".into(),
        },
        height: h,
        width: w,
        encoding: "bgra8".into(),
        is_bigendian: 0,
        step: w * 4,
        data,
    }
    .to_cdr()
}

/// Sample `k` of a 200 Hz joint state: moving arm joints, a still gripper.
fn joints_at(k: u64, names: &[String], moving: bool) -> Vec<u8> {
    let t = k as f64 * 0.005;
    JointState {
        header: Header {
            stamp: Time::from_ns(T0 + k * 5_000_000),
            frame_id: String::new(),
        },
        name: names.to_vec(),
        position: (0..names.len())
            .map(|j| {
                if moving {
                    0.3 * (t + j as f64).sin()
                } else {
                    0.02
                }
            })
            .collect(),
        velocity: vec![],
        effort: vec![],
    }
    .to_cdr()
}

fn useful(t: &TopicInfo) -> bool {
    t.message_type.starts_with("sensor_msgs/msg/")
}

/// Converts `path` with `opts`, the first read guessing frames for `guess` (None: no guess).
/// Returns the episode, the frames encoded ahead and the frames read again.
fn episode(
    path: &Path,
    guess: Option<&ConvertOptions>,
    opts: &ConvertOptions,
) -> (Episode, usize, usize) {
    let (rec, frames) = read_mcap_light(path, &useful, guess).unwrap();
    let ahead = frames.prefetched();
    assert_eq!(
        frames
            .stamps(&opts.rig.as_ref().unwrap().cameras[0].topic)
            .len(),
        75
    );
    let ep = convert(path, &rec, &frames, opts).unwrap();
    (ep, ahead, frames.read_again())
}

fn same(a: &Episode, b: &Episode) {
    assert_eq!(a.timestamps, b.timestamps);
    assert_eq!(a.state, b.state);
    assert_eq!(a.action, b.action);
    assert_eq!(a.cameras.len(), b.cameras.len());
    for (x, y) in a.cameras.iter().zip(&b.cameras) {
        assert_eq!(x.jpeg, y.jpeg, "{}", x.name);
        for c in 0..3 {
            assert_eq!(
                x.histogram.channel(c, &[0.5]),
                y.histogram.channel(c, &[0.5])
            );
        }
    }
}

#[test]
fn frames_picked_during_the_read_equal_frames_read_again() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("episode.mcap");
    let rig = Rig::builtin("franka_2zed").unwrap().training_streams();
    record(&path, &rig);
    let unrigged = ConvertOptions::default()
        .size(160, 120)
        .max_invalid_fraction(0.2);
    let opts = unrigged.clone().rig(rig.clone());
    let (reference, none_ahead, all_again) = episode(&path, None, &opts);
    assert_eq!(none_ahead, 0);
    assert!(reference.len() > 15, "{} frames", reference.len());
    // Without a guess every frame used comes from the second read.
    assert!((reference.len()..=2 * reference.len()).contains(&all_again));

    // The guess: every frame used, a few more at most, and none read again (the guess predicts
    // alignment's ticks exactly).
    let (guessed, ahead, again) = episode(&path, Some(&opts), &opts);
    same(&guessed, &reference);
    assert_eq!(again, 0, "frames the guess missed");
    let used = 2 * reference.len();
    assert!(
        ahead >= reference.cameras[0].jpeg.len(),
        "{ahead} encoded ahead"
    );
    assert!(
        ahead <= used + 8,
        "{ahead} encoded ahead for {used} frame slots"
    );

    // The rig found in the file's metadata instead of given.
    let stored = unrigged;
    let (from_metadata, ahead) = episode_with_rig(&path, &stored, &opts);
    same(&from_metadata, &reference);
    assert!(ahead > 0);

    // A wrong guess (another rate): the frames it missed are read again.
    let wrong = opts.clone().fps(7.0);
    let (fixed, _, again) = episode(&path, Some(&wrong), &opts);
    same(&fixed, &reference);
    assert!(again > 0);
}

/// Like [`episode`], guessing with `guess` (no rig given) and converting with `opts`.
fn episode_with_rig(
    path: &Path,
    guess: &ConvertOptions,
    opts: &ConvertOptions,
) -> (Episode, usize) {
    let (rec, frames) = read_mcap_light(path, &useful, Some(guess)).unwrap();
    let ahead = frames.prefetched();
    (convert(path, &rec, &frames, opts).unwrap(), ahead)
}

/// A 16×16 bgra8 frame of one gray level `v`, stamped `stamp_ns`.
fn small_frame(v: u8, stamp_ns: u64) -> Vec<u8> {
    Image {
        header: Header {
            stamp: Time::from_ns(stamp_ns),
            frame_id: "cam".into(),
        },
        height: 16,
        width: 16,
        encoding: "bgra8".into(),
        is_bigendian: 0,
        step: 64,
        data: vec![v; 16 * 16 * 4],
    }
    .to_cdr()
}

#[test]
fn frames_read_again_are_counted_like_the_first_read() {
    use scaledp_converter::images::{encode_message, EncodeSpec};
    use scaledp_converter::Serialization;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("shared_topic.mcap");
    // "/cam" carries images and, on a second channel, messages of a type the read does not
    // want: they are not frames, on the first read or the second.
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .create(BufWriter::new(std::fs::File::create(&path).unwrap()))
        .unwrap();
    let image = w
        .add_schema("sensor_msgs/msg/Image", "ros2msg", b"")
        .unwrap();
    let text = w.add_schema("std_msgs/msg/String", "ros2msg", b"").unwrap();
    let none = BTreeMap::new();
    let cam = w.add_channel(image, "/cam", "cdr", &none).unwrap();
    let other = w.add_channel(text, "/cam", "cdr", &none).unwrap();
    let mut frames = Vec::new();
    for k in 0..3u64 {
        let log = T0 + k * 100_000_000;
        for (ch, data) in [
            (other, b"\0\x01\0\0\x04\0\0\0abc\0".to_vec()),
            (cam, small_frame(40 + 80 * k as u8, log)),
        ] {
            let header = mcap::records::MessageHeader {
                channel_id: ch,
                sequence: k as u32,
                log_time: log,
                publish_time: log,
            };
            w.write_to_known_channel(&header, &data).unwrap();
        }
        frames.push((log, small_frame(40 + 80 * k as u8, log)));
    }
    w.finish().unwrap();
    drop(w);

    let (_, store) = read_mcap_light(&path, &useful, None).unwrap();
    assert_eq!(store.stamps("/cam").len(), 3);
    let spec = EncodeSpec {
        width: 8,
        height: 8,
        quality: 90,
        raw: false,
    };
    let wanted = BTreeMap::from([("/cam".to_string(), (0..3).collect())]);
    let got = store.encode(&path, &wanted, &spec).unwrap();
    for (k, (log, data)) in frames.iter().enumerate() {
        let topic = "/cam";
        let image = "sensor_msgs/msg/Image";
        let want =
            encode_message(&path, topic, image, *log, Serialization::Cdr, data, &spec).unwrap();
        assert_eq!(got[&(topic.to_string(), k)].bytes, want.bytes, "frame {k}");
    }
}

/// A recording whose camera was zoomed (another `vertical_fov_deg` in its rig) does not join a
/// dataset of pictures at the old field of view: it fails alone, naming both fields, and the
/// dataset keeps its episode.
#[test]
fn a_recording_at_another_field_of_view_does_not_join_the_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let rig = Rig::builtin("franka_2zed").unwrap().training_streams();
    let mut zoomed = rig.clone();
    zoomed.cameras[0].vertical_fov_deg = Some(45.0);
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    record(&a, &rig);
    record(&b, &zoomed);
    let out = dir.path().join("dataset");
    // These recordings carry no label: kept, as the choice has to be made.
    let opts = scaledp_converter::JobOptions::default()
        .jobs(1)
        .unlabeled(scaledp_converter::Unlabeled::Keep)
        .convert(
            ConvertOptions::default()
                .size(160, 120)
                .max_invalid_fraction(0.2),
        );
    let first = scaledp_converter::run(&[a], &out, &opts, &|_| {}).unwrap();
    assert!(
        matches!(first[0].1, scaledp_converter::InputResult::Converted(_)),
        "{:?}",
        first[0].1
    );
    let second = scaledp_converter::run(&[b], &out, &opts, &|_| {}).unwrap();
    match &second[0].1 {
        scaledp_converter::InputResult::Failed(e) => {
            let e = e.to_string();
            assert!(
                e.contains("b.mcap") && e.contains("45°") && e.contains("the simulator's own"),
                "{e}"
            );
        }
        other => panic!("{other:?}"),
    }
    let info = std::fs::read_to_string(out.join("meta/info.json")).unwrap();
    assert!(info.contains("\"total_episodes\": 1"), "{info}");
}
