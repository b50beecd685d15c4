//! `scaledp record` as a process, fed over loopback Zenoh by the test itself: what the command
//! line reports when its writer queue overflows, and an operator driving it from a terminal.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use scaledp_recorder::net;
use scaledp_schema::rig::TopicSpec;
use scaledp_tests::child::{wait_status, Reap};
use scaledp_tests::{
    episode_metadata, free_endpoint, numbered_message, python, scaledp_bin, small_franka,
    workspace, write_rig_file,
};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

/// How long a status event may take.
const WAIT: Duration = Duration::from_secs(20);

/// The test's side of the link: a Zenoh session listening on a free loopback endpoint, the
/// recorder's status events under `prefix` as they arrive, and a blocking publisher per topic
/// (on the keys zenoh-bridge-ros2dds uses).
struct Feed {
    endpoint: String,
    session: zenoh::Session,
    statuses: mpsc::Receiver<serde_json::Value>,
    publishers: Vec<zenoh::pubsub::Publisher<'static>>,
    _sub: zenoh::pubsub::Subscriber<()>,
}

impl Feed {
    fn open(prefix: &str, topics: &[TopicSpec]) -> Self {
        let endpoint = free_endpoint();
        let session =
            net::open(net::zenoh_config(None, &[], std::slice::from_ref(&endpoint)).unwrap())
                .unwrap();
        let (tx, statuses) = mpsc::channel::<serde_json::Value>();
        let _sub = session
            .declare_subscriber(format!("{prefix}/status"))
            .callback(move |s| {
                let _ = tx.send(serde_json::from_slice(&s.payload().to_bytes()).unwrap());
            })
            .wait()
            .unwrap();
        let publishers = topics
            .iter()
            .map(|t| {
                session
                    .declare_publisher(scaledp_recorder::keys::bridge_key("", &t.topic))
                    .congestion_control(CongestionControl::Block)
                    .wait()
                    .unwrap()
            })
            .collect();
        Self {
            endpoint,
            session,
            statuses,
            publishers,
            _sub,
        }
    }
}

/// Messages per topic in an MCAP file.
fn messages_per_topic(path: &std::path::Path) -> BTreeMap<String, u64> {
    let bytes = std::fs::read(path).unwrap();
    let mut n: BTreeMap<String, u64> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        *n.entry(m.unwrap().channel.topic.clone()).or_default() += 1;
    }
    n
}

/// `--queue-mib 0` leaves a one-message queue; a burst on every topic overflows it. The
/// episode's line on stdout, the session summary on stderr, the exit status (3: data lost), the
/// status key and the file's metadata all report the same drops, and per topic the file holds
/// every message sent but the dropped ones.
#[test]
fn record_command_reports_queue_drops_and_exits_3() {
    let rig = small_franka();
    let topics = rig.topics();
    let dir = tempfile::tempdir().unwrap();
    let rig_path = write_rig_file(dir.path(), &rig);
    let out = dir.path().join("rec");
    let prefix = format!("test/cli_drops{}", std::process::id());
    let Feed {
        endpoint,
        session,
        statuses,
        publishers,
        _sub,
    } = Feed::open(&prefix, &topics);
    let mut child = Reap(Some(
        Command::new(scaledp_bin())
            .args([
                "record",
                "--task",
                "drop test",
                "--operator",
                "tester",
                "--episodes",
                "1",
                "--queue-mib",
                "0",
                "--no-keyboard",
                "-q",
                "--control-prefix",
                &prefix,
                "--connect",
                &endpoint,
            ])
            .arg("--rig")
            .arg(&rig_path)
            .arg("--out")
            .arg(&out)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    ));
    let control = |word: &str| {
        // Blocking like the data, on the same link: it arrives after every message put before.
        session
            .put(format!("{prefix}/control"), word)
            .congestion_control(CongestionControl::Block)
            .wait()
            .unwrap();
    };
    // Repeat `start` until the recorder, connecting in the background, obeys it.
    let deadline = Instant::now() + Duration::from_secs(30);
    let started = loop {
        assert!(Instant::now() < deadline, "the recorder never started");
        if let Some(c) = child.0.as_mut().unwrap().try_wait().unwrap() {
            panic!("scaledp record exited early: {c}");
        }
        control("start");
        match statuses.recv_timeout(Duration::from_millis(200)) {
            Ok(v) if v["event"] == "started" => break v,
            _ => {}
        }
    };
    assert_eq!(started["episode"], 0);

    let per_topic = 300;
    for k in 0..per_topic {
        for (t, p) in topics.iter().zip(&publishers) {
            p.put(numbered_message(t, k)).wait().unwrap();
        }
    }
    control("success");
    let finished = wait_status(&statuses, "finished", WAIT);

    let deadline = Instant::now() + Duration::from_secs(60);
    let status = loop {
        if let Some(s) = child.0.as_mut().unwrap().try_wait().unwrap() {
            break s;
        }
        assert!(Instant::now() < deadline, "scaledp record did not exit");
        std::thread::sleep(Duration::from_millis(20));
    };
    let output = child.0.take().unwrap().wait_with_output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr),
    );
    assert_eq!(status.code(), Some(3), "exit status; stderr: {stderr}");

    let path = out.join("episode_000000.mcap");
    let meta = episode_metadata(&path);
    assert_eq!(meta["outcome"], "success");
    assert_eq!(meta["operator"], "tester");
    let dropped: BTreeMap<String, u64> = serde_json::from_str(&meta["dropped"]).unwrap();
    let counts: BTreeMap<String, u64> = serde_json::from_str(&meta["message_counts"]).unwrap();
    assert_eq!(finished["dropped"], serde_json::to_value(&dropped).unwrap());
    assert_eq!(finished["messages"], serde_json::to_value(&counts).unwrap());
    let in_file = messages_per_topic(&path);
    for t in &topics {
        let (written, lost) = (counts[&t.topic], dropped[&t.topic]);
        assert_eq!(written + lost, per_topic, "{}: written + dropped", t.topic);
        assert_eq!(in_file.get(&t.topic).copied().unwrap_or(0), written);
    }
    let (lost, written): (u64, u64) = (dropped.values().sum(), counts.values().sum());
    assert!(lost > 0, "the queue never overflowed: {dropped:?}");
    assert!(written > 0);

    // stdout: `<path>\tsuccess\t<s> s\t<n> messages\t<lost> lost`; stderr: the session total.
    let line = stdout.lines().next().unwrap_or_default();
    let fields: Vec<&str> = line.split('\t').collect();
    assert_eq!(fields.len(), 5, "{line:?}");
    assert_eq!(fields[0], path.display().to_string());
    assert_eq!(fields[1], "success");
    assert_eq!(fields[3], format!("{written} messages"));
    assert_eq!(fields[4], format!("{lost} lost"));
    assert!(
        stderr.contains(&format!(
            "1 episodes recorded in {}, 0 failed, {lost} messages lost",
            out.display()
        )),
        "{stderr}"
    );
}

/// An operator at the terminal: `scaledp record` on a pseudo-terminal (`tests/py/pty_keys.py`)
/// with no `--no-keyboard`, driven by keys only. Space is refused while the rig's topics are
/// silent (the line names them), `f` starts anyway, `y` ends as success; the verdict (twenty
/// messages a topic within 20 ms: no two ticks) asks keep or re-record, `k` keeps; `f` starts
/// again, `d` discards, `q` quits; the status key, the files and the terminal all agree.
#[test]
fn keys_on_a_terminal_start_end_discard_and_quit() {
    let rig = small_franka();
    let topics = rig.topics();
    let dir = tempfile::tempdir().unwrap();
    let rig_path = write_rig_file(dir.path(), &rig);
    let out = dir.path().join("rec");
    let prefix = format!("test/keys{}", std::process::id());
    let Feed {
        endpoint,
        session: _session,
        statuses,
        publishers,
        _sub,
    } = Feed::open(&prefix, &topics);
    let mut driver = Reap(Some(
        Command::new(python())
            .arg(workspace().join("tests/py/pty_keys.py"))
            .args(["30", "--"])
            .arg(scaledp_bin())
            .args(["record", "--task", "keys", "--operator", "kb", "-q"])
            .args(["--control-prefix", &prefix, "--connect", &endpoint])
            .arg("--rig")
            .arg(&rig_path)
            .arg("--out")
            .arg(&out)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap(),
    ));
    // Keys act at once, but the status only reaches us once the recorder has connected and
    // subscribed: wait for its subscriptions to match our publishers first.
    let deadline = Instant::now() + Duration::from_secs(30);
    while !publishers
        .iter()
        .all(|p| p.matching_status().wait().unwrap().matching())
    {
        assert!(Instant::now() < deadline, "the recorder never subscribed");
        if let Some(c) = driver.0.as_mut().unwrap().try_wait().unwrap() {
            panic!("the terminal driver exited early: {c}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut keys = driver.0.as_mut().unwrap().stdin.take().unwrap();
    // One key at a time: the driver reads its stdin line by line as select() wakes it, so two
    // lines written together would leave the second waiting for the next.
    let press = |keys: &mut std::process::ChildStdin, key: &str| {
        use std::io::Write;
        writeln!(keys, "{key}").unwrap();
        keys.flush().unwrap();
        std::thread::sleep(Duration::from_millis(150));
    };
    let per_topic = 20;
    press(&mut keys, "space");
    let refused = wait_status(&statuses, "refused", WAIT);
    assert_eq!(refused["force"], true);
    let problems = refused["problems"].as_array().unwrap();
    assert_eq!(problems.len(), topics.len(), "{refused}");
    let episode =
        |keys: &mut std::process::ChildStdin, end_key: &str, index: u64, outcome: &str| {
            press(keys, "f");
            let started = wait_status(&statuses, "started", WAIT);
            assert_eq!(started["episode"], index);
            for k in 0..per_topic {
                for (t, p) in topics.iter().zip(&publishers) {
                    p.put(numbered_message(t, k)).wait().unwrap();
                }
            }
            // The key takes the terminal, the data the Zenoh link: give the data a head start.
            std::thread::sleep(Duration::from_millis(300));
            press(keys, end_key);
            let finished = wait_status(&statuses, "finished", WAIT);
            assert_eq!(finished["episode"], index);
            assert_eq!(finished["outcome"], outcome);
            finished
        };
    let kept = episode(&mut keys, "y", 0, "success");
    assert_eq!(kept["verdict"]["accepted"], false, "{kept}");
    press(&mut keys, "k");
    episode(&mut keys, "d", 1, "discarded");
    press(&mut keys, "q");
    drop(keys); // end of keys: the driver now waits for the exit
    let output = driver.0.take().unwrap().wait_with_output().unwrap();
    assert!(output.status.success());
    let run: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let screen = run["output"].as_str().unwrap();
    assert_eq!(run["returncode"], 0, "{screen}");

    // The terminal: the key help, the refusal and how to start anyway, the verdict and its
    // question, a status line, one line per episode, the session total.
    assert!(screen.contains("[space] start/stop"), "{screen}");
    for said in [
        "episode 0 not started, topics not live: ",
        "[f] starts it anyway",
        "episode 0: convert would reject it: ",
        "convert would reject it: [k] keep it, [r] record it again",
        "; 1 kept",
    ] {
        assert!(screen.contains(said), "{said:?} not in {screen}");
    }
    let kept_path = out.join("episode_000000.mcap");
    let discarded_path = out.join("discarded/episode_000001.mcap");
    for (path, outcome) in [(&kept_path, "success"), (&discarded_path, "discarded")] {
        assert!(path.exists(), "{} is missing", path.display());
        assert!(
            screen.contains(&format!("{}\t{outcome}\t", path.display())),
            "{screen}"
        );
    }
    assert!(
        screen.contains(&format!("2 episodes recorded in {}", out.display())),
        "{screen}"
    );
    assert!(!out.join("episode_000001.mcap").exists());

    // The kept file: its metadata and every message the status reported.
    let meta = episode_metadata(&kept_path);
    assert_eq!(meta["outcome"], "success");
    assert_eq!(meta["operator"], "kb");
    assert_eq!(meta["task"], "keys");
    let missing: Vec<String> =
        serde_json::from_str(&meta[scaledp_recorder::STARTED_WITH_MISSING_TOPICS]).unwrap();
    assert_eq!(missing.len(), topics.len(), "{missing:?}");
    let counts: BTreeMap<String, u64> = serde_json::from_str(&meta["message_counts"]).unwrap();
    assert_eq!(kept["messages"], serde_json::to_value(&counts).unwrap());
    let in_file = messages_per_topic(&kept_path);
    for t in &topics {
        // Keys and data travel different paths, so a message put just before `y` may land
        // after the stop; each topic holds some and at most what was sent.
        let n = in_file.get(&t.topic).copied().unwrap_or(0);
        assert!((1..=per_topic).contains(&n), "{}: {n} {screen}", t.topic);
        assert_eq!(counts[&t.topic], n, "{}", t.topic);
    }
}
