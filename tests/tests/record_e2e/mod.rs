//! Simulated rig → Zenoh (loopback) → recorder → MCAP, checked message by message against what
//! the simulator published, by the Rust `mcap` crate and by two Python ROS 2 readers.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use scaledp_recorder::{
    net, now_ns, Command, EpisodeReport, Event, Label, Recorder, RecorderOptions,
};
use scaledp_schema::msg::{header_stamp, Image, JointState};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::{KeyStyle, SimOptions};
use scaledp_tests::{episode_metadata, free_endpoint, run_python, small_bimanual, small_franka};
use sha2::{Digest, Sha256};

type Published = Arc<Mutex<HashMap<String, Vec<Vec<u8>>>>>;

/// Waits (bounded) until every topic of the recorder has delivered a message.
fn wait_live(recorder: &Recorder) {
    let deadline = Instant::now() + Duration::from_secs(15);
    while recorder.status().topics.iter().any(|t| t.received == 0) {
        assert!(
            Instant::now() < deadline,
            "topics never went live: {:?}",
            recorder.status().topics
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits (bounded) for the next finished episode.
fn next_finished(recorder: &Recorder) -> EpisodeReport {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let left = deadline
            .checked_duration_since(Instant::now())
            .expect("no episode finished within 30 s");
        match recorder.events().recv_timeout(left) {
            Ok(Event::Finished(r)) => return r,
            Ok(Event::Failed { error, .. }) => panic!("episode failed: {error}"),
            Ok(_) => {}
            Err(e) => panic!("no episode finished: {e}"),
        }
    }
}

struct Run {
    report: EpisodeReport,
    published: HashMap<String, Vec<Vec<u8>>>,
    /// Wall clock (ns) just before `start` was sent and just after the episode finished.
    wall_ns: (u64, u64),
    _dir: tempfile::TempDir,
}

/// Records one episode of `seconds` from a simulated `rig`.
fn record_one(rig: Rig, keys: KeyStyle, seconds: f64) -> Run {
    let endpoint = free_endpoint();
    let sim_session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let published: Published = Arc::default();
    let sink = published.clone();
    let sim = SimOptions::new(rig.clone())
        .seed(3)
        .keys(keys)
        .on_publish(Arc::new(move |topic, payload| {
            sink.lock()
                .unwrap()
                .entry(topic.to_string())
                .or_default()
                .push(payload.to_vec());
        }))
        .spawn(&sim_session)
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let recorder = RecorderOptions::new(rig, dir.path())
        .task("pick up the red cube")
        .operator("test")
        .control_prefix(format!("test/{}", std::process::id()))
        .start(net::zenoh_config(None, &[endpoint], &[]).unwrap())
        .unwrap();
    wait_live(&recorder);
    let before = now_ns();
    recorder.send(Command::Start);
    std::thread::sleep(Duration::from_secs_f64(seconds));
    recorder.send(Command::Stop(Label::Success));
    let report = next_finished(&recorder);
    let after = now_ns();
    recorder.finish().unwrap();
    sim.stop();
    let published = std::mem::take(&mut *published.lock().unwrap());
    Run {
        report,
        published,
        wall_ns: (before, after),
        _dir: dir,
    }
}

/// Per topic: (payload, log_time, publish_time) in file order, read with the Rust mcap crate.
fn read_rust(path: &Path) -> BTreeMap<String, Vec<(Vec<u8>, u64, u64)>> {
    let bytes = std::fs::read(path).unwrap();
    let mut out: BTreeMap<String, Vec<_>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        out.entry(m.channel.topic.clone()).or_default().push((
            m.data.to_vec(),
            m.log_time,
            m.publish_time,
        ));
    }
    out
}

/// `ns` since the epoch as the recorder writes it: RFC 3339, UTC, milliseconds
/// (`2023-11-14T22:13:20.000Z`), from the civil-from-days algorithm.
fn rfc3339_millis(ns: u64) -> String {
    let secs = ns / 1_000_000_000;
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60,
        ns / 1_000_000 % 1000
    )
}

fn sha(b: &[u8]) -> String {
    Sha256::digest(b)
        .iter()
        .map(|x| format!("{x:02x}"))
        .collect()
}

/// Every recorded message equals a published one, in order, with none missing in between.
fn assert_contiguous(run: &Run, path: &Path) -> BTreeMap<String, Vec<(Vec<u8>, u64, u64)>> {
    let recorded = read_rust(path);
    for (topic, msgs) in &recorded {
        let sent = &run.published[topic];
        let first = sent
            .iter()
            .position(|p| *p == msgs[0].0)
            .unwrap_or_else(|| panic!("{topic}: first message never published"));
        for (k, (data, log_time, publish_time)) in msgs.iter().enumerate() {
            assert!(
                sent.get(first + k) == Some(data),
                "{topic}: message {k} differs from what was published (a gap or a corruption)"
            );
            let stamp = header_stamp(data).unwrap().as_ns();
            assert_eq!(
                *publish_time, stamp,
                "{topic}: publish_time must be the header stamp"
            );
            assert!(
                log_time > publish_time,
                "{topic}: received before it was captured?"
            );
        }
    }
    recorded
}

#[test]
fn recorded_episode_is_what_the_sim_published_and_ros2_tools_read_it() {
    let rig = small_franka();
    let run = record_one(rig.clone(), KeyStyle::Bridge, 2.0);
    let path = run.report.summary.path.clone();
    assert!(path.ends_with("episode_000000.mcap"), "{}", path.display());
    let recorded = assert_contiguous(&run, &path);
    assert_eq!(recorded.len(), 4, "every topic recorded");
    // Contiguous (above) means nothing the simulator published in between was lost; the
    // episode must also span the recording's whole duration. The message count is not a
    // check: the simulator's own rate sags on a loaded machine (1,612 joint states in 2 s
    // against the rig's 1 kHz, every one recorded).
    for t in rig.topics() {
        let msgs = &recorded[&t.topic];
        let span_s = (msgs[msgs.len() - 1].2 - msgs[0].2) as f64 * 1e-9;
        let d = run.report.duration_s;
        assert!(
            (span_s - d).abs() <= d * 0.15 + 2.0 / t.rate_hz,
            "{}: {} messages over {span_s:.3} s of an episode of {d:.3} s",
            t.topic,
            msgs.len()
        );
        assert_eq!(run.report.dropped[&t.topic], 0);
    }

    let py = run_python("read_mcap.py", &[&path]);
    assert_eq!(py["header"]["profile"], "ros2");
    for c in py["channels"].as_array().unwrap() {
        let topic = c["topic"].as_str().unwrap();
        let spec = rig.topics().into_iter().find(|t| t.topic == topic).unwrap();
        assert_eq!(c["message_encoding"], "cdr");
        assert_eq!(c["schema_encoding"], "ros2msg");
        assert_eq!(c["schema_name"], spec.message_type);
        assert_eq!(
            c["schema_data"].as_str().unwrap(),
            scaledp_schema::msg::definition(&spec.message_type).unwrap()
        );
        assert!(c["metadata"]["offered_qos_profiles"]
            .as_str()
            .unwrap()
            .contains("reliability"));
    }
    let meta = &py["metadata"]["scaledp.episode"];
    assert_eq!(meta["outcome"], "success");
    assert_eq!(meta["task"], "pick up the red cube");
    assert_eq!(meta["rig_name"], "franka_2zed");
    assert_eq!(meta["operator"], "test");
    assert_eq!(meta["episode_index"], "0");
    let version = meta["recorder_version"].as_str().unwrap();
    assert_eq!(version, env!("CARGO_PKG_VERSION"), "one workspace version");
    assert_eq!(
        py["header"]["library"],
        format!("scaledp-recorder {version}")
    );
    // Start and end: inside the test's own clock window, in order, after every message was
    // received, and the readable forms agree with the nanosecond ones.
    let ns = |k: &str| meta[k].as_str().unwrap().parse::<u64>().unwrap();
    let (start, end) = (ns("start_time_ns"), ns("end_time_ns"));
    let (before, after) = run.wall_ns;
    assert!(
        before <= start && start < end && end <= after,
        "{before} {start} {end} {after}"
    );
    assert_eq!(meta["start_time"], rfc3339_millis(start));
    assert_eq!(meta["end_time"], rfc3339_millis(end));
    let duration: f64 = meta["duration_s"].as_str().unwrap().parse().unwrap();
    assert!((duration - run.report.duration_s).abs() <= 5e-4);
    let last_log = recorded.values().flatten().map(|m| m.1).max().unwrap();
    assert!(start < last_log && last_log <= end);
    // The start record (what a crashed episode keeps) agrees with the final one.
    let start_meta = py["metadata"]["scaledp.episode.start"].as_object().unwrap();
    for key in [
        "episode_index",
        "task",
        "operator",
        "rig_name",
        "rig",
        "start_time_ns",
        "start_time",
        "recorder_version",
    ] {
        assert_eq!(start_meta[key], meta[key], "{key}");
    }
    assert!(!start_meta.contains_key("outcome"));
    let counts: BTreeMap<String, usize> =
        serde_json::from_str(meta["message_counts"].as_str().unwrap()).unwrap();
    let dropped: BTreeMap<String, u64> =
        serde_json::from_str(meta["dropped"].as_str().unwrap()).unwrap();
    for (topic, msgs) in &recorded {
        assert_eq!(counts[topic], msgs.len());
        assert_eq!(dropped[topic], 0);
    }

    // Both Python readers see every message, byte-identical, with the fields the sim set.
    let total: usize = recorded.values().map(Vec::len).sum();
    let by_hash: HashMap<String, &Vec<u8>> = recorded
        .values()
        .flatten()
        .map(|(d, _, _)| (sha(d), d))
        .collect();
    for reader in ["mcap_ros2", "rosbags"] {
        let msgs = py[reader].as_array().unwrap();
        assert_eq!(msgs.len(), total, "{reader} message count");
        for m in msgs {
            let data = by_hash
                .get(m["sha256"].as_str().unwrap())
                .unwrap_or_else(|| panic!("{reader}: unknown payload"));
            assert_eq!(
                m["stamp_ns"].as_u64().unwrap(),
                header_stamp(data).unwrap().as_ns()
            );
            if m["topic"].as_str().unwrap().contains("image") {
                let img = Image::from_cdr(data).unwrap();
                assert_eq!(m["encoding"], "bgra8");
                assert_eq!(
                    (m["width"].as_u64(), m["height"].as_u64()),
                    (Some(64), Some(48))
                );
                assert_eq!(m["step"].as_u64(), Some(u64::from(img.step)));
                assert_eq!(m["data_len"].as_u64(), Some(img.data.len() as u64));
            } else {
                let js = JointState::from_cdr(data).unwrap();
                assert_eq!(m["name"].as_array().unwrap().len(), js.name.len());
                let pos: Vec<f64> = m["position"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|x| x.as_f64().unwrap())
                    .collect();
                assert_eq!(pos, js.position);
            }
        }
    }
}

mod control;
