//! What `scaledp convert` writes beyond the frames: actions from a `PoseStamped` command topic,
//! the `scaledp` section of `info.json` and the per-episode alignment report, and `--overwrite`.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

use crate::convert_common::{convert_cli, convert_ok};
use scaledp_schema::msg::{Header, Point, Pose, PoseStamped, Quaternion, Time};
use scaledp_schema::{Rig, RosMessage};
use scaledp_tests::{
    check_dataset, episode_column, f32_column, f32_rows, read_json, run_python, small_franka,
    synth_episode, workspace, T0,
};

/// Copies the MCAP `src` to `dst`: its metadata and every message `keep(topic, index in topic)`
/// accepts, with `extra` (log time, payload) messages of type `extra_type` on `extra_topic`
/// merged in by log time.
fn rewrite_mcap(
    src: &Path,
    dst: &Path,
    keep: &dyn Fn(&str, u64) -> bool,
    (extra_topic, extra_type, extra): (&str, &str, &[(u64, Vec<u8>)]),
) {
    let bytes = std::fs::read(src).unwrap();
    let mut w = mcap::WriteOptions::new()
        .profile("ros2")
        .create(std::io::BufWriter::new(std::fs::File::create(dst).unwrap()))
        .unwrap();
    for r in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = r.unwrap() {
            w.write_metadata(&m).unwrap();
        }
    }
    let schema = Arc::new(mcap::Schema {
        id: 1000,
        name: extra_type.into(),
        encoding: "ros2msg".into(),
        data: Cow::Owned(
            scaledp_schema::msg::definition(extra_type)
                .unwrap()
                .into_bytes(),
        ),
    });
    let channel = Arc::new(mcap::Channel {
        id: 1000,
        topic: extra_topic.into(),
        schema: Some(schema),
        message_encoding: "cdr".into(),
        metadata: BTreeMap::new(),
    });
    let write_extra = |w: &mut mcap::Writer<_>, i: usize, log: u64, data: &[u8]| {
        w.write(&mcap::Message {
            channel: channel.clone(),
            sequence: i as u32,
            log_time: log,
            publish_time: log,
            data: Cow::Borrowed(data),
        })
        .unwrap();
    };
    let mut extra = extra.iter().enumerate().peekable();
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        while let Some((i, (log, data))) = extra.next_if(|(_, (log, _))| *log <= m.log_time) {
            write_extra(&mut w, i, *log, data);
        }
        let k = counts.entry(m.channel.topic.clone()).or_default();
        if keep(&m.channel.topic, *k) {
            w.write(&m).unwrap();
        }
        *k += 1;
    }
    for (i, (log, data)) in extra {
        write_extra(&mut w, i, *log, data);
    }
    w.finish().unwrap();
}

/// ROS's quaternion of R = Rz(yaw)·Ry(pitch)·Rx(roll).
fn quaternion([roll, pitch, yaw]: [f64; 3]) -> Quaternion {
    let (sr, cr) = (roll / 2.0).sin_cos();
    let (sp, cp) = (pitch / 2.0).sin_cos();
    let (sy, cy) = (yaw / 2.0).sin_cos();
    Quaternion {
        x: sr * cp * cy - cr * sp * sy,
        y: cr * sp * cy + sr * cp * sy,
        z: cr * cp * sy - sr * sp * cy,
        w: cr * cp * cy + sr * sp * sy,
    }
}

/// Command target k: x, y, z, roll, pitch, yaw, angles unwrapped. The arm's own roll sits just
/// below π; the target's starts 0.25 rad past it, i.e. at −π + 0.25 as a ROS quaternion reads,
/// and runs back through π; its yaw runs down through −π.
fn target(k: usize) -> [f64; 6] {
    let k = k as f64;
    [
        0.40 + 0.001 * k,
        -0.10 + 0.002 * k,
        0.30 + 0.0005 * k,
        PI + 0.25 - 0.004 * k,
        0.2 - 0.002 * k,
        -PI + 0.5 - 0.01 * k,
    ]
}

#[test]
fn a_pose_stamped_command_topic_is_the_action_at_each_tick() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let plain = dir.path().join("plain.mcap");
    synth_episode(&plain, &rig, 3, 3.0);
    let start = T0 + 300_000_000_000;
    // Targets at 50 Hz on their own grid, received 1 ms after their stamp.
    let stamps: Vec<u64> = (0..150)
        .map(|k| start + 5_000_000 + k * 20_000_000)
        .collect();
    let msgs: Vec<(u64, Vec<u8>)> = stamps
        .iter()
        .enumerate()
        .map(|(k, &stamp)| {
            let p = target(k);
            let msg = PoseStamped {
                header: Header {
                    stamp: Time::from_ns(stamp),
                    frame_id: "fr3_link0".into(),
                },
                pose: Pose {
                    position: Point {
                        x: p[0],
                        y: p[1],
                        z: p[2],
                    },
                    orientation: quaternion([p[3], p[4], p[5]]),
                },
            };
            (stamp + 1_000_000, msg.to_cdr())
        })
        .collect();
    let ep = dir.path().join("episode_000000.mcap");
    rewrite_mcap(
        &plain,
        &ep,
        &|_, _| true,
        ("/arm/target_pose", PoseStamped::TYPE_NAME, &msgs),
    );
    let ds = dir.path().join("ds");
    let over = format!("{}_command=/arm/target_pose", rig.arms[0].name);
    let out = convert_cli(&[
        ep.as_os_str(),
        "--out".as_ref(),
        ds.as_os_str(),
        "--size".as_ref(),
        "64x48".as_ref(),
        "--topic".as_ref(),
        over.as_ref(),
    ]);
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let (state, action) = (f32_rows(&ds, "observation.state"), f32_rows(&ds, "action"));
    assert!(state.len() > 20);
    // A valid LeRobot dataset, but for check_lerobot.py's "action is the next state" (scaledp's
    // default convention, which a command topic replaces).
    let v = run_python(
        "check_lerobot.py",
        &[&ds, &workspace().join("tests/fixtures/lerobot_v3_example")],
    );
    let errors: Vec<&str> = v["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_str().unwrap())
        .filter(|e| !e.ends_with("action is not the next state"))
        .collect();
    assert!(errors.is_empty(), "{errors:?}");
    assert_eq!(v["frames"].as_u64().unwrap() as usize, state.len());
    let ts: Vec<f64> = f32_column(&ds, "timestamp")
        .into_iter()
        .map(f64::from)
        .collect();
    // The command's angles are on the state's branch (within π of it at the first tick), so
    // action − state never carries a spurious turn; then they run on continuously.
    for d in 3..6 {
        let gap = f64::from((action[0][d] - state[0][d]).abs());
        assert!(
            gap <= PI + 1e-5,
            "dim {d}: action {action:?} vs state {state:?}",
            action = action[0][d],
            state = state[0][d]
        );
        for t in 1..action.len() {
            assert!(
                (action[t][d] - action[t - 1][d]).abs() < 0.5,
                "dim {d} jumps at tick {t}"
            );
        }
    }
    let mut chosen = Vec::new();
    for (t, a) in action.iter().enumerate() {
        // Which target the action is (x encodes k), then every dimension of that target.
        let k = ((f64::from(a[0]) - 0.40) / 0.001).round() as usize;
        assert!(k < stamps.len(), "tick {t}: {a:?}");
        let want = target(k);
        for d in 0..6 {
            let err = (f64::from(a[d]) - want[d]).abs();
            assert!(
                err < 1e-5,
                "tick {t} dim {d}: {} vs target {k} {want:?}",
                a[d]
            );
        }
        if t + 1 < state.len() {
            assert_eq!(a[6], state[t + 1][6], "tick {t}: gripper of the next tick");
        }
        chosen.push(k);
    }
    // The target is the latest at or before its tick: one first-tick time, ticks 100 ms apart,
    // fits every choice.
    let (mut lo, mut hi) = (f64::MIN, f64::MAX);
    for (&k, t) in chosen.iter().zip(&ts) {
        lo = lo.max(stamps[k] as f64 - t * 1e9 - 1e3);
        if let Some(&next) = stamps.get(k + 1) {
            hi = hi.min(next as f64 - t * 1e9 + 1e3);
        }
    }
    assert!(
        lo <= hi,
        "targets {chosen:?} are not the latest at their ticks"
    );
    assert!(
        chosen.windows(2).all(|w| (4..=6).contains(&(w[1] - w[0]))),
        "{chosen:?}"
    );
}

/// BLAKE3 of a file's name then its bytes, as the converter keys its inputs.
fn source_hash(path: &Path) -> String {
    let mut h = blake3::Hasher::new();
    h.update(path.file_name().unwrap().as_encoded_bytes());
    h.update(&std::fs::read(path).unwrap());
    h.finalize().to_hex().to_string()
}

#[test]
fn info_json_and_the_episodes_table_record_provenance_and_overwrite_starts_afresh() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir_all(&inp).unwrap();
    let rig = small_franka();
    let eps: Vec<_> = (0..2)
        .map(|i| inp.join(format!("episode_{i:06}.mcap")))
        .collect();
    for (i, ep) in eps.iter().enumerate() {
        synth_episode(ep, &rig, i as u64 + 1, 2.0);
    }
    let ds = dir.path().join("ds");
    let run = |inputs: &Path, extra: &[&str], converted: &str| {
        let mut args = vec![
            inputs.as_os_str(),
            "--out".as_ref(),
            ds.as_os_str(),
            "--size".as_ref(),
            "64x48".as_ref(),
            "--jobs".as_ref(),
            "1".as_ref(),
        ];
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        convert_ok(&args, converted)
    };
    run(&inp, &[], "2 converted");
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], 2);

    let info = read_json(&ds.join("meta/info.json"));
    let s = &info["scaledp"];
    assert_eq!(s["converter_version"], env!("CARGO_PKG_VERSION"));
    let recorded = Rig::parse(s["rig"].as_str().unwrap(), Path::new("info.json")).unwrap();
    assert_eq!(recorded, rig, "the rig the episodes were recorded with");
    assert_eq!(s["fps"].as_f64(), Some(rig.control_rate_hz));
    assert_eq!(s["image_size"], serde_json::json!([64, 48]));
    for key in ["action", "kinematics", "time_alignment"] {
        assert!(s[key].as_str().is_some_and(|t| t.len() > 40), "{key}");
    }
    let hashes: Vec<String> = eps.iter().map(|p| source_hash(p)).collect();
    assert_ne!(hashes[0], hashes[1]);
    let sources = s["sources"].as_array().unwrap();
    assert_eq!(sources.len(), 2);
    for (i, src) in sources.iter().enumerate() {
        assert_eq!(src["episode_index"], i);
        assert!(
            src["source"]
                .as_str()
                .unwrap()
                .ends_with(&format!("episode_{i:06}.mcap")),
            "{src}"
        );
        assert_eq!(src["blake3"], hashes[i]);
    }

    // The episodes table carries the same provenance and the alignment report.
    assert_eq!(
        episode_column(&ds, "scaledp/source"),
        sources
            .iter()
            .map(|s| s["source"].clone())
            .collect::<Vec<_>>()
    );
    assert_eq!(
        episode_column(&ds, "scaledp/source_blake3"),
        hashes
            .iter()
            .map(|h| h.as_str().into())
            .collect::<Vec<serde_json::Value>>()
    );
    // The simulator's cameras are stamped within ±0.5 ms of the same instants.
    for skew in episode_column(&ds, "scaledp/max_camera_skew_s") {
        let skew = skew.as_f64().unwrap();
        assert!((0.0..=0.0011).contains(&skew), "camera skew {skew} s");
    }
    for column in ["scaledp/invalid_ticks", "scaledp/dropped_frames"] {
        assert_eq!(
            episode_column(&ds, column),
            [serde_json::json!(0), serde_json::json!(0)],
            "{column}"
        );
    }

    // Again: both inputs are skipped by content. With --overwrite on the second alone, the
    // dataset is rebuilt holding just that one.
    run(&inp, &[], "0 converted");
    run(&eps[1], &["--overwrite"], "1 converted");
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], 1);
    let info = read_json(&ds.join("meta/info.json"));
    assert_eq!(info["total_episodes"], 1);
    assert_eq!(info["scaledp"]["sources"][0]["blake3"], hashes[1]);
    assert_eq!(
        episode_column(&ds, "scaledp/source_blake3"),
        [serde_json::Value::from(hashes[1].as_str())]
    );
}
