//! Faults around a running recorder: its output directory removed mid-episode, and the Zenoh
//! peer it records from going away and coming back. Each time the recorder says what happened
//! (the OS's reason included), keeps what it completed readable, and goes on recording.
//! (A disk filling up is `tests/tests/hostile_record.rs`: it needs a small filesystem.)

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::time::{Duration, Instant};

use scaledp_recorder::{keys, net, Command, Event, Label, Recorder, RecorderOptions};
use scaledp_schema::msg::{Header, JointState, Time};
use scaledp_schema::{Rig, RosMessage};
use zenoh::qos::CongestionControl;
use zenoh::Wait;

const ARM: &str = "/franka/joint_states";

fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

/// The test's end of the link: a peer listening on `endpoint`, publishing joint states.
struct Peer {
    session: zenoh::Session,
    arm: zenoh::pubsub::Publisher<'static>,
    sent: u64,
}

impl Peer {
    fn listen(endpoint: &str) -> Self {
        // Right after a close the port may still be held for a moment.
        let deadline = Instant::now() + Duration::from_secs(10);
        let session = loop {
            let config = net::zenoh_config(None, &[], &[endpoint.to_string()]).unwrap();
            match net::open(config) {
                Ok(s) => break s,
                Err(e) if Instant::now() < deadline => {
                    eprintln!("listening on {endpoint}: {e}; again");
                    std::thread::sleep(Duration::from_millis(200));
                }
                Err(e) => panic!("{e}"),
            }
        };
        let arm = session
            .declare_publisher(keys::bridge_key("", ARM))
            .congestion_control(CongestionControl::Block)
            .wait()
            .unwrap();
        Self {
            session,
            arm,
            sent: 0,
        }
    }

    /// Publishes `n` joint states, 1 ms apart.
    fn publish(&mut self, n: u64) {
        for _ in 0..n {
            self.sent += 1;
            let js = JointState {
                header: Header {
                    stamp: Time::from_ns(1_700_000_000_000_000_000 + self.sent * 1_000_000),
                    frame_id: String::new(),
                },
                name: vec!["fr3_joint1".into()],
                position: vec![self.sent as f64],
                velocity: vec![],
                effort: vec![],
            };
            self.arm.put(js.to_cdr()).wait().unwrap();
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    fn close(self) {
        self.session.close().wait().unwrap();
    }
}

fn start_recorder(out: &std::path::Path, endpoint: &str) -> Recorder {
    let rig = Rig::builtin("franka_2zed").unwrap();
    RecorderOptions::new(rig, out)
        .task("t")
        .flush_interval(Duration::from_millis(100))
        .control_prefix(format!("test/faults{}", std::process::id()))
        .start(net::zenoh_config(None, &[endpoint.to_string()], &[]).unwrap())
        .unwrap()
}

/// Arm messages the recorder has received so far.
fn received(recorder: &Recorder) -> u64 {
    recorder
        .status()
        .topics
        .iter()
        .find(|t| t.topic == ARM)
        .unwrap()
        .received
}

/// Waits (bounded) until the recorder has received `n` arm messages in all.
fn wait_received(recorder: &Recorder, n: u64) {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let got = received(recorder);
        if got >= n {
            return;
        }
        assert!(Instant::now() < deadline, "{got} of {n} messages arrived");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The next episode that finished or failed, within 20 s.
fn next_end(recorder: &Recorder) -> Event {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline
            .checked_duration_since(Instant::now())
            .expect("no episode ended within 20 s");
        let e = recorder.events().recv_timeout(left).unwrap();
        if matches!(e, Event::Finished(_) | Event::Failed { .. }) {
            return e;
        }
    }
}

fn messages(path: &std::path::Path) -> usize {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes).unwrap().count()
}

#[test]
fn a_removed_output_directory_fails_that_episode_and_the_next_one_records() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demos");
    let endpoint = free_endpoint();
    let mut peer = Peer::listen(&endpoint);
    let recorder = start_recorder(&out, &endpoint);
    peer.publish(20);
    wait_received(&recorder, 1);

    recorder.send(Command::Start);
    peer.publish(100);
    std::fs::remove_dir_all(&out).unwrap();
    let t0 = Instant::now();
    peer.publish(100);
    match next_end(&recorder) {
        Event::Failed { index, error } => {
            assert_eq!(index, 0);
            assert!(
                error.contains("episode_000000.mcap.partial") && error.contains("removed"),
                "{error}"
            );
        }
        e => panic!("episode 0: {e:?}"),
    }
    assert!(
        t0.elapsed() < Duration::from_secs(5),
        "noticed within a few flushes"
    );

    // The session goes on: the next episode makes the directory again and is complete.
    recorder.send(Command::Start);
    peer.publish(50);
    recorder.send(Command::Stop(Label::Success));
    match next_end(&recorder) {
        Event::Finished(r) => {
            assert_eq!(r.index, 1);
            assert!(r.summary.path.starts_with(&out));
            assert!(messages(&r.summary.path) > 0);
        }
        e => panic!("episode 1: {e:?}"),
    }
    recorder.finish().unwrap();
    peer.close();
}

#[test]
fn a_peer_that_restarts_is_reported_and_recording_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let endpoint = free_endpoint();
    let mut peer = Peer::listen(&endpoint);
    let recorder = start_recorder(dir.path(), &endpoint);
    peer.publish(20);
    wait_received(&recorder, 1);
    // The first messages may go out before the subscription reaches the peer (Zenoh drops
    // them at the publisher): count from what has arrived once messages flow.
    std::thread::sleep(Duration::from_millis(100));
    let flowing = received(&recorder);
    recorder.send(Command::Start);
    peer.publish(50);
    wait_received(&recorder, flowing + 50);
    assert!(recorder.zenoh_links() > 0);

    // The bridge (or router) goes away: the recorder sees no link left.
    peer.close();
    let deadline = Instant::now() + Duration::from_secs(10);
    while recorder.zenoh_links() > 0 {
        assert!(Instant::now() < deadline, "the lost link was never noticed");
        std::thread::sleep(Duration::from_millis(50));
    }
    // It comes back on the same endpoint: the recorder reconnects by itself and the episode
    // still open takes the new messages.
    let mut peer = Peer::listen(&endpoint);
    let deadline = Instant::now() + Duration::from_secs(30);
    while recorder.zenoh_links() == 0 {
        assert!(Instant::now() < deadline, "never reconnected");
        std::thread::sleep(Duration::from_millis(50));
    }
    let before = received(&recorder);
    // Publish until messages flow again (subscriptions are re-declared on the new link).
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        peer.publish(10);
        if received(&recorder) > before {
            break;
        }
        assert!(Instant::now() < deadline, "no message after the restart");
    }
    peer.publish(30);
    std::thread::sleep(Duration::from_millis(200));
    recorder.send(Command::Stop(Label::Success));
    match next_end(&recorder) {
        Event::Finished(r) => {
            let n = r.summary.messages[ARM];
            assert!(n > 70, "messages from before and after the restart: {n}");
            assert_eq!(
                messages(&r.summary.path) as u64,
                r.summary.messages.values().sum::<u64>()
            );
        }
        e => panic!("{e:?}"),
    }
    recorder.finish().unwrap();
    peer.close();
}
