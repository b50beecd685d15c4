//! The live simulator over loopback Zenoh: seeded streams, commands that move the arm, resets
//! and the task's status key.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glam::{DMat4, DVec3};
use scaledp_recorder::keys::{bridge_key, rmw_key, rmw_key_expr};
use scaledp_recorder::net;
use scaledp_schema::msg::{definition, header_stamp, Image, JointState, StampField};
use scaledp_schema::rig::TopicKind;
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::messages::{gripper_command, pose_command};
use scaledp_sim::task::Task;
use scaledp_sim::{KeyStyle, Scene, SimOptions};
use zenoh::Wait;

/// An origin long past: every message is due at once, so the streams run flat out and the
/// run's timing cannot shape what they publish.
const T0: u64 = 1_700_000_000_000_000_000;
const N: usize = 40;

fn endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

fn small(name: &str) -> Rig {
    Rig::builtin(name).unwrap().with_image_size(32, 24)
}

/// Polls `done` every 10 ms for at most `seconds`.
fn wait_until(seconds: f64, mut done: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < deadline {
        if done() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    done()
}

/// The first `N` messages of every topic the live simulator publishes under `seed` (on a
/// session that only listens on a free loopback port, so nothing else receives them).
fn first_messages(rig: &Rig, seed: u64) -> BTreeMap<String, Vec<Vec<u8>>> {
    let session = net::open(net::zenoh_config(None, &[], &[endpoint()]).unwrap()).unwrap();
    let got: Arc<Mutex<BTreeMap<String, Vec<Vec<u8>>>>> = Arc::default();
    let sink = got.clone();
    let sim = SimOptions::new(rig.clone())
        .seed(seed)
        .start_time_ns(T0)
        .on_publish(Arc::new(move |topic, payload| {
            let mut got = sink.lock().unwrap();
            let msgs = got.entry(topic.to_string()).or_default();
            if msgs.len() < N {
                msgs.push(payload.to_vec());
            }
        }))
        .spawn(&session)
        .unwrap();
    // Every stream N messages; the latched /tf_static once, at startup.
    let full = || {
        let got = got.lock().unwrap();
        got.len() == rig.topics().len()
            && rig
                .topics()
                .iter()
                .all(|t| got[&t.topic].len() == if t.latched { 1 } else { N })
    };
    let ok = wait_until(60.0, full);
    sim.stop();
    session.close().wait().unwrap();
    assert!(
        ok,
        "the streams did not publish {N} messages each within 60 s"
    );
    let out = std::mem::take(&mut *got.lock().unwrap());
    out
}

#[test]
fn a_seed_fixes_the_live_streams_and_another_seed_changes_them() {
    // Nobody commands the arms, so the world holds still and every byte follows from the seed.
    let rig = small("franka_2zed");
    let a = first_messages(&rig, 3);
    assert_eq!(a, first_messages(&rig, 3), "same seed, same messages");
    let other = first_messages(&rig, 4);
    // The rig's depth, camera_info and tf are seeded streams like the others.
    assert!(rig.topics().iter().any(|t| t.kind == TopicKind::Depth));
    for t in rig.topics().into_iter().filter(|t| !t.latched) {
        let (mine, theirs) = (&a[&t.topic], &other[&t.topic]);
        // Stamps on the rate's grid but for the seeded jitter (±0.5 ms for cameras and the
        // gripper, ±20 µs for the arm), which is not zero.
        let half_width = if t.topic == "/franka/joint_states" {
            0.02e6
        } else {
            0.5e6
        };
        // A rig's [tf] without a rate: the simulator's own.
        let rate = if t.rate_hz > 0.0 {
            t.rate_hz
        } else {
            scaledp_sim::tf::DEFAULT_TF_RATE_HZ
        };
        let period = 1e9 / rate;
        // Where the type keeps its stamp (a TFMessage: its first transform's header).
        let field = StampField::of_definition(&definition(&t.message_type).unwrap());
        let stamp = |m: &Vec<u8>| field.read(m).unwrap().as_ns();
        let stamps: Vec<u64> = mine.iter().map(stamp).collect();
        for (k, s) in stamps.iter().enumerate() {
            let jitter = (s - T0) as f64 - k as f64 * period;
            assert!(jitter.abs() <= half_width + 1.0, "{}: {jitter} ns", t.topic);
        }
        let off_grid = stamps
            .iter()
            .enumerate()
            .filter(|(k, s)| ((**s - T0) as f64 - *k as f64 * period).abs() > 1.0)
            .count();
        assert!(off_grid > N / 2, "{}: no jitter", t.topic);
        let their_stamps: Vec<u64> = theirs.iter().map(stamp).collect();
        assert_ne!(stamps, their_stamps, "{}: same jitter", t.topic);
        if t.kind == TopicKind::Color {
            // Another seed puts the cube and the target elsewhere.
            let pixels = |m: &[Vec<u8>]| -> Vec<Vec<u8>> {
                m.iter().map(|x| Image::from_cdr(x).unwrap().data).collect()
            };
            let (p, q) = (pixels(mine), pixels(theirs));
            assert!(
                p.iter().zip(&q).all(|(x, y)| x != y),
                "{}: same pictures",
                t.topic
            );
        }
    }
}

/// Latest joint positions of `topic` seen by `session`.
fn watch_joints(
    session: &zenoh::Session,
    key: String,
) -> (
    Arc<Mutex<Option<JointState>>>,
    zenoh::pubsub::Subscriber<()>,
) {
    let latest: Arc<Mutex<Option<JointState>>> = Arc::default();
    let sink = latest.clone();
    let sub = session
        .declare_subscriber(key)
        .callback(move |s| {
            if let Ok(js) = JointState::from_cdr(&s.payload().to_bytes()) {
                *sink.lock().unwrap() = Some(js);
            }
        })
        .wait()
        .unwrap();
    (latest, sub)
}

#[test]
fn commands_over_zenoh_move_the_arm_to_the_target_and_close_the_gripper() {
    for keys in [KeyStyle::Bridge, KeyStyle::Rmw] {
        let rig = small("franka_sim");
        let arm = rig.arms[0].clone();
        let g = arm.gripper.clone().unwrap();
        let ep = endpoint();
        let sim_session =
            net::open(net::zenoh_config(None, &[], std::slice::from_ref(&ep)).unwrap()).unwrap();
        let sim = SimOptions::new(rig.clone())
            .seed(2)
            .keys(keys)
            .spawn(&sim_session)
            .unwrap();
        // A separate process's session: the policy's.
        let policy = net::open(net::zenoh_config(None, &[ep], &[]).unwrap()).unwrap();
        let key = |topic: &str, ty: &str| match keys {
            KeyStyle::Bridge => bridge_key("", topic),
            KeyStyle::Rmw => rmw_key(0, topic, ty, "TypeHashNotSupported"),
        };
        let state_key = match keys {
            KeyStyle::Bridge => bridge_key("", &arm.joint_state_topic),
            KeyStyle::Rmw => rmw_key_expr(&arm.joint_state_topic, "sensor_msgs/msg/JointState"),
        };
        let (joints, _sub) = watch_joints(&policy, state_key);
        assert!(
            wait_until(10.0, || joints.lock().unwrap().is_some()),
            "{keys:?}: no joint states"
        );
        let start = sim.state().arms[0].tcp;
        let target = DMat4::from_translation(DVec3::new(0.06, -0.05, -0.08)) * start;
        let pose_pub = policy
            .declare_publisher(key(
                arm.command_topic.as_ref().unwrap(),
                "geometry_msgs/msg/PoseStamped",
            ))
            .wait()
            .unwrap();
        let grip_pub = policy
            .declare_publisher(key(
                g.command_topic.as_ref().unwrap(),
                "sensor_msgs/msg/JointState",
            ))
            .wait()
            .unwrap();
        let tcp_of = |js: &JointState| {
            let flange = arm.model.base_from_flange(&js.position).unwrap();
            flange * arm.model.default_flange_from_tcp()
        };
        let reached = wait_until(10.0, || {
            let now = scaledp_recorder::now_ns();
            pose_pub
                .put(pose_command(&arm, &target, now).to_cdr())
                .wait()
                .unwrap();
            grip_pub
                .put(gripper_command(&g, 0.02, now).to_cdr())
                .wait()
                .unwrap();
            let js = joints.lock().unwrap().clone().unwrap();
            let off = (tcp_of(&js).w_axis - target.w_axis).truncate().length();
            let width = sim.state().arms[0].gripper_width_m;
            off < 1e-3 && (width - 0.02).abs() < 1e-6
        });
        let js = joints.lock().unwrap().clone().unwrap();
        let off = (tcp_of(&js).w_axis - target.w_axis).truncate().length();
        assert!(
            reached,
            "{keys:?}: the published joint states stay {off} m from the target"
        );
        assert!((start.w_axis - target.w_axis).truncate().length() > 0.1);
        drop(sim);
        let _ = policy.close().wait();
        let _ = sim_session.close().wait();
    }
}

#[test]
fn a_reset_over_zenoh_redraws_the_task_and_the_status_key_reports_it() {
    let rig = small("bimanual_ur5_sim");
    let ep = endpoint();
    let sim_session =
        net::open(net::zenoh_config(None, &[], std::slice::from_ref(&ep)).unwrap()).unwrap();
    let prefix = format!("test/sim{}", std::process::id());
    let sim = SimOptions::new(rig.clone())
        .seed(1)
        .control_prefix(&prefix)
        .spawn(&sim_session)
        .unwrap();
    let harness = net::open(net::zenoh_config(None, &[ep], &[]).unwrap()).unwrap();
    let statuses: Arc<Mutex<Vec<serde_json::Value>>> = Arc::default();
    let sink = statuses.clone();
    let _sub = harness
        .declare_subscriber(format!("{prefix}/task"))
        .callback(move |s| {
            sink.lock()
                .unwrap()
                .push(serde_json::from_slice(&s.payload().to_bytes()).unwrap());
        })
        .wait()
        .unwrap();
    let seed_seen = |seed: u64| statuses.lock().unwrap().iter().any(|v| v["seed"] == seed);
    assert!(wait_until(10.0, || seed_seen(1)), "no status for seed 1");
    let want = Task::new(&Scene::new(&rig), 7);
    assert_ne!(
        sim.task().cubes[0].position_m,
        want.cubes[0].position.to_array()
    );
    assert!(wait_until(10.0, || {
        harness.put(format!("{prefix}/reset"), "7").wait().unwrap();
        seed_seen(7)
    }));
    let status = statuses
        .lock()
        .unwrap()
        .iter()
        .rev()
        .find(|v| v["seed"] == 7)
        .cloned()
        .unwrap();
    for (k, cube) in want.cubes.iter().enumerate() {
        let json = &status["cubes"][k];
        for d in 0..3 {
            assert!((json["position_m"][d].as_f64().unwrap() - cube.position[d]).abs() < 1e-9);
            assert!((json["target_m"][d].as_f64().unwrap() - cube.target[d]).abs() < 1e-9);
        }
        assert_eq!(json["held_by"], serde_json::Value::Null);
        assert_eq!(json["placed"], false);
    }
    assert_eq!(status["success"], false);
    assert_eq!(status["operator"], serde_json::Value::Null);
    assert_eq!(sim.task().seed, 7);
    drop(sim);
    let _ = harness.close().wait();
    let _ = sim_session.close().wait();
}

/// A camera asked for more frames than the machine renders drops frames instead of falling
/// behind: its stamps stay on real time (a backlog would stamp frames further and further in
/// the past, until an episode's images no longer overlap its joints), at a lower rate.
#[test]
fn a_camera_that_cannot_keep_up_skips_frames_and_stays_on_real_time() {
    let mut rig = Rig::builtin("franka_sim").unwrap();
    rig.cameras.truncate(1);
    rig.cameras[0].width = 320;
    rig.cameras[0].height = 240;
    rig.cameras[0].fps = 5000.0;
    let topic = rig.cameras[0].topic.clone();
    let session = net::open(net::zenoh_config(None, &[], &[endpoint()]).unwrap()).unwrap();
    // (capture stamp, time seen) of every frame.
    let got: Arc<Mutex<Vec<(u64, u64)>>> = Arc::default();
    let sink = got.clone();
    let cam = topic.clone();
    let sim = SimOptions::new(rig)
        .on_publish(Arc::new(move |t, payload| {
            if t == cam {
                let stamp = header_stamp(payload).unwrap().as_ns();
                sink.lock()
                    .unwrap()
                    .push((stamp, scaledp_recorder::now_ns()));
            }
        }))
        .spawn(&session)
        .unwrap();
    let started = Instant::now();
    assert!(wait_until(30.0, || started.elapsed() >= Duration::from_secs(2)));
    sim.stop();
    session.close().wait().unwrap();
    let got = got.lock().unwrap();
    let span_s = started.elapsed().as_secs_f64();
    assert!(got.len() > 20, "{} frames in {span_s:.1} s", got.len());
    assert!(
        (got.len() as f64) < 0.5 * 5000.0 * span_s,
        "{} frames in {span_s:.1} s: nothing was skipped",
        got.len()
    );
    // Stamps follow the clock: the newest frames are not older than the first ones were.
    let lag_ms = |&(stamp, seen): &(u64, u64)| seen.saturating_sub(stamp) as f64 * 1e-6;
    let early = got[..10].iter().map(lag_ms).fold(0.0, f64::max);
    let late = got[got.len() - 10..].iter().map(lag_ms).fold(0.0, f64::max);
    assert!(
        late < early + 100.0,
        "{topic}: frames lag the clock by {late:.0} ms at the end, {early:.0} ms at the start"
    );
}
