//! The operator's commands are recorded like any topic of the rig, and the converter takes the
//! action (pose and gripper) from them: live through the recorder library, and offline through
//! the synthetic writer on the bimanual rig (14-D actions).

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use glam::{DMat3, DQuat};
use scaledp_converter::episode::convert;
use scaledp_converter::frames::InMemory;
use scaledp_converter::ConvertOptions;
use scaledp_recorder::{net, Command, Event, Label, RecorderOptions};
use scaledp_schema::kinematics::rpy_from_rotation;
use scaledp_schema::msg::{JointState, PoseStamped};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::SimOptions;

fn small(name: &str, w: u32, h: u32) -> Rig {
    Rig::builtin(name).unwrap().with_image_size(w, h)
}

/// Per topic: (schema name, payloads) of an MCAP file.
fn topics(path: &Path) -> BTreeMap<String, (String, Vec<Vec<u8>>)> {
    let bytes = std::fs::read(path).unwrap();
    let mut out: BTreeMap<String, (String, Vec<Vec<u8>>)> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m
            .channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        out.entry(m.channel.topic.clone())
            .or_insert((schema, Vec::new()))
            .1
            .push(m.data.to_vec());
    }
    out
}

/// Every action row's pose and gripper is one of the recorded commands of its arm (as the
/// converter reads them: x, y, z, roll, pitch, yaw; width), and not merely the next state.
fn assert_actions_are_commands(rig: &Rig, path: &Path) {
    let rec = scaledp_converter::read_input(path).unwrap();
    let opts = ConvertOptions {
        width: 16,
        height: 12,
        ..ConvertOptions::default()
    };
    let ep = convert(path, &rec, &InMemory(&rec), &opts).unwrap();
    let dim = 7 * rig.arms.len();
    assert_eq!(ep.state_names.len(), dim);
    let frames = ep.len();
    assert!(frames > 50, "{frames} frames");
    let msgs = topics(path);
    let mut differs_from_next_state = 0;
    for (a, arm) in rig.arms.iter().enumerate() {
        let poses: Vec<[f64; 6]> = msgs[arm.command_topic.as_ref().unwrap()]
            .1
            .iter()
            .map(|m| {
                let p = PoseStamped::from_cdr(m).unwrap();
                let o = p.pose.orientation;
                let r = DMat3::from_quat(DQuat::from_xyzw(o.x, o.y, o.z, o.w));
                let [roll, pitch, yaw] = rpy_from_rotation(r);
                let q = p.pose.position;
                [q.x, q.y, q.z, roll, pitch, yaw]
            })
            .collect();
        let g = arm.gripper.as_ref().unwrap();
        let widths: Vec<f64> = msgs[g.command_topic.as_ref().unwrap()]
            .1
            .iter()
            .map(|m| g.model.width_m(&JointState::from_cdr(m).unwrap().position))
            .collect();
        let mut closed_ticks = 0;
        for t in 0..frames {
            let row = &ep.action[t * dim + a * 7..t * dim + a * 7 + 7];
            let near = |p: &[f64; 6]| (0..6).all(|d| (f64::from(row[d]) - p[d]).abs() < 1e-4);
            assert!(
                poses.iter().any(near),
                "arm {a} tick {t}: action {row:?} is no command"
            );
            let w = f64::from(row[6]);
            assert!(
                widths.iter().any(|c| (c - w).abs() < 1e-5),
                "arm {a} tick {t}: gripper {w}"
            );
            if t + 1 < frames {
                let next = &ep.state[(t + 1) * dim + a * 7..(t + 1) * dim + a * 7 + 7];
                differs_from_next_state += usize::from((row[6] - next[6]).abs() > 0.01);
            }
            // While the fingers squeeze the cube (measured 4.5 cm), the command says 0.
            let measured = ep.state[t * dim + a * 7 + 6];
            closed_ticks += usize::from(w < 1e-3 && (measured - 0.045).abs() < 1e-3);
        }
        assert!(
            closed_ticks > 10,
            "arm {a}: {closed_ticks} ticks commanded closed on the cube"
        );
    }
    assert!(
        differs_from_next_state > 10,
        "the actions look like the next state"
    );
}

#[test]
fn a_recorded_operator_episode_carries_its_commands_and_converts_them_to_actions() {
    let rig = small("franka_sim", 64, 36);
    let dir = tempfile::tempdir().unwrap();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let config = net::zenoh_config(None, &[], &[format!("tcp/127.0.0.1:{port}")]).unwrap();
    let recorder = RecorderOptions::new(rig.clone(), dir.path())
        .task("put the red cube on the green square")
        .control_prefix(format!("test/rec{}", std::process::id()))
        .start(config)
        .unwrap();
    let sim = SimOptions::new(rig.clone())
        .seed(21)
        .scripted_operator(true)
        .spawn(recorder.session())
        .unwrap();
    // Every topic, commands included, is live before the episode starts.
    let deadline = Instant::now() + Duration::from_secs(20);
    while recorder.status().topics.iter().any(|t| t.received == 0) {
        assert!(
            Instant::now() < deadline,
            "silent topics: {:?}",
            recorder.status().topics
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let stop = AtomicBool::new(false);
    let r = sim.run_episode(21, 0.5, 25.0, &mut || recorder.send(Command::Start), &stop);
    std::thread::sleep(Duration::from_millis(300));
    assert!(r.operator_done && r.task.success, "{:?}", r.task);
    recorder.send(Command::Stop(Label::Success));
    let report = loop {
        match recorder
            .events()
            .recv_timeout(Duration::from_secs(30))
            .unwrap()
        {
            Event::Finished(r) => break r,
            Event::Failed { error, .. } => panic!("{error}"),
            _ => {}
        }
    };
    recorder.finish().unwrap();
    sim.stop();
    let msgs = topics(&report.summary.path);
    let arm = &rig.arms[0];
    let g = arm.gripper.as_ref().unwrap();
    let (schema, poses) = &msgs[arm.command_topic.as_ref().unwrap()];
    assert_eq!(schema, "geometry_msgs/msg/PoseStamped");
    // 100 Hz leader samples over an episode of about ten seconds.
    assert!(poses.len() > 700, "{} pose commands", poses.len());
    let (schema, grips) = &msgs[g.command_topic.as_ref().unwrap()];
    assert_eq!(schema, "sensor_msgs/msg/JointState");
    assert!(grips.len() > 700, "{} gripper commands", grips.len());
    assert_actions_are_commands(&rig, &report.summary.path);
}

#[test]
fn a_bimanual_synthetic_episode_converts_to_fourteen_dimensional_command_actions() {
    let rig = small("bimanual_ur5_sim", 32, 24);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("episode_000000.mcap");
    let t0 = 1_700_000_000_000_000_000;
    let r =
        scaledp_sim::write_episode(&path, &rig, 5, 12.0, t0, "t", &mut |_, _, _, _| {}).unwrap();
    assert!(r.task.success, "{:?}", r.task);
    assert_actions_are_commands(&rig, &path);
}
