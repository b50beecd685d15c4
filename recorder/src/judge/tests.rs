//! The verdict on synthetic episodes: each rule of the converter that the recorder applies.

use scaledp_schema::msg::{Header, JointState, Time};
use scaledp_schema::rig::{Rig, TopicKind, TopicSpec};
use scaledp_schema::RosMessage;

use super::{judge, Evidence};

const T0: u64 = 1_700_000_000_000_000_000;

/// franka_2zed with its training streams only (no depth, camera_info, tf).
fn rig() -> Rig {
    Rig::builtin("franka_2zed")
        .expect("shipped rig")
        .training_streams()
}

fn joints(names: &[String], stamp_ns: u64) -> Vec<u8> {
    JointState {
        header: Header {
            stamp: Time::from_ns(stamp_ns),
            frame_id: String::new(),
        },
        name: names.to_vec(),
        position: vec![0.1; names.len()],
        velocity: vec![],
        effort: vec![],
    }
    .to_cdr()
}

/// Feeds every topic at its rate over `[0, seconds)`, but where `keep(topic, t_s)` says no.
fn feed(rig: &Rig, seconds: f64, keep: impl Fn(&TopicSpec, f64) -> bool) -> Evidence {
    let specs = rig.topics();
    let mut ev = Evidence::new(rig, &specs);
    // Interleaved in time, as they arrive.
    let mut msgs = Vec::new();
    for (i, s) in specs.iter().enumerate() {
        let n = (seconds * s.rate_hz) as u64;
        for k in 0..n {
            let t = k as f64 / s.rate_hz;
            if keep(s, t) {
                msgs.push(((t * 1e9) as u64, i));
            }
        }
    }
    msgs.sort_unstable();
    let names = |t: &str| -> Vec<String> {
        let a = &rig.arms[0];
        if t == a.joint_state_topic {
            a.joint_names.clone()
        } else {
            a.gripper.as_ref().expect("gripper").joint_names.clone()
        }
    };
    for (t, i) in msgs {
        let s = &specs[i];
        let stamp = T0 + t;
        let payload = match s.kind {
            TopicKind::Joints | TopicKind::Gripper => joints(&names(&s.topic), stamp),
            _ => Vec::new(),
        };
        // Arrival 20 ms after capture, header stamp read from the message.
        ev.message(i, Some(stamp), stamp + 20_000_000, &payload);
    }
    ev
}

#[test]
fn a_clean_episode_is_accepted_with_its_figures() {
    let rig = rig();
    let v = judge(&rig, "stack", &feed(&rig, 3.0, |_, _| true));
    assert!(v.accepted, "{v:?}");
    assert_eq!(v.reason, None);
    assert_eq!(v.invalid, 0);
    assert!(v.warnings.is_empty(), "{:?}", v.warnings);
    assert!((28..=30).contains(&v.ticks), "{}", v.ticks);
    assert!(v.max_camera_skew_s < 1e-3, "{}", v.max_camera_skew_s);
    let cam = &v.topics[0];
    assert_eq!(cam.messages, 90);
    assert!((cam.rate_hz - 30.0).abs() < 0.1 && (cam.max_gap_s - 1.0 / 30.0).abs() < 1e-3);
    assert!(v.line().starts_with("accepted: 2."), "{}", v.line());
}

#[test]
fn a_silent_camera_is_the_converters_reason() {
    let rig = rig();
    let wrist = rig.cameras[1].topic.clone();
    let v = judge(&rig, "stack", &feed(&rig, 2.0, |s, _| s.topic != wrist));
    assert!(!v.accepted);
    assert_eq!(
        v.reason.as_deref(),
        Some(format!("camera 'wrist' ({wrist}) has no messages").as_str())
    );
    // Not named twice.
    assert!(v.warnings.is_empty(), "{:?}", v.warnings);
}

#[test]
fn a_camera_that_stops_is_named_and_one_that_stalls_rejects_the_episode() {
    let rig = rig();
    let front = rig.cameras[0].topic.clone();
    // Stops after 1 s of 3: the converter keeps the first second.
    let v = judge(
        &rig,
        "stack",
        &feed(&rig, 3.0, |s, t| s.topic != front || t < 1.0),
    );
    assert!(v.accepted, "{v:?}");
    assert!(v.kept_s < 1.1, "{}", v.kept_s);
    assert_eq!(
        v.warnings,
        [format!("{front} stopped 2.0 s before the end")]
    );
    assert!(
        v.line().contains(&format!("│ {front} stopped 2.0 s")),
        "{}",
        v.line()
    );
    // Silent from 1 s to 2 s of 3: the ticks at 1.108 … 1.908 s have no frame younger than
    // 1.5 periods (the one at 1.008 s still has the frame of 0.967 s).
    let v = judge(
        &rig,
        "stack",
        &feed(&rig, 3.0, |s, t| {
            s.topic != front || !(1.0..2.0).contains(&t)
        }),
    );
    assert!(!v.accepted);
    let r = v.reason.expect("a reason");
    assert!(
        r.contains("ticks have a stale camera frame or a joint gap (limit 5 %)")
            && r.ends_with(&format!("{front} 9")),
        "{r}"
    );
}

#[test]
fn joints_missing_and_stamps_running_backwards_are_the_converters_reasons() {
    let rig = rig();
    let specs = rig.topics();
    let mut ev = Evidence::new(&rig, &specs);
    for (i, s) in specs.iter().enumerate() {
        let names = match s.kind {
            TopicKind::Joints => rig.arms[0].joint_names[..6].to_vec(),
            TopicKind::Gripper => vec!["fr3_finger_joint1".into(), "fr3_finger_joint2".into()],
            _ => vec![],
        };
        ev.message(i, Some(T0), T0, &joints(&names, T0));
    }
    let v = judge(&rig, "stack", &ev);
    assert!(
        v.reason.as_deref().is_some_and(
            |r| r.starts_with("joint 'fr3_joint7' is missing from /franka/joint_states")
        ),
        "{:?}",
        v.reason
    );

    let rig = self::rig();
    let mut ev = feed(&rig, 1.0, |_, _| true);
    // A frame stamped 0.2 s before the front camera's latest.
    ev.message(0, Some(T0 + 800_000_000), T0 + 2_000_000_000, &[]);
    let v = judge(&rig, "stack", &ev);
    assert!(
        v.reason.as_deref().is_some_and(|r| r.starts_with(&format!(
            "time runs backwards on {}: message 30 is stamped",
            rig.cameras[0].topic
        )) && r
            .ends_with("beyond the 0.100 s reorder window: a clock jump")),
        "{:?}",
        v.reason
    );
    // No task: the converter asks for one.
    let v = judge(&rig, "", &feed(&rig, 1.0, |_, _| true));
    assert_eq!(
        v.reason.as_deref(),
        Some("no task instruction: the recording stores none; pass --task")
    );
}
