//! Everything a camera rig publishes, recorded by name: the simulator publishes as
//! realsense2_camera 4.x and the ZED wrapper v5 and v4 do (colour, registered depth, both
//! camera_infos, /tf, and /tf_static once at startup, served to late joiners from a cache as
//! zenoh-bridge-ros2dds or rmw_zenoh serve it), and a recorder that joins after /tf_static was
//! published writes all of it into every episode of a session, over both key styles. A peer
//! that restarts mid-session costs an outage the episode counts, nothing else; depth in an
//! encoding the rig does not declare and a /tf_static that never comes are named in each
//! episode, every stream still recorded.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use scaledp_recorder::{net, Command, EpisodeReport, Event, Label, Recorder, RecorderOptions};
use scaledp_schema::msg::{camera_info_size, image_layout, TfMessage};
use scaledp_schema::rig::{DepthEncoding, TopicKind};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::{KeyStyle, LatchedCache, Sim, SimOptions};
use scaledp_tests::{episode_metadata, free_endpoint, full_rig};
use zenoh::Wait;

/// Per topic: (log_time, publish_time, payload), in file order.
type Recorded = BTreeMap<String, Vec<(u64, u64, Vec<u8>)>>;

fn read(path: &std::path::Path) -> Recorded {
    let bytes = std::fs::read(path).unwrap();
    let mut out: Recorded = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        out.entry(m.channel.topic.clone()).or_default().push((
            m.log_time,
            m.publish_time,
            m.data.to_vec(),
        ));
    }
    out
}

/// A session listening on `endpoint` (retried: right after a close the port may be held).
fn listen(endpoint: &str) -> zenoh::Session {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let config = net::zenoh_config(None, &[], &[endpoint.to_string()]).unwrap();
        match net::open(config) {
            Ok(s) => return s,
            Err(e) if Instant::now() < deadline => {
                eprintln!("listening on {endpoint}: {e}; again");
                std::thread::sleep(Duration::from_millis(200));
            }
            Err(e) => panic!("{e}"),
        }
    }
}

fn sim(rig: &Rig, keys: KeyStyle, cache: Option<LatchedCache>, session: &zenoh::Session) -> Sim {
    let opts = SimOptions::new(rig.clone()).seed(1).keys(keys);
    match cache {
        Some(c) => opts.latched_cache(c),
        None => opts,
    }
    .spawn(session)
    .unwrap()
}

fn recorder(rig: Rig, out: &std::path::Path, endpoint: &str) -> Recorder {
    RecorderOptions::new(rig, out)
        .task("t")
        .flush_interval(Duration::from_millis(100))
        .control_prefix(format!("test/topics{}", std::process::id()))
        .start(net::zenoh_config(None, &[endpoint.to_string()], &[]).unwrap())
        .unwrap()
}

/// Waits (bounded) until every rig topic has delivered a message.
fn wait_live(recorder: &Recorder, rig: &Rig) {
    let deadline = Instant::now() + Duration::from_secs(30);
    let n = rig.topics().len();
    loop {
        let silent: Vec<String> = recorder.status().topics[..n]
            .iter()
            .filter(|t| t.received == 0)
            .map(|t| t.topic.clone())
            .collect();
        if silent.is_empty() {
            return;
        }
        assert!(Instant::now() < deadline, "never arrived: {silent:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn next_finished(recorder: &Recorder) -> EpisodeReport {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let left = deadline
            .checked_duration_since(Instant::now())
            .expect("no episode finished within 30 s");
        match recorder.events().recv_timeout(left).unwrap() {
            Event::Finished(r) => return r,
            Event::Failed { error, .. } => panic!("episode failed: {error}"),
            _ => {}
        }
    }
}

fn episode(recorder: &Recorder, seconds: f64) -> EpisodeReport {
    recorder.send(Command::Start);
    std::thread::sleep(Duration::from_secs_f64(seconds));
    recorder.send(Command::Stop(Label::Success));
    next_finished(recorder)
}

/// Every rig topic is in the episode; /tf_static first, written at the episode's start with the
/// stamp it was published with; depth in the rig's encoding; camera_info the images' size.
fn check_episode(rig: &Rig, r: &EpisodeReport, what: &str) {
    let recorded = read(&r.summary.path);
    let start_ns: u64 = episode_metadata(&r.summary.path)["start_time_ns"]
        .parse()
        .unwrap();
    for t in rig.topics() {
        let msgs = recorded
            .get(&t.topic)
            .unwrap_or_else(|| panic!("{what}: episode {} has no {}", r.index, t.topic));
        match t.kind {
            TopicKind::TfStatic => {
                let (log, publish, data) = &msgs[0];
                assert_eq!(*log, start_ns, "{what}: /tf_static at the episode's start");
                let tf = TfMessage::from_cdr(data).unwrap();
                assert_eq!(*publish, tf.transforms[0].header.stamp.as_ns(), "{what}");
                assert!(tf
                    .transforms
                    .iter()
                    .any(|x| x.child_frame_id.ends_with("optical_frame")));
            }
            TopicKind::Depth => {
                let cam = rig.cameras.iter().find(|c| c.name == t.owner).unwrap();
                let want = cam.depth.as_ref().unwrap().encoding;
                for (_, _, data) in msgs {
                    assert_eq!(
                        image_layout(data).unwrap().encoding,
                        want.as_str(),
                        "{what}"
                    );
                }
            }
            TopicKind::CameraInfo => {
                let cam = rig.cameras.iter().find(|c| c.name == t.owner).unwrap();
                let size = camera_info_size(&msgs[0].2).unwrap();
                assert_eq!(size, (cam.height, cam.width), "{what}: {}", t.topic);
            }
            _ => {}
        }
    }
    assert_eq!(r.latched_at_start["/tf_static"], 1, "{what}");
    assert!(r.warnings.is_empty(), "{what}: {:?}", r.warnings);
}

/// realsense2_camera 4.x, the ZED wrapper v5 and v4, over both key styles, each latched cache
/// kind: three episodes each, the recorder started after /tf_static went out.
#[test]
fn camera_rigs_record_depth_camera_info_and_tf_static_in_every_episode() {
    let cases = [
        ("bimanual_ur5_3rs", KeyStyle::Bridge, None),
        ("bimanual_ur5_3rs", KeyStyle::Rmw, None),
        ("franka_2zed", KeyStyle::Rmw, None),
        (
            "franka_2zed",
            KeyStyle::Bridge,
            Some(LatchedCache::Advanced),
        ),
        ("franka_2zed_v4", KeyStyle::Bridge, None),
        ("franka_2zed_v4", KeyStyle::Rmw, None),
    ];
    for (name, keys, cache) in cases {
        let what = format!("{name} {keys:?} {cache:?}");
        let rig = full_rig(name, 32, 24);
        let endpoint = free_endpoint();
        let sim_session = listen(&endpoint);
        let sim = sim(&rig, keys, cache, &sim_session);
        // /tf_static is out before the recorder exists.
        std::thread::sleep(Duration::from_millis(300));
        let dir = tempfile::tempdir().unwrap();
        let recorder = recorder(rig.clone(), dir.path(), &endpoint);
        wait_live(&recorder, &rig);
        for _ in 0..3 {
            let r = episode(&recorder, 0.5);
            check_episode(&rig, &r, &what);
        }
        recorder.finish().unwrap();
        sim.stop();
        sim_session.close().wait().unwrap();
    }
}

/// The simulator stops mid-episode and comes back on the same endpoint: the episode goes on
/// with the messages from before and after, counts the outage, and the restarted simulator's
/// /tf_static (served from its cache to the recorder that reconnects) opens the next episode.
#[test]
fn a_restarted_peer_costs_an_outage_the_episode_counts() {
    for keys in [KeyStyle::Bridge, KeyStyle::Rmw] {
        let rig = full_rig("franka_2zed_v4", 32, 24);
        let endpoint = free_endpoint();
        let first = listen(&endpoint);
        let sim_a = sim(&rig, keys, None, &first);
        let dir = tempfile::tempdir().unwrap();
        let recorder = recorder(rig.clone(), dir.path(), &endpoint);
        wait_live(&recorder, &rig);
        let tf_static_before = recorder
            .status()
            .topics
            .iter()
            .find(|t| t.topic == "/tf_static")
            .unwrap()
            .received;
        recorder.send(Command::Start);
        std::thread::sleep(Duration::from_millis(500));
        sim_a.stop();
        first.close().wait().unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        while recorder.zenoh_links() > 0 {
            assert!(
                Instant::now() < deadline,
                "{keys:?}: the lost link was never noticed"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_millis(300));
        let second = listen(&endpoint);
        let sim_b = sim(&rig, keys, None, &second);
        let deadline = Instant::now() + Duration::from_secs(30);
        let tf_static = || {
            recorder
                .status()
                .topics
                .iter()
                .find(|t| t.topic == "/tf_static")
                .unwrap()
                .received
        };
        while recorder.zenoh_links() == 0 || tf_static() == tf_static_before {
            assert!(
                Instant::now() < deadline,
                "{keys:?}: the restarted peer's /tf_static never came"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_millis(500));
        recorder.send(Command::Stop(Label::Success));
        let r = next_finished(&recorder);
        assert_eq!(r.link_outages, 1, "{keys:?}: {r:?}");
        assert!(r.link_outage_s > 0.2, "{keys:?}: {}", r.link_outage_s);
        let recorded = read(&r.summary.path);
        let color = &recorded[&rig.cameras[0].topic];
        let gap = color.windows(2).map(|w| w[1].0 - w[0].0).max().unwrap();
        assert!(
            gap > 200_000_000,
            "{keys:?}: an outage shows as a gap ({gap} ns)"
        );
        assert!(
            color.len() > 20,
            "{keys:?}: before and after ({})",
            color.len()
        );
        let meta = episode_metadata(&r.summary.path);
        assert_eq!(meta["link_outages"], "1");
        let first_stamp = recorded["/tf_static"][0].1;
        // The next episode opens with the restarted peer's /tf_static.
        let next = episode(&recorder, 0.4);
        let statics = &read(&next.summary.path)["/tf_static"];
        let restarted_stamp = statics.iter().map(|m| m.1).max().unwrap();
        assert!(
            restarted_stamp > first_stamp,
            "{keys:?}: the restarted peer's"
        );
        assert_eq!(next.link_outages, 0);
        check_tf_static_stamps(statics, keys);
        recorder.finish().unwrap();
        sim_b.stop();
        second.close().wait().unwrap();
    }
}

/// Behind rmw_zenoh a publisher's gid says the restarted one replaces the first; a bridge
/// gives none, so both messages are kept (each distinct message counts as a publisher).
fn check_tf_static_stamps(statics: &[(u64, u64, Vec<u8>)], keys: KeyStyle) {
    let at_start = statics.iter().filter(|m| m.0 == statics[0].0).count();
    match keys {
        KeyStyle::Rmw => assert_eq!(at_start, 1, "{statics:?}"),
        KeyStyle::Bridge => assert_eq!(at_start, 2),
    }
}

/// The recorder's rig says 16UC1 and /tf_static; the cameras publish 32FC1 and no /tf_static
/// comes: every episode names both in one line each and holds every stream all the same.
#[test]
fn undeclared_depth_and_a_missing_tf_static_are_named_in_every_episode() {
    let declared = full_rig("franka_2zed", 32, 24);
    let mut published = declared.clone();
    published.tf.as_mut().unwrap().static_ = false;
    let mut rig = declared.clone();
    for c in &mut rig.cameras {
        c.depth.as_mut().unwrap().encoding = DepthEncoding::U16Millimetres;
    }
    let endpoint = free_endpoint();
    let session = listen(&endpoint);
    let sim = sim(&published, KeyStyle::Bridge, None, &session);
    let dir = tempfile::tempdir().unwrap();
    let recorder = recorder(rig.clone(), dir.path(), &endpoint);
    let deadline = Instant::now() + Duration::from_secs(20);
    while recorder
        .status()
        .topics
        .iter()
        .filter(|t| t.received == 0)
        .count()
        > 1
    {
        assert!(Instant::now() < deadline, "{:?}", recorder.status().topics);
        std::thread::sleep(Duration::from_millis(20));
    }
    for _ in 0..2 {
        let r = episode(&recorder, 0.5);
        let depth = &rig.cameras[0].depth.as_ref().unwrap().topic;
        let want = [
            format!("{depth}: depth in 32FC1, the rig declares 16UC1"),
            "/tf_static: nothing latched at the start of the episode".to_string(),
        ];
        for w in &want {
            assert!(
                r.warnings.iter().any(|x| x.starts_with(w)),
                "{w}: {:?}",
                r.warnings
            );
        }
        assert_eq!(
            r.warnings.len(),
            3,
            "two depth topics and /tf_static: {:?}",
            r.warnings
        );
        for t in rig
            .topics()
            .iter()
            .filter(|t| t.kind != TopicKind::TfStatic)
        {
            assert!(r.summary.messages[&t.topic] > 0, "{} kept", t.topic);
        }
        let stored: Vec<String> =
            serde_json::from_str(&episode_metadata(&r.summary.path)["warnings"]).unwrap();
        assert_eq!(stored, r.warnings);
    }
    recorder.finish().unwrap();
    sim.stop();
    session.close().wait().unwrap();
}
