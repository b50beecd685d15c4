//! What the recording-session tests share: a small Franka rig from the simulator with a third
//! camera the test publishes itself (so it can fall silent, stall or stop), a recorder on the
//! simulator's session (loopback), bounded waits for its events, and a file's verdict beside
//! what `scaledp convert`'s rules decide on it.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use scaledp_converter::episode::convert;
use scaledp_converter::frames::InMemory;
use scaledp_converter::ConvertOptions;
use scaledp_recorder::{keys, now_ns, Event, Recorder, RecorderOptions, Verdict, VERDICT_RECORD};
use scaledp_schema::msg::{Header, Image, Time};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::{Sim, SimOptions};
use zenoh::Wait;

/// The camera the test publishes.
pub const SIDE: &str = "/side_cam/image";

/// franka_2zed's training streams at 64×48 and 15 fps, the arm at 100 Hz (light enough for a
/// debug build on a busy machine), and a third camera `side` on [`SIDE`]: (the recorder's rig,
/// the simulator's, without `side`).
pub fn rigs() -> (Rig, Rig) {
    let mut rig = Rig::builtin("franka_2zed")
        .unwrap()
        .with_image_size(64, 48)
        .training_streams();
    for c in &mut rig.cameras {
        c.fps = 15.0;
    }
    rig.arms[0].rate_hz = 100.0;
    let sim = rig.clone();
    let mut side = rig.cameras[1].clone();
    side.name = "side".into();
    side.topic = SIDE.into();
    rig.cameras.push(side);
    (rig, sim)
}

/// A recorder of `rig` into `out`, `opts` applied, the simulator on its session, and the
/// recorder's control prefix.
pub fn start(
    rig: &Rig,
    sim_rig: &Rig,
    out: &Path,
    opts: impl FnOnce(RecorderOptions) -> RecorderOptions,
) -> (Recorder, Sim, String) {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let config =
        scaledp_recorder::net::zenoh_config(None, &[], &[format!("tcp/127.0.0.1:{port}")]).unwrap();
    let prefix = format!("test/{}/{port}", std::process::id());
    let recorder = opts(
        RecorderOptions::new(rig.clone(), out)
            .task("put the red cube on the green square")
            .control_prefix(&prefix),
    )
    .start(config)
    .unwrap();
    let sim = SimOptions::new(sim_rig.clone())
        .seed(7)
        .spawn(recorder.session())
        .unwrap();
    (recorder, sim, prefix)
}

/// Publishes 64×48 frames on [`SIDE`] at 15 fps, stamped now, while `on` is set; at most 60 s.
pub struct Side {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Side {
    pub fn publish(session: &zenoh::Session, on: Arc<AtomicBool>) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let (s, session) = (stop.clone(), session.clone());
        let key = keys::bridge_key("", SIDE);
        let thread = std::thread::spawn(move || {
            let t0 = Instant::now();
            let mut k = 0u32;
            while !s.load(Ordering::Relaxed) && t0.elapsed() < Duration::from_secs(60) {
                if on.load(Ordering::Relaxed) {
                    let image = Image {
                        header: Header {
                            stamp: Time::from_ns(now_ns()),
                            frame_id: "side".into(),
                        },
                        height: 48,
                        width: 64,
                        encoding: "bgra8".into(),
                        is_bigendian: 0,
                        step: 64 * 4,
                        data: vec![(k % 251) as u8; 64 * 48 * 4],
                    };
                    let _ = session.put(&key, image.to_cdr()).wait();
                }
                k += 1;
                let next = Duration::from_secs_f64(f64::from(k) / 15.0);
                std::thread::sleep(next.saturating_sub(t0.elapsed()));
            }
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Side {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Waits (at most 20 s) until every topic but `except` has delivered a message.
pub fn wait_live(recorder: &Recorder, except: &[&str]) {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let silent: Vec<String> = recorder
            .status()
            .topics
            .into_iter()
            .filter(|t| t.received == 0 && !except.contains(&t.topic.as_str()))
            .map(|t| t.topic)
            .collect();
        if silent.is_empty() {
            return;
        }
        assert!(Instant::now() < deadline, "never live: {silent:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The next event `pick` takes, within 30 s (others skipped).
pub fn next<T>(recorder: &Recorder, mut pick: impl FnMut(Event) -> Option<T>) -> T {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let left = deadline
            .checked_duration_since(Instant::now())
            .expect("no such event within 30 s");
        let e = recorder.events().recv_timeout(left).unwrap();
        if let Some(t) = pick(e) {
            return t;
        }
    }
}

/// The metadata records of an episode file, by name.
pub fn records(path: &Path) -> BTreeMap<String, BTreeMap<String, String>> {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    summary
        .metadata_indexes
        .iter()
        .map(|i| {
            let m = mcap::read::metadata(&bytes, i).unwrap();
            (m.name, m.metadata)
        })
        .collect()
}

/// The verdict stored in an episode file.
pub fn stored_verdict(path: &Path) -> Verdict {
    Verdict::from_record(&records(path)[VERDICT_RECORD]).unwrap()
}

/// What `scaledp convert` (default rules, small images) decides on a file: None when it takes
/// it, else its reason.
pub fn convert_reason(path: &Path) -> Option<String> {
    let rec = scaledp_converter::read_input(path).unwrap();
    let opts = ConvertOptions {
        width: 16,
        height: 12,
        ..ConvertOptions::default()
    };
    match convert(path, &rec, &InMemory(&rec), &opts) {
        Ok(_) => None,
        Err(scaledp_converter::Error::Rejected { reason, .. }) => Some(reason),
        Err(e) => panic!("{}: {e}", path.display()),
    }
}
