//! rmw_zenoh keys, the Zenoh control key, and a queue that overflows.

use super::*;

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
    for end in ["stop", "discard", "failure", " Success\n"] {
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
    let want: [(PathBuf, Label); 4] = [
        (dir.path().join("episode_000000.mcap"), Label::Unlabeled),
        (
            dir.path().join("discarded/episode_000001.mcap"),
            Label::Discarded,
        ),
        (dir.path().join("episode_000002.mcap"), Label::Failure),
        (dir.path().join("episode_000003.mcap"), Label::Success),
    ];
    assert_eq!(paths.len(), want.len());
    for ((path, outcome), report) in want.iter().zip(&paths) {
        assert_eq!(&report.summary.path, path);
        assert_eq!(report.outcome, *outcome);
        assert_eq!(episode_metadata(path)["outcome"], outcome.as_str());
        assert!(report.summary.messages.values().all(|n| *n > 0));
    }
    assert!(!dir.path().join("episode_000001.mcap").exists());
    // The status key reports every finish with its outcome, in order (bounded wait: the
    // last status may still be on its way to the pedal).
    let deadline = Instant::now() + Duration::from_secs(10);
    let finished = loop {
        let finished: Vec<serde_json::Value> = statuses
            .lock()
            .unwrap()
            .iter()
            .map(|s| serde_json::from_str::<serde_json::Value>(s).unwrap())
            .filter(|v| v["event"] == "finished")
            .collect();
        if finished.len() >= want.len() || Instant::now() > deadline {
            break finished;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let outcomes: Vec<&str> = finished
        .iter()
        .map(|v| v["outcome"].as_str().unwrap())
        .collect();
    assert_eq!(
        outcomes,
        ["unlabeled", "discarded", "failure", "success"],
        "{finished:?}"
    );
}

/// A 1-byte writer queue (a message is taken only while the queue is empty) and bursts put on
/// the recorder's own session (no transport in between, so every message put is received):
/// the queue overflows, and every message received during the episode is either in the file or
/// counted as dropped on its own topic, in the report, the metadata, the status key and the
/// live figures alike.
#[test]
fn queue_overflow_drops_are_counted_per_topic_and_reported() {
    use zenoh::Wait;
    let rig = small_franka();
    let topics = rig.topics();
    let dir = tempfile::tempdir().unwrap();
    let prefix = format!("test/drops{}", std::process::id());
    let recorder = RecorderOptions::new(rig, dir.path())
        .task("t")
        .queue_bytes(1)
        .control_prefix(&prefix)
        .start(net::zenoh_config(None, &[], &[free_endpoint()]).unwrap())
        .unwrap();
    let session = recorder.session().clone();
    let statuses = Arc::new(Mutex::new(Vec::<serde_json::Value>::new()));
    let sink = statuses.clone();
    let _sub = session
        .declare_subscriber(format!("{prefix}/status"))
        .callback(move |s| {
            let v = serde_json::from_slice(&s.payload().to_bytes()).unwrap();
            sink.lock().unwrap().push(v);
        })
        .wait()
        .unwrap();
    let publishers: Vec<_> = topics
        .iter()
        .map(|t| {
            session
                .declare_publisher(scaledp_recorder::keys::bridge_key("", &t.topic))
                .wait()
                .unwrap()
        })
        .collect();

    recorder.send(Command::Start);
    let deadline = Instant::now() + Duration::from_secs(10);
    while recorder.status().episode.is_none() {
        assert!(Instant::now() < deadline, "the episode never opened");
        std::thread::sleep(Duration::from_millis(10));
    }
    // Round-robin bursts over every topic until each has lost a message (bounded: a writer
    // that keeps up with 1000 back-to-back puts 20 times over is not plausible).
    let mut published: Vec<Vec<Vec<u8>>> = vec![Vec::new(); topics.len()];
    let deadline = Instant::now() + Duration::from_secs(60);
    for burst in 0.. {
        for _ in 0..250 {
            for (i, (t, p)) in topics.iter().zip(&publishers).enumerate() {
                let msg = scaledp_tests::numbered_message(t, published[i].len() as u64);
                p.put(msg.clone()).wait().unwrap();
                published[i].push(msg);
            }
        }
        let all_dropped = recorder.status().topics.iter().all(|t| t.dropped > 0);
        if all_dropped || burst >= 20 || Instant::now() > deadline {
            break;
        }
    }
    // Every put has reached the recorder's callback before the episode stops.
    let deadline = Instant::now() + Duration::from_secs(10);
    while recorder
        .status()
        .topics
        .iter()
        .zip(&published)
        .any(|(t, p)| t.received < p.len() as u64)
    {
        assert!(Instant::now() < deadline, "{:?}", recorder.status().topics);
        std::thread::sleep(Duration::from_millis(10));
    }
    recorder.send(Command::Stop(Label::Failure));
    let report = next_finished(&recorder);
    let live = recorder.status().topics;
    let path = report.summary.path.clone();
    let recorded = read_rust(&path);
    let meta = episode_metadata(&path);
    let deadline = Instant::now() + Duration::from_secs(10);
    let finished = loop {
        let found = statuses
            .lock()
            .unwrap()
            .iter()
            .find(|v| v["event"] == "finished")
            .cloned();
        if let Some(v) = found {
            break v;
        }
        assert!(Instant::now() < deadline, "no 'finished' status");
        std::thread::sleep(Duration::from_millis(20));
    };
    recorder.finish().unwrap();

    let meta_dropped: BTreeMap<String, u64> = serde_json::from_str(&meta["dropped"]).unwrap();
    let meta_counts: BTreeMap<String, u64> = serde_json::from_str(&meta["message_counts"]).unwrap();
    assert_eq!(meta_dropped, report.dropped);
    assert_eq!(meta_counts, report.summary.messages);
    assert_eq!(meta["outcome"], "failure");
    assert_eq!(
        finished["dropped"],
        serde_json::to_value(&report.dropped).unwrap()
    );
    // An empty queue always takes a message: the episode holds some, whichever topic won.
    assert!(report.summary.messages.values().sum::<u64>() > 0);
    for ((t, sent), status) in topics.iter().zip(&published).zip(&live) {
        let topic = &t.topic;
        let dropped = report.dropped[topic];
        let written = report.summary.messages[topic];
        let sent_n = sent.len() as u64;
        assert!(dropped > 0, "{topic}: nothing dropped ({live:?})");
        assert_eq!(written + dropped, sent_n, "{topic}: written + dropped");
        assert_eq!(status.received, sent_n, "{topic}: received");
        // Every drop happened inside this episode.
        assert_eq!(status.dropped, dropped, "{topic}: live drop count");
        // What was written is what was sent, in order, less the dropped messages.
        let in_file = recorded.get(topic).map_or(&[][..], Vec::as_slice);
        assert_eq!(in_file.len() as u64, written);
        let mut rest = sent.iter();
        for (k, (data, _, _)) in in_file.iter().enumerate() {
            assert!(
                rest.any(|s| s == data),
                "{topic}: message {k} of the file was not sent, or out of order"
            );
        }
    }
}
