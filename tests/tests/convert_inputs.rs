//! `scaledp convert` on inputs the other end-to-end tests leave out: foreign bags without a rig
//! (detected from joint names and message types), `CompressedImage` cameras (JPEG and PNG), and
//! an episode whose end-effector yaw runs past ±π.

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::f64::consts::{PI, TAU};
use std::path::Path;

use crate::convert_common::{convert_cli, convert_ok};
use scaledp_schema::msg::JointState;
use scaledp_schema::rig::{CameraModel, GripperModel};
use scaledp_schema::{Rig, RobotModel, RosMessage};
use scaledp_tests::{
    check_dataset, f32_column, f32_rows, make_bags, run_python, small_bimanual, T0,
};

/// The rig `info.json` records (its `scaledp.rig` TOML).
fn recorded_rig(ds: &Path) -> Rig {
    let info = scaledp_tests::read_json(&ds.join("meta/info.json"));
    Rig::parse(
        info["scaledp"]["rig"].as_str().unwrap(),
        Path::new("info.json"),
    )
    .unwrap()
}

/// Distance between two angles on the circle.
fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(TAU);
    d.min(TAU - d)
}

/// Every state row is the forward kinematics (to the arm's default TCP) of the joint row beside
/// it, angles compared on the circle; the gripper opening comes from the gripper joints.
fn assert_state_is_fk(rig: &Rig, state: &[Vec<f32>], joints: &[Vec<f32>]) {
    assert_eq!(state.len(), joints.len());
    assert!(!state.is_empty());
    for (t, (s, j)) in state.iter().zip(joints).enumerate() {
        let mut at = 0;
        for (a, arm) in rig.arms.iter().enumerate() {
            let q: Vec<f64> = j[at..at + arm.joint_names.len()]
                .iter()
                .map(|&x| f64::from(x))
                .collect();
            at += q.len();
            let flange = arm.model.base_from_flange(&q).unwrap();
            let pose = scaledp_schema::kinematics::pose6_from_transform(
                flange * arm.model.default_flange_from_tcp(),
            );
            for (d, want) in pose.iter().enumerate() {
                let got = f64::from(s[a * 7 + d]);
                let err = if d < 3 {
                    (got - want).abs()
                } else {
                    angle_gap(got, *want)
                };
                assert!(err < 1e-4, "tick {t} arm {a} dim {d}: {got} vs {want}");
            }
            let g = arm.gripper.as_ref().unwrap();
            let gq: Vec<f64> = j[at..at + g.joint_names.len()]
                .iter()
                .map(|&x| f64::from(x))
                .collect();
            at += gq.len();
            assert!((f64::from(s[a * 7 + 6]) - g.model.width_m(&gq)).abs() < 1e-6);
        }
        assert_eq!(at, j.len(), "every joint column is accounted for");
    }
}

/// The interval of first-tick times (ns) under which every chosen message `chosen[t]` is the
/// latest of `stamps` at or before tick `t` (first tick + `ts[t]`). Empty when none is.
fn tick_origin_bounds(stamps: &[u64], chosen: &[usize], ts: &[f32]) -> (i128, i128) {
    const SLACK_NS: i128 = 1_000; // f32 timestamps of a few seconds round within ~0.2 µs
    let (mut lo, mut hi) = (i128::MIN, i128::MAX);
    for (&k, &t) in chosen.iter().zip(ts) {
        let t = (f64::from(t) * 1e9).round() as i128;
        lo = lo.max(i128::from(stamps[k]) - t - SLACK_NS);
        if let Some(&next) = stamps.get(k + 1) {
            hi = hi.min(i128::from(next) - t + SLACK_NS);
        }
    }
    (lo, hi)
}

#[test]
fn a_foreign_ur_bag_with_compressed_cameras_converts_without_a_rig() {
    let dir = tempfile::tempdir().unwrap();
    let bags = dir.path().join("bags");
    let expected = run_python("make_foreign_bags.py", &[&bags]);
    let ds = dir.path().join("ds");
    let bag = bags.join("ur_compressed");
    convert_ok(
        &[
            bag.as_os_str(),
            "--task".as_ref(),
            "fold the towel".as_ref(),
            "--out".as_ref(),
            ds.as_os_str(),
        ],
        "1 converted",
    );
    let v = check_dataset(&ds);

    // The detected rig: two UR5 arms named by their joint prefix, each with its Robotiq, two
    // compressed cameras named by their topic, rates measured from the bag.
    let rig = recorded_rig(&ds);
    assert_eq!(rig.name, "detected");
    assert_eq!(rig.control_rate_hz, 10.0);
    let arms: Vec<(&str, RobotModel, &str, f64)> = rig
        .arms
        .iter()
        .map(|a| {
            (
                a.name.as_str(),
                a.model,
                a.joint_state_topic.as_str(),
                a.rate_hz,
            )
        })
        .collect();
    assert_eq!(
        arms,
        [
            ("left", RobotModel::Ur5, "/left/joint_states", 125.0),
            ("right", RobotModel::Ur5, "/right/joint_states", 125.0)
        ]
    );
    for arm in &rig.arms {
        assert_eq!(
            arm.joint_names[0],
            format!("{}_shoulder_pan_joint", arm.name)
        );
        let g = arm.gripper.as_ref().expect("the Robotiq is found");
        assert_eq!(g.model, GripperModel::Robotiq2f85);
        assert_eq!(g.topic, format!("/{}/gripper/joint_states", arm.name));
    }
    let cams: Vec<(&str, &str, bool, f64)> = rig
        .cameras
        .iter()
        .map(|c| (c.name.as_str(), c.topic.as_str(), c.compressed, c.fps))
        .collect();
    assert_eq!(
        cams,
        [
            (
                "cam_high",
                "/cam_high/color/image_raw/compressed",
                true,
                30.0
            ),
            (
                "cam_wrist",
                "/cam_wrist/color/image_raw/compressed",
                true,
                30.0
            )
        ]
    );
    let names: Vec<String> = ["left", "right"]
        .iter()
        .flat_map(|a| {
            ["x", "y", "z", "roll", "pitch", "yaw", "gripper"].map(|d| format!("{a}_{d}"))
        })
        .collect();
    assert_eq!(v["features"]["observation.state"], serde_json::json!(names));
    let (state, joints) = (
        f32_rows(&ds, "observation.state"),
        f32_rows(&ds, "observation.joints"),
    );
    assert_eq!((state[0].len(), joints[0].len()), (14, 14));
    assert_state_is_fk(&rig, &state, &joints);

    // Frames: as many as ticks, each decoded from the JPEG / PNG it was chosen from. The top
    // half of frame k is k in binary (eight black or white stripes), the bottom half is
    // (200, G, 40) left and (40, G, 200) right: a channel swap, a flip or a mix-up of cameras
    // shows in those.
    let frames = v["frames"].as_u64().unwrap() as usize;
    assert!(frames > 20, "{frames} frames");
    let ts = f32_column(&ds, "timestamp");
    assert_eq!(ts.len(), frames);
    let colours = run_python("frame_colours.py", &[&ds, Path::new("8"), Path::new("2")]);
    let mut origin = (i128::MIN, i128::MAX);
    for cam in &rig.cameras {
        let e = &expected["cameras"][&cam.topic];
        let green = e["green"].as_f64().unwrap();
        let stamps: Vec<u64> = e["stamps_ns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_u64().unwrap())
            .collect();
        let rows = colours[format!("observation.images.{}", cam.name)]
            .as_array()
            .unwrap();
        assert_eq!(rows.len(), frames, "{}", cam.name);
        let mut chosen = Vec::new();
        for (t, row) in rows.iter().enumerate() {
            let cell: Vec<[f64; 3]> = serde_json::from_value(row.clone()).unwrap();
            let mut k = 0;
            for (bit, c) in cell[..8].iter().enumerate() {
                let level = (c[0] + c[1] + c[2]) / 3.0;
                assert!(
                    !(30.0..=225.0).contains(&level),
                    "{} frame {t}: stripe {bit} is {c:?}",
                    cam.name
                );
                k |= usize::from(level > 128.0) << bit;
            }
            for (i, c) in cell[8..].iter().enumerate() {
                let want = if i < 4 {
                    [200.0, green, 40.0]
                } else {
                    [40.0, green, 200.0]
                };
                let err = (0..3).map(|d| (c[d] - want[d]).abs()).fold(0.0, f64::max);
                assert!(
                    err < 6.0,
                    "{} ({}) frame {t} cell {i}: {c:?}, want {want:?}",
                    cam.name,
                    e["format"]
                );
            }
            assert!(k < stamps.len(), "{} frame {t}: k = {k}", cam.name);
            chosen.push(k);
        }
        // The latest frame at or before each tick, ticks 100 ms apart.
        let (lo, hi) = tick_origin_bounds(&stamps, &chosen, &ts);
        assert!(lo <= hi, "{}: frames {chosen:?} fit no tick grid", cam.name);
        origin = (origin.0.max(lo), origin.1.min(hi));
    }
    assert!(origin.0 <= origin.1, "the cameras fit different tick grids");
    assert!(origin.0 >= expected["t0_ns"].as_i64().unwrap() as i128);
}

#[test]
fn a_franka_ros1_bag_without_a_rig_is_detected_as_fr3_with_its_hand() {
    let dir = tempfile::tempdir().unwrap();
    let bags = dir.path().join("bags");
    make_bags(&bags);
    let ds = dir.path().join("ds");
    let bag = bags.join("franka_ros1_bz2.bag");
    convert_ok(
        &[
            bag.as_os_str(),
            "--task".as_ref(),
            "t".as_ref(),
            "--out".as_ref(),
            ds.as_os_str(),
        ],
        "1 converted",
    );
    let v = check_dataset(&ds);
    let rig = recorded_rig(&ds);
    assert_eq!(rig.name, "detected");
    assert_eq!(rig.arms.len(), 1);
    let arm = &rig.arms[0];
    assert_eq!(
        (arm.name.as_str(), arm.model, arm.joint_state_topic.as_str()),
        ("arm", RobotModel::Fr3, "/franka/joint_states")
    );
    let fr3: Vec<String> = (1..=7).map(|i| format!("fr3_joint{i}")).collect();
    assert_eq!(arm.joint_names, fr3);
    // Rates are measured (median log-time interval): 1 kHz with ±0.5 ms jitter reads as about.
    assert!((990.0..=1010.0).contains(&arm.rate_hz), "{}", arm.rate_hz);
    let g = arm.gripper.as_ref().expect("the Franka Hand is found");
    assert_eq!(
        (g.model, g.topic.as_str()),
        (GripperModel::FrankaHand, "/franka_gripper/joint_states")
    );
    assert!((49.0..=51.0).contains(&g.rate_hz), "{}", g.rate_hz);
    assert_eq!(g.joint_names, ["fr3_finger_joint1", "fr3_finger_joint2"]);
    let cams: Vec<(&str, CameraModel, u32, u32, &str, bool)> = rig
        .cameras
        .iter()
        .map(|c| {
            (
                c.name.as_str(),
                c.model,
                c.width,
                c.height,
                c.encoding(),
                c.compressed,
            )
        })
        .collect();
    assert_eq!(
        cams,
        [
            ("zed_front", CameraModel::Zed, 64, 48, "bgra8", false),
            ("zed_wrist", CameraModel::Zed, 64, 48, "bgra8", false)
        ]
    );
    assert_eq!(
        v["features"]["observation.state"],
        serde_json::json!(["x", "y", "z", "roll", "pitch", "yaw", "gripper"])
    );
    let mut joint_names = fr3.clone();
    joint_names.extend(["fr3_finger_joint1".into(), "fr3_finger_joint2".into()]);
    assert_eq!(
        v["features"]["observation.joints"],
        serde_json::json!(joint_names)
    );
    let state = f32_rows(&ds, "observation.state");
    assert_eq!(state[0].len(), 7);
    assert_state_is_fk(&rig, &state, &f32_rows(&ds, "observation.joints"));
}

#[test]
fn a_yaw_sweeping_past_pi_is_unwrapped_in_state_and_action() {
    // The left UR5's shoulder pan sweeps 6.5 rad in 3 s: its tool's yaw crosses ±π (twice the
    // way round is impossible, so a wrapped column could never span more than 2π).
    let dir = tempfile::tempdir().unwrap();
    let rig = small_bimanual();
    let ep = dir.path().join("episode_000000.mcap");
    let seconds = 3.0;
    let start = T0 + 600_000_000_000;
    let pan = |stamp: u64| -3.0 + 6.5 * ((stamp - start) as f64 * 1e-9 / seconds).min(1.0);
    let mut sweep = |topic: &str, _k: u64, stamp: &mut u64, payload: &mut Vec<u8>| {
        if topic == "/left/joint_states" {
            let mut js = JointState::from_cdr(payload).unwrap();
            js.position[0] = pan(*stamp);
            *payload = js.to_cdr();
        }
    };
    scaledp_sim::synth::write_episode(&ep, &rig, 6, seconds, start, "sweep", &mut sweep).unwrap();
    let ds = dir.path().join("ds");
    let out = convert_cli(&[ep.as_os_str(), "--out".as_ref(), ds.as_os_str()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let v = check_dataset(&ds);
    let names = v["features"]["observation.state"].as_array().unwrap();
    let col = |name: &str| names.iter().position(|n| n == name).unwrap();
    let (state, action, joints) = (
        f32_rows(&ds, "observation.state"),
        f32_rows(&ds, "action"),
        f32_rows(&ds, "observation.joints"),
    );
    assert!(state.len() > 20);
    // The sweep reached the converter: the pan joint covers most of its range.
    let pans: Vec<f32> = joints.iter().map(|j| j[0]).collect();
    assert!(pans[0] < -2.5 && pans[pans.len() - 1] > 2.5, "{pans:?}");

    let yaw: Vec<f64> = state
        .iter()
        .map(|s| f64::from(s[col("left_yaw")]))
        .collect();
    let max_abs = yaw.iter().fold(0.0f64, |m, y| m.max(y.abs()));
    assert!(max_abs > PI + 0.2, "yaw stays within ±π: {yaw:?}");
    let span =
        yaw.iter().copied().fold(f64::MIN, f64::max) - yaw.iter().copied().fold(f64::MAX, f64::min);
    assert!(
        span > TAU - 0.5,
        "the yaw column spans only {span}: {yaw:?}"
    );
    // No column of either arm jumps between ticks (roll sits near ±π and is unwrapped too).
    for name in names {
        let c = col(name.as_str().unwrap());
        for t in 1..state.len() {
            let step = (state[t][c] - state[t - 1][c]).abs();
            assert!(step < 0.5, "{name} jumps by {step} at tick {t}");
        }
    }
    // The values are still the arm's pose: FK of the joints, on the circle.
    assert_state_is_fk(&rig, &state, &joints);
    for t in 0..state.len() - 1 {
        assert_eq!(action[t], state[t + 1], "tick {t}");
    }
}
