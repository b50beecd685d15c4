//! ROS bags written by the Python `rosbags` package (tests/py/make_bags.py): ROS 1 bags with
//! none / bz2 / lz4 chunks and rosbag2 directories with mcap and sqlite3 storage must read back
//! with the right topics, counts, types, order and message contents; truncated or altered ones
//! must fail with an error, never a panic.

// Helpers outside #[test] functions unwrap too (allowed in tests).
#![allow(clippy::unwrap_used)]

use scaledp_converter::{read_ros1_bag, read_rosbag2, ros1, Recording, Serialization, TopicInfo};
use scaledp_schema::msg::{Image, JointState};
use scaledp_schema::RosMessage;
use serde_json::Value;

/// Fixtures in a temporary directory, removed when dropped.
struct Fixtures {
    dir: tempfile::TempDir,
    expected: Value,
}

fn fixtures(seconds: f64) -> Fixtures {
    let dir = tempfile::tempdir().unwrap();
    let expected = scaledp_testkit::make_bags_lasting(dir.path(), seconds);
    Fixtures { dir, expected }
}

fn all(_: &TopicInfo) -> bool {
    true
}

fn read(fx: &Fixtures, name: &str, want: &dyn Fn(&TopicInfo) -> bool) -> Recording {
    let path = fx.dir.path().join(name);
    let r = match fx.expected["files"][name]["format"].as_str().unwrap() {
        "ros1" => read_ros1_bag(&path, want),
        _ => read_rosbag2(&path, want),
    };
    r.unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Checks topics, counts, types, order and the first message of each topic against
/// expected.json.
fn check(fx: &Fixtures, name: &str, rec: &Recording) {
    let want = fx.expected["files"][name]["topics"].as_object().unwrap();
    let topics: Vec<&str> = rec.topics.iter().map(|t| t.topic.as_str()).collect();
    assert_eq!(
        topics,
        want.keys().map(String::as_str).collect::<Vec<_>>(),
        "{name}"
    );
    for t in &rec.topics {
        let w = &want[&t.topic];
        assert_eq!(
            t.message_type,
            w["type"].as_str().unwrap(),
            "{name} {}",
            t.topic
        );
        assert_eq!(t.count, w["count"].as_u64(), "{name} {}", t.topic);
        let n = rec.messages.iter().filter(|m| m.topic == t.topic).count();
        assert_eq!(Some(n as u64), w["count"].as_u64(), "{name} {}", t.topic);
    }
    assert!(
        rec.messages
            .windows(2)
            .all(|w| w[0].log_time_ns <= w[1].log_time_ns),
        "{name}"
    );
    let ros1 = fx.expected["files"][name]["format"] == "ros1";
    for (topic, first) in fx.expected["first"].as_object().unwrap() {
        let m = rec.messages.iter().find(|m| &m.topic == topic).unwrap();
        let ctx = format!("{name} {topic}");
        assert_eq!(
            m.log_time_ns,
            first["log_time_ns"].as_u64().unwrap(),
            "{ctx}"
        );
        assert_eq!(
            m.serialization,
            if ros1 {
                Serialization::Ros1
            } else {
                Serialization::Cdr
            }
        );
        assert_eq!(
            m.message_type,
            want[topic]["type"].as_str().unwrap(),
            "{ctx}"
        );
        if m.message_type.ends_with("/Image") {
            let img = if ros1 {
                ros1::decode::image(&m.data).unwrap()
            } else {
                Image::from_cdr(&m.data).unwrap()
            };
            assert_eq!(
                img.header.stamp.as_ns(),
                first["stamp_ns"].as_u64().unwrap(),
                "{ctx}"
            );
            assert_eq!(
                img.header.frame_id,
                first["frame_id"].as_str().unwrap(),
                "{ctx}"
            );
            assert_eq!(
                u64::from(img.height),
                first["height"].as_u64().unwrap(),
                "{ctx}"
            );
            assert_eq!(
                u64::from(img.width),
                first["width"].as_u64().unwrap(),
                "{ctx}"
            );
            assert_eq!(
                u64::from(img.step),
                first["step"].as_u64().unwrap(),
                "{ctx}"
            );
            assert_eq!(img.encoding, first["encoding"].as_str().unwrap(), "{ctx}");
            assert_eq!(
                img.data.len() as u64,
                first["data_len"].as_u64().unwrap(),
                "{ctx}"
            );
            let sum: u64 = img.data.iter().map(|&b| u64::from(b)).sum();
            assert_eq!(sum, first["data_sum"].as_u64().unwrap(), "{ctx}");
        } else {
            let js = if ros1 {
                ros1::decode::joint_state(&m.data).unwrap()
            } else {
                JointState::from_cdr(&m.data).unwrap()
            };
            assert_eq!(
                js.header.stamp.as_ns(),
                first["stamp_ns"].as_u64().unwrap(),
                "{ctx}"
            );
            let names: Vec<&str> = first["name"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_str().unwrap())
                .collect();
            assert_eq!(js.name, names, "{ctx}");
            let pos: Vec<f64> = first["position"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert_eq!(js.position, pos, "{ctx}");
            assert_eq!(js.velocity.len(), names.len(), "{ctx}");
        }
    }
}

#[test]
fn rosbags_fixtures_read_back() {
    let fx = fixtures(3.0);
    let names: Vec<String> = fx.expected["files"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    assert_eq!(names.len(), 5);
    let mut reference: Option<Vec<(String, u64)>> = None;
    for name in &names {
        let rec = read(&fx, name, &all);
        check(&fx, name, &rec);
        // Every file holds the same messages at the same log times.
        let order: Vec<(String, u64)> = rec
            .messages
            .iter()
            .map(|m| (m.topic.clone(), m.log_time_ns))
            .collect();
        match &reference {
            None => reference = Some(order),
            Some(r) => assert!(*r == order, "{name}: messages differ from the first file's"),
        }
        // Filtering: only the gripper; topics still lists everything.
        let gripper = |t: &TopicInfo| t.topic == "/franka_gripper/joint_states";
        let only = read(&fx, name, &gripper);
        assert_eq!(only.topics, rec.topics, "{name}");
        assert_eq!(only.messages.len(), 150, "{name}");
        assert!(only
            .messages
            .iter()
            .all(|m| m.topic == "/franka_gripper/joint_states"));
    }
    // The storage files of the rosbag2 directories read standalone too.
    for (dir, file) in [
        ("franka_rosbag2_sqlite3", "franka_rosbag2_sqlite3.db3"),
        ("franka_rosbag2_mcap", "franka_rosbag2_mcap.mcap"),
    ] {
        let rec = read_rosbag2(&fx.dir.path().join(dir).join(file), &all).unwrap();
        check(&fx, dir, &rec);
    }
}

#[test]
fn damaged_inputs_are_errors() {
    let fx = fixtures(0.2);
    let work = tempfile::tempdir().unwrap();
    let cut_path = work.path().join("cut.bag");
    for name in [
        "franka_ros1_none.bag",
        "franka_ros1_bz2.bag",
        "franka_ros1_lz4.bag",
    ] {
        let bytes = std::fs::read(fx.dir.path().join(name)).unwrap();
        // Cuts all over, dense at the start (bag header) and the end (index section).
        let near_end = |c: usize| c + 64 > bytes.len() || (c + 12_000 > bytes.len() && c % 13 == 0);
        let cuts = (0..bytes.len()).filter(|&c| c % 997 == 0 || c < 300 || near_end(c));
        std::fs::write(&cut_path, &bytes).unwrap();
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(&cut_path)
            .unwrap();
        for cut in cuts.rev() {
            file.set_len(cut as u64).unwrap();
            let err = read_ros1_bag(&cut_path, &all).err();
            assert!(
                err.is_some(),
                "{name} cut at {cut} of {} bytes read",
                bytes.len()
            );
        }
        // ROS 1 decoding of every prefix of real payloads fails.
        let rec = read(&fx, name, &all);
        for topic in fx.expected["first"].as_object().unwrap().keys() {
            let m = rec.messages.iter().find(|m| &m.topic == topic).unwrap();
            for n in 0..m.data.len() {
                let r = if m.message_type.ends_with("/Image") {
                    ros1::decode::image(&m.data[..n]).map(drop)
                } else {
                    ros1::decode::joint_state(&m.data[..n]).map(drop)
                };
                assert!(r.is_err(), "{topic}: {n}-byte prefix decoded");
            }
        }
    }

    // rosbag2: no metadata.yaml, metadata listing no storage file or a missing one, a
    // truncated db3, a non-cdr topic.
    let bare = work.path().join("bare");
    std::fs::create_dir(&bare).unwrap();
    assert!(read_rosbag2(&bare, &all)
        .unwrap_err()
        .to_string()
        .contains("metadata.yaml"));
    std::fs::write(
        bare.join("metadata.yaml"),
        "rosbag2_bagfile_information: {}\n",
    )
    .unwrap();
    let e = read_rosbag2(&bare, &all).unwrap_err().to_string();
    assert!(e.contains("lists no storage files"), "{e}");
    std::fs::write(
        bare.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  relative_file_paths:\n  - bare_0.db3\n",
    )
    .unwrap();
    let e = read_rosbag2(&bare, &all).unwrap_err().to_string();
    assert!(e.contains("'bare_0.db3', which is missing"), "{e}");
    // A Foxy bag (metadata version < 4) lists its files from the parent directory.
    let foxy = work.path().join("foxy");
    std::fs::create_dir(&foxy).unwrap();
    std::fs::copy(
        fx.dir
            .path()
            .join("franka_rosbag2_sqlite3/franka_rosbag2_sqlite3.db3"),
        foxy.join("foxy_0.db3"),
    )
    .unwrap();
    std::fs::write(
        foxy.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 3\n  relative_file_paths:\n    - foxy/foxy_0.db3\n",
    )
    .unwrap();
    assert!(!read_rosbag2(&foxy, &all).unwrap().messages.is_empty());
    let db3 = fx
        .dir
        .path()
        .join("franka_rosbag2_sqlite3/franka_rosbag2_sqlite3.db3");
    let bytes = std::fs::read(&db3).unwrap();
    let cut = work.path().join("cut.db3");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    assert!(read_rosbag2(&cut, &all).is_err());
    let ros1_db3 = work.path().join("ros1.db3");
    std::fs::copy(&db3, &ros1_db3).unwrap();
    let db = rusqlite::Connection::open(&ros1_db3).unwrap();
    db.execute(
        "UPDATE topics SET serialization_format = 'ros1' WHERE name = '/franka/joint_states'",
        [],
    )
    .unwrap();
    drop(db);
    let err = read_rosbag2(&ros1_db3, &all).unwrap_err().to_string();
    assert!(
        err.contains("expected 'cdr'") && err.contains("ros1.db3"),
        "{err}"
    );
    // ... which is fine when that topic is not wanted.
    let cams = |t: &TopicInfo| t.message_type == "sensor_msgs/msg/Image";
    assert!(!read_rosbag2(&ros1_db3, &cams).unwrap().messages.is_empty());
    let mcap = fx
        .dir
        .path()
        .join("franka_rosbag2_mcap/franka_rosbag2_mcap.mcap");
    let bytes = std::fs::read(&mcap).unwrap();
    let cut_dir = work.path().join("cut_mcap");
    std::fs::create_dir(&cut_dir).unwrap();
    std::fs::write(
        cut_dir.join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  relative_file_paths: [cut.mcap]\n",
    )
    .unwrap();
    std::fs::write(cut_dir.join("cut.mcap"), &bytes[..bytes.len() * 2 / 3]).unwrap();
    let e = read_rosbag2(&cut_dir, &all).unwrap_err().to_string();
    assert!(e.contains("cut.mcap") && e.contains("truncated"), "{e}");
}
