//! `scaledp record`'s topic flags: `--topic NAME[:TYPE]` (a glob; over rmw_zenoh the type is the
//! key's), `--msg-path DIR` (definitions of types scaledp does not know, as rosbag2 finds them),
//! `--remap FROM:=TO` (a rig topic under another name); and the one-line error each gives for a
//! bad value.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use scaledp_recorder::keys::{rmw_key, RmwAttachment};
use scaledp_recorder::net;
use scaledp_schema::CDR_LE_HEADER;
use scaledp_sim::{KeyStyle, SimOptions};
use scaledp_tests::{
    cli_ok, episode_metadata, free_endpoint, full_rig, run_scaledp, write_rig_file,
};
use zenoh::Wait;

/// (exit code, stderr) of `scaledp record` with `extra` flags after valid ones.
fn record_fails(extra: &[&str]) -> (Option<i32>, String) {
    let dir = tempfile::tempdir().unwrap();
    let mut args = vec![
        "record",
        "--rig",
        "franka_2zed",
        "--out",
        "o",
        "--task",
        "t",
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--no-keyboard", "--connect", "tcp/127.0.0.1:9"]);
    let out = run_scaledp(&args, dir.path());
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).trim().to_string(),
    )
}

#[test]
fn bad_topic_remap_and_msg_path_values_are_one_line_errors() {
    for (flags, code, want) in [
        (&["--topic", "diagnostics"][..], 2, "must be absolute"),
        (
            &["--topic", "/a:DiagnosticArray"],
            2,
            "not a ROS 2 message type",
        ),
        (&["--topic", "/cam*"], 2, "whole level"),
        (&["--remap", "/tf"], 2, "expected FROM:=TO"),
        (&["--remap", "/tf:=/a b"], 2, "not a ROS 2 topic name"),
        (
            &["--remap", "/nope:=/x"],
            1,
            "error: remap /nope:=/x: rig franka_2zed has no topic /nope",
        ),
        (
            &["--msg-path", "/nonexistent/msgs"],
            1,
            "error: --msg-path /nonexistent/msgs: no such directory",
        ),
    ] {
        let (got, stderr) = record_fails(flags);
        assert_eq!(got, Some(code), "{flags:?}: {stderr}");
        let line = stderr
            .lines()
            .find(|l| l.contains("error"))
            .unwrap_or_else(|| panic!("{flags:?}: no error in {stderr}"));
        assert!(line.contains(want), "{flags:?}: {line}");
        if code == 1 {
            assert_eq!(stderr.lines().count(), 1, "{flags:?}: one line: {stderr}");
        }
    }
}

/// Writes `<dir>/my_msgs/msg/Status.msg` (a type scaledp does not know) and returns `dir`.
fn msg_tree(dir: &Path) -> std::path::PathBuf {
    let root = dir.join("msgs");
    let pkg = root.join("my_msgs/msg");
    std::fs::create_dir_all(&pkg).unwrap();
    std::fs::write(
        pkg.join("Status.msg"),
        "# A robot's status\nstd_msgs/Header header\nstring text\n",
    )
    .unwrap();
    root
}

/// A simulated rig over rmw_zenoh keys with /tf remapped, plus two further topics the test
/// publishes under /robot: one of a type found under --msg-path, one found nowhere. One timed
/// episode records the rig under its remapped names and both further topics by the glob.
#[test]
fn globs_msg_paths_and_remaps_shape_what_is_recorded() {
    let mut rig = full_rig("franka_2zed_v4", 32, 24);
    rig.cameras.truncate(1);
    rig.remap("/tf", "/robot1/tf").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let shipped = full_rig("franka_2zed_v4", 32, 24);
    let mut file_rig = shipped.clone();
    file_rig.cameras.truncate(1);
    let rig_path = write_rig_file(dir.path(), &file_rig);
    let msgs = msg_tree(dir.path());
    let endpoint = free_endpoint();
    let session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let sim = SimOptions::new(rig.clone())
        .keys(KeyStyle::Rmw)
        .spawn(&session)
        .unwrap();
    // The further topics, published until the recorder is done (bounded: 60 s).
    let done = Arc::new(AtomicBool::new(false));
    let feeder = {
        let (session, done) = (session.clone(), done.clone());
        std::thread::spawn(move || {
            let started = Instant::now();
            let mut seq = 0i64;
            while !done.load(Ordering::Relaxed) && started.elapsed() < Duration::from_secs(60) {
                seq += 1;
                for (topic, ty) in [
                    ("/robot/status", "my_msgs/msg/Status"),
                    ("/robot/odd", "other_msgs/msg/Unknown"),
                ] {
                    let mut payload = CDR_LE_HEADER.to_vec();
                    payload.extend_from_slice(&[1, 0, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0]);
                    let att = RmwAttachment {
                        sequence_number: seq,
                        source_timestamp_ns: 1,
                        source_gid: vec![3; 16],
                    };
                    let key = rmw_key(0, topic, ty, "RIHS01_00");
                    let _ = session.put(key, payload).attachment(att.to_zbytes()).wait();
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    let out = dir.path().join("out");
    let args = [
        "record",
        "--rig",
        rig_path.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--task",
        "t",
        "--episodes",
        "1",
        "--duration",
        "1.5",
        "--no-keyboard",
        "-q",
        "--connect",
        &endpoint,
        "--remap",
        "/tf:=/robot1/tf",
        "--topic",
        "/robot/**",
        "--msg-path",
        msgs.to_str().unwrap(),
    ];
    let ran = run_scaledp(&args, dir.path());
    done.store(true, Ordering::Relaxed);
    feeder.join().unwrap();
    sim.stop();
    session.close().wait().unwrap();
    cli_ok(&ran, "scaledp record");
    let path = out.join("episode_000000.mcap");
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let channels: BTreeMap<&str, (&str, String)> = summary
        .channels
        .values()
        .map(|c| {
            let schema = c.schema.as_ref().unwrap();
            (
                c.topic.as_str(),
                (
                    schema.name.as_str(),
                    String::from_utf8(schema.data.to_vec()).unwrap(),
                ),
            )
        })
        .collect();
    let counts: BTreeMap<String, u64> = summary
        .stats
        .as_ref()
        .map(|s| {
            s.channel_message_counts
                .iter()
                .map(|(id, n)| (summary.channels[id].topic.clone(), *n))
                .collect()
        })
        .unwrap();
    // The rig under its remapped names.
    assert_eq!(channels["/robot1/tf"].0, "tf2_msgs/msg/TFMessage");
    assert!(!channels.contains_key("/tf"));
    assert!(
        counts["/robot1/tf"] > 0 && counts["/tf_static"] > 0,
        "{counts:?}"
    );
    let stored = episode_metadata(&path)["rig"].clone();
    assert!(stored.contains("topic = \"/robot1/tf\""), "{stored}");
    // The glob's topics: the type from the rmw key, the definition from --msg-path (rosbag2's
    // composition: the file verbatim, then its dependency), or an empty one.
    let (ty, text) = &channels["/robot/status"];
    assert_eq!(*ty, "my_msgs/msg/Status");
    assert!(
        text.starts_with("# A robot's status\nstd_msgs/Header header\nstring text\n\n")
            && text.contains("MSG: std_msgs/Header\n"),
        "{text}"
    );
    assert_eq!(
        channels["/robot/odd"],
        ("other_msgs/msg/Unknown", String::new())
    );
    assert!(
        counts["/robot/status"] > 10 && counts["/robot/odd"] > 10,
        "{counts:?}"
    );
}
