//! Simulated rig → Zenoh (loopback) → recorder → MCAP, checked message by message against what
//! the simulator published, by the Rust `mcap` crate and by two Python ROS 2 readers.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use scaledp::sim::{KeyStyle, SimOptions};
use scaledp_recorder::{net, Command, EpisodeReport, Event, Outcome, Recorder, RecorderOptions};
use scaledp_schema::msg::{header_stamp, Image, JointState};
use scaledp_schema::{Rig, RosMessage};
use scaledp_tests::{free_endpoint, run_python, small_bimanual, small_franka};
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
            Ok(Event::Started { .. }) => {}
            Err(e) => panic!("no episode finished: {e}"),
        }
    }
}

struct Run {
    report: EpisodeReport,
    published: HashMap<String, Vec<Vec<u8>>>,
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
    recorder.send(Command::Start);
    std::thread::sleep(Duration::from_secs_f64(seconds));
    recorder.send(Command::Stop(Outcome::Success));
    let report = next_finished(&recorder);
    recorder.finish().unwrap();
    sim.stop();
    let published = std::mem::take(&mut *published.lock().unwrap());
    Run {
        report,
        published,
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
    for t in rig.topics() {
        let n = recorded[&t.topic].len() as f64;
        let expected = t.rate_hz * run.report.duration_s;
        assert!(
            (n - expected).abs() <= expected * 0.15 + 2.0,
            "{}: {n} messages, expected ≈ {expected}",
            t.topic
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
            scaledp_schema::msg::definition(spec.message_type).unwrap()
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

#[test]
fn rmw_zenoh_keys_are_recorded_too() {
    let rig = small_bimanual();
    let run = record_one(rig.clone(), KeyStyle::Rmw, 1.5);
    let recorded = assert_contiguous(&run, &run.report.summary.path);
    assert_eq!(recorded.len(), rig.topics().len());
    assert!(
        run.report.upstream_gaps.values().all(|g| *g == 0),
        "{:?}",
        run.report.upstream_gaps
    );
    let img = Image::from_cdr(&recorded["/cam_high/camera/color/image_raw"][0].0).unwrap();
    assert_eq!(img.encoding, "rgb8");
}

fn episode_metadata(path: &Path) -> BTreeMap<String, String> {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .unwrap()
        .expect("a summary section");
    let idx = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == "scaledp.episode")
        .expect("scaledp.episode");
    mcap::read::metadata(&bytes, idx).unwrap().metadata
}

#[test]
fn zenoh_control_key_starts_stops_and_discards_episodes() {
    use zenoh::Wait;
    let rig = small_franka();
    let endpoint = free_endpoint();
    let sim_session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let sim = SimOptions::new(rig.clone()).spawn(&sim_session).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let prefix = format!("lab/pedal{}", std::process::id());
    let recorder = RecorderOptions::new(rig, dir.path())
        .task("t")
        .control_prefix(&prefix)
        .start(net::zenoh_config(None, std::slice::from_ref(&endpoint), &[]).unwrap())
        .unwrap();
    wait_live(&recorder);
    // A separate session plays the foot pedal.
    let pedal = net::open(net::zenoh_config(None, &[endpoint], &[]).unwrap()).unwrap();
    let statuses = Arc::new(Mutex::new(Vec::new()));
    let sink = statuses.clone();
    let _sub = pedal
        .declare_subscriber(format!("{prefix}/status"))
        .callback(move |s| {
            sink.lock()
                .unwrap()
                .push(String::from_utf8_lossy(&s.payload().to_bytes()).into_owned())
        })
        .wait()
        .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let mut paths = Vec::new();
    for end in ["stop", "discard", "failure"] {
        // Repeat `start` until the recorder opens the episode (the pedal's link may be new).
        let deadline = Instant::now() + Duration::from_secs(10);
        while recorder.status().episode.is_none() {
            assert!(Instant::now() < deadline, "start over zenoh was not obeyed");
            pedal
                .put(format!("{prefix}/control"), "start")
                .wait()
                .unwrap();
            std::thread::sleep(Duration::from_millis(100));
        }
        std::thread::sleep(Duration::from_millis(500));
        pedal.put(format!("{prefix}/control"), end).wait().unwrap();
        paths.push(next_finished(&recorder));
    }
    recorder.finish().unwrap();
    sim.stop();
    let want: [(PathBuf, &str); 3] = [
        (dir.path().join("episode_000000.mcap"), "unlabeled"),
        (
            dir.path().join("discarded/episode_000001.mcap"),
            "discarded",
        ),
        (dir.path().join("episode_000002.mcap"), "failure"),
    ];
    for ((path, outcome), report) in want.iter().zip(&paths) {
        assert_eq!(&report.summary.path, path);
        assert_eq!(episode_metadata(path)["outcome"], *outcome);
        assert!(report.summary.messages.values().all(|n| *n > 0));
    }
    assert!(!dir.path().join("episode_000001.mcap").exists());
    let statuses = statuses.lock().unwrap();
    assert_eq!(
        statuses
            .iter()
            .filter(|s| s.contains("\"finished\""))
            .count(),
        3,
        "{statuses:?}"
    );
}
