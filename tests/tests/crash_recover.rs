//! `kill -9` a recording `scaledp record` process mid-episode, then `scaledp recover`: the file
//! opens in ROS 2 tools and at most the last second of messages is gone. And a command whose
//! stdout reader has gone (`scaledp … | head`) ends quietly.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::process::{Command, Stdio};
use std::time::Duration;

use scaledp_recorder::{net, now_ns};
use scaledp_sim::SimOptions;
use scaledp_tests::{free_endpoint, run_python, scaledp_bin, small_franka};

#[test]
fn kill_9_then_recover_loses_at_most_one_second() {
    let rig = small_franka();
    let endpoint = free_endpoint();
    let sim_session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let sim = SimOptions::new(rig.clone())
        .seed(9)
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
            "crash test",
            "--duration",
            "60",
            "--no-keyboard",
            "-q",
            "--connect",
            &endpoint,
        ])
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
    child.kill().unwrap(); // SIGKILL: no destructor, no flush, no rename
    let killed_ns = now_ns();
    child.wait().unwrap();
    sim.stop();
    assert!(
        partial.exists(),
        "the episode must still be a .partial file"
    );

    let status = Command::new(scaledp_bin())
        .arg("recover")
        .arg(&partial)
        .status()
        .unwrap();
    assert!(
        matches!(status.code(), Some(0 | 3)),
        "recover exited with {status}"
    );
    let fixed = out.join("episode_000000.mcap");
    let py = run_python("read_mcap.py", &[&fixed]);
    assert_eq!(py["header"]["profile"], "ros2");
    assert_eq!(
        py["metadata"]["scaledp.episode.start"]["task"],
        "crash test"
    );
    let rosbags = py["rosbags"].as_array().unwrap();
    assert_eq!(rosbags.len(), py["mcap_ros2"].as_array().unwrap().len());
    let last = rosbags
        .iter()
        .map(|m| m["log_time"].as_u64().unwrap())
        .max()
        .unwrap();
    let lost_s = killed_ns.saturating_sub(last) as f64 * 1e-9;
    assert!(lost_s <= 1.0, "lost the last {lost_s:.3} s (more than 1 s)");
    for topic in rig.topics() {
        assert!(
            rosbags.iter().any(|m| m["topic"] == topic.topic),
            "{} missing",
            topic.topic
        );
    }
}

/// `scaledp recover … | head -0`: stdout's reader gone before the summary line, the command
/// still finishes its work and exits 0, with no panic on stderr.
#[test]
fn a_closed_stdout_ends_a_command_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.mcap");
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(&input).unwrap(),
    ))
    .unwrap();
    let schema = w
        .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
        .unwrap();
    let ch = w
        .add_channel(schema, "/chatter", "cdr", &Default::default())
        .unwrap();
    for k in 0..10u64 {
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: k as u32,
            log_time: 1_000 + k,
            publish_time: 1_000 + k,
        };
        w.write_to_known_channel(&header, &[0, 1, 0, 0, 1, 0, 0, 0, 0])
            .unwrap();
    }
    w.finish().unwrap();
    drop(w);
    let output = dir.path().join("out.mcap");
    let mut child = Command::new(scaledp_bin())
        .arg("recover")
        .arg(&input)
        .arg("--output")
        .arg(&output)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The reader goes away at once: the summary line meets a closed pipe.
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(output.exists());
}
