//! Latched topics (`/tf_static`) reach a recorder that joins after they were published, from
//! each kind of publisher cache a ROS 2 system behind Zenoh has: rmw_zenoh's (a zenoh-ext
//! AdvancedPublisher with a cache, also zenoh-bridge-ros2dds from 1.5.1) and the
//! `@ros2_pub_cache` queryable of zenoh-bridge-ros2dds up to 1.5.0. Each episode of the session
//! starts with them. What the recorder notices in the cameras' streams is named in one line,
//! recorded as it is, and never stops the other streams.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use scaledp_recorder::keys::{self, RmwAttachment};
use scaledp_recorder::{net, Command, EpisodeReport, Event, Label, Recorder, RecorderOptions};
use scaledp_schema::msg::{
    CameraInfo, Header, Image, TfMessage, Time, Transform, TransformStamped,
};
use scaledp_schema::{Rig, RosMessage};
use zenoh::query::Query;
use zenoh::Wait;
use zenoh_ext::{AdvancedPublisherBuilderExt, CacheConfig};

fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

fn tf_static(stamp_ns: u64) -> Vec<u8> {
    TfMessage {
        transforms: vec![TransformStamped {
            header: Header {
                stamp: Time::from_ns(stamp_ns),
                frame_id: "world".into(),
            },
            child_frame_id: "fr3_link0".into(),
            transform: Transform::default(),
        }],
    }
    .to_cdr()
}

/// A rig with one camera (depth and camera_info) and `[tf]`.
fn rig() -> Rig {
    let mut rig = Rig::builtin("franka_2zed").unwrap();
    rig.cameras.truncate(1);
    rig.arms.clear();
    rig
}

fn recorder(endpoint: &str, out: &std::path::Path, rig: Rig) -> Recorder {
    RecorderOptions::new(rig, out)
        .task("t")
        .flush_interval(Duration::from_millis(100))
        .control_prefix(format!("test/latched{}", std::process::id()))
        .start(net::zenoh_config(None, &[endpoint.to_string()], &[]).unwrap())
        .unwrap()
}

fn next_finished(recorder: &Recorder) -> EpisodeReport {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline
            .checked_duration_since(Instant::now())
            .expect("no episode finished within 20 s");
        match recorder.events().recv_timeout(left).unwrap() {
            Event::Finished(r) => return r,
            Event::Failed { error, .. } => panic!("{error}"),
            _ => {}
        }
    }
}

/// Waits (bounded) until `topic` has delivered `n` messages.
fn wait_received(recorder: &Recorder, topic: &str, n: u64) {
    let deadline = Instant::now() + Duration::from_secs(15);
    loop {
        let got = recorder
            .status()
            .topics
            .iter()
            .find(|t| t.topic == topic)
            .map_or(0, |t| t.received);
        if got >= n {
            return;
        }
        assert!(Instant::now() < deadline, "{topic}: {got} of {n} messages");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Per topic: (log_time, publish_time, payload).
fn read(path: &std::path::Path) -> BTreeMap<String, Vec<(u64, u64, Vec<u8>)>> {
    let bytes = std::fs::read(path).unwrap();
    let mut out: BTreeMap<String, Vec<_>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        out.entry(m.channel.topic.clone()).or_default().push((
            m.log_time,
            m.publish_time,
            m.data.to_vec(),
        ));
        if m.channel.topic == "/tf_static" {
            let qos = &m.channel.metadata["offered_qos_profiles"];
            assert!(qos.contains("durability: 1"), "transient local: {qos}");
        }
    }
    out
}

/// Two episodes; each must start with the latched message (log_time = its start).
fn two_episodes_hold(recorder: &Recorder, payload: &[u8], stamp_ns: u64) {
    for _ in 0..2 {
        recorder.send(Command::Start);
        std::thread::sleep(Duration::from_millis(300));
        recorder.send(Command::Stop(Label::Success));
        let r = next_finished(recorder);
        assert_eq!(r.latched_at_start["/tf_static"], 1, "{r:?}");
        assert!(
            r.warnings.iter().all(|w| !w.contains("/tf_static")),
            "{r:?}"
        );
        let msgs = &read(&r.summary.path)["/tf_static"];
        assert_eq!(msgs.len(), 1, "episode {}", r.index);
        let (log, publish, data) = &msgs[0];
        assert_eq!(data.as_slice(), payload);
        assert_eq!(*publish, stamp_ns, "publish_time = the transform's stamp");
        let meta = scaledp_schema::episode::START_RECORD;
        let bytes = std::fs::read(&r.summary.path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let start = summary
            .metadata_indexes
            .iter()
            .find(|m| m.name == meta)
            .map(|m| mcap::read::metadata(&bytes, m).unwrap().metadata)
            .unwrap();
        assert_eq!(
            log.to_string(),
            start["start_time_ns"],
            "log_time = episode start"
        );
    }
}

#[test]
fn rmw_zenoh_latched_topics_come_from_the_publishers_cache() {
    let endpoint = free_endpoint();
    let peer =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let key = keys::rmw_key(0, "/tf_static", "tf2_msgs/msg/TFMessage", "RIHS01_00");
    let publisher = peer
        .declare_publisher(key)
        .cache(CacheConfig::default().max_samples(1))
        .publisher_detection()
        .wait()
        .unwrap();
    let stamp = 1_700_000_000_000_000_000;
    let payload = tf_static(stamp);
    let att = RmwAttachment {
        sequence_number: 1,
        source_timestamp_ns: 5,
        source_gid: vec![9; 16],
    };
    publisher
        .put(payload.clone())
        .attachment(att.to_zbytes())
        .wait()
        .unwrap();
    // Published before anyone listened: only the cache has it.
    let dir = tempfile::tempdir().unwrap();
    let recorder = recorder(&endpoint, dir.path(), rig());
    wait_received(&recorder, "/tf_static", 1);
    two_episodes_hold(&recorder, &payload, stamp);
    recorder.finish().unwrap();
    peer.close().wait().unwrap();
}

#[test]
fn bridge_latched_topics_come_from_its_publication_cache() {
    let endpoint = free_endpoint();
    let peer =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let stamp = 1_700_000_001_000_000_000;
    let payload = tf_static(stamp);
    let key = keys::bridge_key("", "/tf_static");
    let queryable = keys::bridge_cache_queryable(&key, &peer.zid().to_string());
    let reply = payload.clone();
    let _cache = peer
        .declare_queryable(&queryable)
        .callback(move |q: Query| {
            // The bridge replies with the publication's own key.
            q.reply("tf_static", reply.clone()).wait().unwrap();
        })
        .wait()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let recorder = recorder(&endpoint, dir.path(), rig());
    wait_received(&recorder, "/tf_static", 1);
    two_episodes_hold(&recorder, &payload, stamp);
    recorder.finish().unwrap();
    peer.close().wait().unwrap();
}

/// Depth in another encoding than the rig's, a camera_info of another size than the images,
/// and no /tf_static at all: each named once in one line, every stream still recorded.
#[test]
fn what_does_not_fit_the_rig_is_named_and_recorded() {
    let endpoint = free_endpoint();
    let peer =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap()).unwrap();
    let rig = rig();
    let cam = rig.cameras[0].clone();
    let depth_topic = cam.depth.as_ref().unwrap().topic.clone();
    let info_topic = cam.camera_info_topic.clone().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let recorder = recorder(&endpoint, dir.path(), rig);
    let publish = |topic: &str, payload: Vec<u8>| {
        peer.put(keys::bridge_key("", topic), payload)
            .wait()
            .unwrap();
    };
    let image = |enc: &str, bpp: u32| {
        Image {
            header: Header::default(),
            height: 48,
            width: 64,
            encoding: enc.into(),
            is_bigendian: 0,
            step: 64 * bpp,
            data: vec![0; (64 * 48 * bpp) as usize],
        }
        .to_cdr()
    };
    // Flowing before the episode (so the recorder knows the images' size).
    let deadline = Instant::now() + Duration::from_secs(15);
    while recorder.status().topics[0].received == 0 {
        assert!(Instant::now() < deadline, "no colour image arrived");
        publish(&cam.topic, image("bgra8", 4));
        std::thread::sleep(Duration::from_millis(50));
    }
    recorder.send(Command::Start);
    std::thread::sleep(Duration::from_millis(200));
    for _ in 0..5 {
        publish(&cam.topic, image("bgra8", 4));
        publish(&depth_topic, image("16UC1", 2));
        let info = CameraInfo::pinhole(Header::default(), 1280, 720, 600.0, 640.0, 360.0);
        publish(&info_topic, info.to_cdr());
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(300));
    recorder.send(Command::Stop(Label::Success));
    let r = next_finished(&recorder);
    assert_eq!(
        r.summary.messages[&depth_topic], 5,
        "wrong depth still recorded"
    );
    assert_eq!(r.summary.messages[&info_topic], 5);
    assert!(r.summary.messages[&cam.topic] >= 5);
    assert_eq!(r.latched_at_start["/tf_static"], 0);
    let want = [
        format!("{depth_topic}: depth in 16UC1, the rig declares 32FC1"),
        format!(
            "{info_topic}: camera_info is 1280×720, the images on {} are 64×48",
            cam.topic
        ),
        "/tf_static: nothing latched at the start of the episode".to_string(),
    ];
    assert_eq!(r.warnings.len(), 3, "{:?}", r.warnings);
    for w in &want {
        assert!(
            r.warnings.iter().any(|x| x.starts_with(w)),
            "{w} in {:?}",
            r.warnings
        );
    }
    assert!(r.warnings.iter().all(|w| !w.contains('\n')));
    // The metadata carries them for the verdict.
    let bytes = std::fs::read(&r.summary.path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let idx = summary
        .metadata_indexes
        .iter()
        .find(|m| m.name == scaledp_schema::episode::END_RECORD)
        .unwrap();
    let meta = mcap::read::metadata(&bytes, idx).unwrap().metadata;
    let stored: Vec<String> = serde_json::from_str(&meta["warnings"]).unwrap();
    assert_eq!(stored, r.warnings);
    assert_eq!(meta["latched_at_start"], r#"{"/tf_static":0}"#);
    assert_eq!(meta["link_outages"], "0");
    recorder.finish().unwrap();
    peer.close().wait().unwrap();
}
