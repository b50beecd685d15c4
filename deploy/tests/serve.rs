//! `scaledp serve` against the live simulator over loopback Zenoh: commands at the control
//! rate that the simulated arm follows, a stop when the rig falls silent, and `--dry-run`
//! publishing nothing.
#![allow(clippy::unwrap_used)]

use crate::common;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use candle_core::Device;
use scaledp_deploy::{ServeOptions, Server};
use scaledp_policy::Policy;
use scaledp_schema::msg::PoseStamped;
use scaledp_schema::RosMessage;
use scaledp_sim::SimOptions;
use zenoh::Wait;

fn session() -> zenoh::Session {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let cfg =
        scaledp_recorder::net::zenoh_config(None, &[], &[format!("tcp/127.0.0.1:{port}")]).unwrap();
    zenoh::open(cfg).wait().unwrap()
}

/// Arrival times and messages on `key`.
type Log = Arc<Mutex<Vec<(Instant, Vec<u8>)>>>;

fn listen(s: &zenoh::Session, key: &str) -> (Log, zenoh::pubsub::Subscriber<()>) {
    let log: Log = Arc::default();
    let l = log.clone();
    let sub = s
        .declare_subscriber(key.to_string())
        .callback(move |x| {
            l.lock()
                .unwrap()
                .push((Instant::now(), x.payload().to_bytes().to_vec()))
        })
        .wait()
        .unwrap();
    (log, sub)
}

#[test]
fn serve_drives_the_sim_at_the_control_rate_and_stops_when_it_falls_silent() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let s = session();
    let (poses, _a) = listen(&s, "cartesian_motion_controller/target_frame");
    let (grips, _b) = listen(&s, "leader/franka_gripper/joint_states");
    let (status_log, _c) = listen(&s, "scaledp/serve/status");
    let sim = SimOptions::new(rig.clone()).seed(5).spawn(&s).unwrap();
    let server = Server::start(policy, ServeOptions::new(rig.clone()), &s).unwrap();

    // Wait (bounded) for the first command, then measure over 2.5 s.
    let start = Instant::now();
    while poses.lock().unwrap().is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "no command in 10 s: {}",
            server.status().line()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let first = poses.lock().unwrap()[0].0;
    std::thread::sleep(Duration::from_millis(2500));
    let log = poses.lock().unwrap().clone();
    let n = log
        .iter()
        .filter(|(t, _)| t.duration_since(first) <= Duration::from_millis(2500))
        .count();
    let rate = (n - 1) as f64 / 2.5;
    assert!(
        (8.0..=12.0).contains(&rate),
        "{rate} commands/s ({})",
        server.status().line()
    );
    assert!(
        grips.lock().unwrap().len() + 2 >= n,
        "gripper commands go with the poses"
    );
    let st = server.status();
    assert!((7.0..=12.5).contains(&st.command_rate_hz), "{}", st.line());
    assert!(
        st.chunks >= 3 && st.inference_ms_p50.is_some(),
        "{}",
        st.line()
    );
    // From the newest frame to the first command of its chunk takes at least the inference.
    assert!(
        st.e2e_ms_p50.unwrap() >= st.inference_ms_p50.unwrap(),
        "{}",
        st.line()
    );
    assert!(
        !status_log.lock().unwrap().is_empty(),
        "nothing on the status key"
    );
    // The simulated arm follows what was published: its controller's target is a command.
    let last = PoseStamped::from_cdr(&log.last().unwrap().1).unwrap();
    assert_eq!(last.header.frame_id, "fr3_link0");
    let target = sim.state().arms[0].target.w_axis.truncate();
    let home = common::home_action(&rig);
    assert!(
        (target - glam::DVec3::new(home[0], home[1], home[2])).length() < 0.03,
        "{target}"
    );
    let published: Vec<glam::DVec3> = log
        .iter()
        .map(|(_, b)| {
            let p = PoseStamped::from_cdr(b).unwrap().pose.position;
            glam::DVec3::new(p.x, p.y, p.z)
        })
        .collect();
    assert!(
        published.iter().any(|p| (*p - target).length() < 1e-9),
        "the sim's target {target} was never published"
    );

    // The rig falls silent: within a few ticks the node stops and says why.
    sim.stop();
    std::thread::sleep(Duration::from_millis(400));
    let before = poses.lock().unwrap().len();
    std::thread::sleep(Duration::from_millis(600));
    let st = server.status();
    assert_eq!(
        poses.lock().unwrap().len(),
        before,
        "commands kept coming from a silent rig"
    );
    let why = st.holding.clone().unwrap_or_default();
    assert!(why.contains("silent"), "{}", st.line());
    assert!(st.halted_ticks >= 5, "{}", st.line());
    server.stop();
}

#[test]
fn a_dry_run_publishes_nothing_but_shows_every_command() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let s = session();
    let (poses, _a) = listen(&s, "cartesian_motion_controller/target_frame");
    let sim = SimOptions::new(rig.clone()).seed(6).spawn(&s).unwrap();
    let shown = Arc::new(Mutex::new(0usize));
    let sh = shown.clone();
    let mut opts = ServeOptions::new(rig);
    opts.dry_run = true;
    opts.on_commands = Some(Arc::new(move |_, cmds| *sh.lock().unwrap() += cmds.len()));
    let server = Server::start(policy, opts, &s).unwrap();
    let start = Instant::now();
    while *shown.lock().unwrap() < 5 {
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "{}",
            server.status().line()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let st = server.stop();
    sim.stop();
    assert!(st.dry_run && st.commanded_ticks >= 5, "{}", st.line());
    assert!(
        poses.lock().unwrap().is_empty(),
        "a dry run published commands"
    );
}
