//! `scaledp convert` end to end: every input format into one LeRobot dataset checked with
//! pyarrow against LeRobot's own files; bad inputs; 14-D bimanual; splits on time gaps; command
//! topics and joint-space actions. (A killed job and shards: `convert_resume`.)

#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use std::path::Path;

use crate::convert_common::convert_cli;
use scaledp_schema::msg::{Image, JointState};
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::synth::write_episode;
use scaledp_tests::{
    check_dataset, f32_rows, make_bags, small_bimanual, small_franka, synth_episode,
    write_rig_file, T0,
};

#[test]
fn every_input_format_converts_into_one_lerobot_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let bags = dir.path().join("bags");
    make_bags(&bags);
    let rig = small_franka();
    synth_episode(&bags.join("episode_000000.mcap"), &rig, 1, 3.0);
    let ds = dir.path().join("ds");
    let rig_path = write_rig_file(dir.path(), &rig);
    let out = convert_cli(&[
        bags.as_os_str(),
        "--rig".as_ref(),
        rig_path.as_os_str(),
        "--task".as_ref(),
        "pick up the cube".as_ref(),
        "--out".as_ref(),
        ds.as_os_str(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("6 converted"), "{stdout}");
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], 6);
    // The recorder episode (sorted first) keeps its own task; bags store none and get --task.
    let tasks: Vec<&str> = v["tasks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap())
        .collect();
    assert_eq!(tasks, ["stack the cubes", "pick up the cube"]);
    let names = &v["features"]["observation.state"];
    assert_eq!(
        names,
        &serde_json::json!(["x", "y", "z", "roll", "pitch", "yaw", "gripper"])
    );
    assert_eq!(v["info"]["fps"], 10);
    assert_eq!(
        v["info"]["features"]["observation.images.front"]["shape"],
        serde_json::json!([240, 320, 3])
    );

    // A second run skips everything already converted (by content hash).
    let again = convert_cli(&[
        bags.as_os_str(),
        "--rig".as_ref(),
        rig_path.as_os_str(),
        "--task".as_ref(),
        "x".as_ref(),
        "--out".as_ref(),
        ds.as_os_str(),
    ]);
    let stdout = String::from_utf8_lossy(&again.stdout);
    assert!(
        stdout.contains("0 converted") && stdout.contains("6 skipped"),
        "{stdout}"
    );
}

/// Plants one fault in an otherwise good episode.
fn faulty(path: &Path, rig: &Rig, seed: u64, fault: &str) {
    let mut f = |topic: &str, k: u64, _stamp: &mut u64, payload: &mut Vec<u8>| {
        let cam = topic.contains("image");
        match fault {
            "corrupt_cdr" if !cam && topic.contains("franka/") && k == 50 => payload.truncate(9),
            "wrong_step" if cam => {
                let mut img = Image::from_cdr(payload).unwrap();
                img.step = img.width * 4 - 1;
                *payload = img.to_cdr();
            }
            "nan_joint" if topic == "/franka/joint_states" && k == 700 => {
                let mut js = JointState::from_cdr(payload).unwrap();
                js.position[3] = f64::NAN;
                *payload = js.to_cdr();
            }
            "backwards" if cam && topic.contains("front") && k == 20 => {
                let mut img = Image::from_cdr(payload).unwrap();
                img.header.stamp =
                    scaledp_schema::msg::Time::from_ns(img.header.stamp.as_ns() - 300_000_000);
                *payload = img.to_cdr();
            }
            _ => {}
        }
    };
    write_episode(
        path,
        rig,
        seed,
        2.5,
        T0 + seed * 100_000_000_000,
        "t",
        &mut f,
    )
    .unwrap();
}

#[test]
fn bad_inputs_get_one_clear_line_each_and_the_rest_convert() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir_all(&inp).unwrap();
    let rig = small_franka();
    synth_episode(&inp.join("a_good.mcap"), &rig, 1, 2.5);
    let good = std::fs::read(inp.join("a_good.mcap")).unwrap();
    std::fs::write(inp.join("truncated.mcap"), &good[..good.len() / 2]).unwrap();
    {
        let mut w = mcap::WriteOptions::new()
            .profile("")
            .create(std::io::BufWriter::new(
                std::fs::File::create(inp.join("wrong_profile.mcap")).unwrap(),
            ))
            .unwrap();
        w.finish().unwrap();
    }
    for (i, fault) in ["corrupt_cdr", "wrong_step", "nan_joint", "backwards"]
        .iter()
        .enumerate()
    {
        faulty(
            &inp.join(format!("{fault}.mcap")),
            &rig,
            10 + i as u64,
            fault,
        );
    }
    let mut no_wrist = rig.clone();
    no_wrist.cameras.pop();
    synth_episode(&inp.join("missing_camera.mcap"), &no_wrist, 20, 2.5);
    let mut renamed = rig.clone();
    renamed.arms[0].joint_names[6] = "fr3_joint7_renamed".into();
    synth_episode(&inp.join("missing_joint.mcap"), &renamed, 21, 2.5);
    synth_episode(&inp.join("z_good.mcap"), &rig, 2, 2.5);

    let ds = dir.path().join("ds");
    let rig_path = write_rig_file(dir.path(), &rig);
    let out = convert_cli(&[
        inp.as_os_str(),
        "--rig".as_ref(),
        rig_path.as_os_str(),
        "--out".as_ref(),
        ds.as_os_str(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(3),
        "finished but lost data: {stdout}"
    );
    assert!(
        stdout.contains("2 converted") && stdout.contains("8 failed"),
        "{stdout}"
    );
    let expect = [
        ("truncated.mcap", "truncated or corrupt MCAP"),
        ("wrong_profile.mcap", "profile is '', expected 'ros2'"),
        ("corrupt_cdr.mcap", "bad CDR"),
        ("wrong_step.mcap", "step 255 is smaller than width 64"),
        (
            "nan_joint.mcap",
            "joint 'fr3_joint4' on /franka/joint_states is NaN",
        ),
        (
            "backwards.mcap",
            "time runs backwards on /zed_front/zed_node/rgb/color/rect/image",
        ),
        (
            "missing_camera.mcap",
            "camera 'wrist' (/zed_wrist/zed_node/rgb/color/rect/image) has no messages",
        ),
        (
            "missing_joint.mcap",
            "joint 'fr3_joint7' is missing from /franka/joint_states",
        ),
    ];
    for (file, reason) in expect {
        let lines: Vec<&str> = stdout
            .lines()
            .filter(|l| l.starts_with("failed: ") && l.contains(file))
            .collect();
        assert_eq!(lines.len(), 1, "{file}: {stdout}");
        assert!(
            lines[0].contains(&inp.join(file).display().to_string()),
            "names the file: {}",
            lines[0]
        );
        assert!(
            lines[0].contains(reason),
            "{file}: expected '{reason}' in '{}'",
            lines[0]
        );
    }
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], 2);
}

#[test]
fn bimanual_state_is_14d_in_rig_order_and_matches_forward_kinematics() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_bimanual();
    let ep = dir.path().join("episode_000000.mcap");
    synth_episode(&ep, &rig, 4, 3.0);
    let ds = dir.path().join("ds");
    let out = convert_cli(&[ep.as_os_str(), "--out".as_ref(), ds.as_os_str()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let v = check_dataset(&ds);
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
    for (s, j) in state.iter().zip(&joints) {
        for arm in 0..2 {
            let q: Vec<f64> = j[arm * 7..arm * 7 + 6]
                .iter()
                .map(|&x| f64::from(x))
                .collect();
            let pose = scaledp_schema::kinematics::pose6_from_transform(
                rig.arms[arm].model.base_from_flange(&q).unwrap(),
            );
            for d in 0..6 {
                let diff = (f64::from(s[arm * 7 + d]) - pose[d]).rem_euclid(std::f64::consts::TAU);
                assert!(
                    diff.min(std::f64::consts::TAU - diff) < 1e-4,
                    "arm {arm} dim {d}: {} vs {}",
                    s[arm * 7 + d],
                    pose[d]
                );
            }
            let width = rig.arms[arm]
                .gripper
                .as_ref()
                .unwrap()
                .model
                .width_m(&[f64::from(j[arm * 7 + 6])]);
            assert!((f64::from(s[arm * 7 + 6]) - width).abs() < 1e-6);
        }
    }
}

#[test]
fn a_long_recording_splits_on_time_gaps() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let (a, b) = (dir.path().join("a.mcap"), dir.path().join("b.mcap"));
    synth_episode(&a, &rig, 0, 2.5);
    synth_episode(&b, &rig, 1, 3.0); // starts 100 s after the first
                                     // One file holding both, as a long session bag would.
    let long = dir.path().join("session.mcap");
    {
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .create(std::io::BufWriter::new(
                std::fs::File::create(&long).unwrap(),
            ))
            .unwrap();
        for part in [&a, &b] {
            let bytes = std::fs::read(part).unwrap();
            for m in mcap::MessageStream::new(&bytes).unwrap() {
                w.write(&m.unwrap()).unwrap();
            }
        }
        w.finish().unwrap();
    }
    let ds = dir.path().join("ds");
    let rig_path = write_rig_file(dir.path(), &rig);
    let args = [
        long.as_os_str(),
        "--rig".as_ref(),
        rig_path.as_os_str(),
        "--task".as_ref(),
        "t".as_ref(),
        "--split-gap".as_ref(),
        "5".as_ref(),
        "--out".as_ref(),
        ds.as_os_str(),
    ];
    let out = convert_cli(&args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.contains("2 converted"),
        "{stdout}"
    );
    assert!(
        stdout.contains("session.mcap#0") && stdout.contains("session.mcap#1"),
        "{stdout}"
    );
    let v = check_dataset(&ds);
    assert_eq!(v["episodes"], 2);
    // Both parts are in: a re-run skips the input.
    let again = convert_cli(&args);
    assert!(String::from_utf8_lossy(&again.stdout).contains("1 skipped"));
}

#[test]
fn a_command_topic_gives_the_action_instead_of_the_next_tick() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let ep = dir.path().join("episode_000000.mcap");
    synth_episode(&ep, &rig, 5, 3.0);
    let arm = &rig.arms[0];
    let run = |name: &str, extra: &[&std::ffi::OsStr]| {
        let ds = dir.path().join(name);
        let mut args = vec![ep.as_os_str(), "--out".as_ref(), ds.as_os_str()];
        args.extend_from_slice(extra);
        let out = convert_cli(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        (f32_rows(&ds, "observation.state"), f32_rows(&ds, "action"))
    };
    // Default: the action is the next tick's state.
    let (state, action) = run("next", &[]);
    for t in 0..state.len() - 1 {
        assert_eq!(action[t], state[t + 1], "tick {t}");
    }
    // The arm's own joint states named as its command topic (a leader arm that is the follower):
    // the action is the pose of the latest command at the tick, i.e. (about) the current state,
    // no longer the next tick's.
    let over = format!("{}_command={}", arm.name, arm.joint_state_topic);
    let (state, action) = run("cmd", &["--topic".as_ref(), over.as_ref()]);
    let (near_now, moving) = follows_now(&state, &action, 3);
    assert!(moving > 5, "the arm hardly moves: {moving} moving ticks");
    assert_eq!(near_now, moving, "the command's pose, not the next tick's");
    // A command topic without messages is a clear error for that file.
    let over = format!("{}_command=/no/such/topic", arm.name);
    let ds = dir.path().join("none");
    let out = convert_cli(&[
        ep.as_os_str(),
        "--out".as_ref(),
        ds.as_os_str(),
        "--topic".as_ref(),
        over.as_ref(),
    ]);
    let text = String::from_utf8_lossy(&out.stdout) + String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && text.contains("/no/such/topic"),
        "{text}"
    );
}

#[test]
fn joint_space_state_and_action_are_the_joints_in_rig_order() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_bimanual();
    let ep = dir.path().join("episode_000000.mcap");
    synth_episode(&ep, &rig, 6, 3.0);
    let ds = dir.path().join("ds");
    let convert = |extra: &[&str]| {
        let mut args = vec![ep.as_os_str(), "--out".as_ref(), ds.as_os_str()];
        args.extend(extra.iter().map(std::ffi::OsStr::new));
        convert_cli(&args)
    };
    let out = convert(&["--action", "joints"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let v = check_dataset(&ds);
    // LeRobot's naming: per arm its joints then its gripper, a joint named after its arm kept.
    let names: Vec<String> = rig
        .arms
        .iter()
        .flat_map(|a| {
            let mut n = a.joint_names.clone();
            n.push(format!("{}_gripper", a.name));
            n
        })
        .collect();
    assert_eq!(names[0], "left_shoulder_pan_joint");
    assert_eq!(v["features"]["observation.state"], serde_json::json!(names));
    assert_eq!(v["features"]["action"], serde_json::json!(names));
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(ds.join("meta/info.json")).unwrap()).unwrap();
    assert_eq!(info["scaledp"]["action_space"], "joints");
    let (state, action, joints) = (
        f32_rows(&ds, "observation.state"),
        f32_rows(&ds, "action"),
        f32_rows(&ds, "observation.joints"),
    );
    assert_eq!(state[0].len(), 14);
    for (t, (s, j)) in state.iter().zip(&joints).enumerate() {
        for arm in 0..2 {
            // Joints as measured (interpolated at the tick), the gripper as its opening.
            assert_eq!(
                &s[arm * 7..arm * 7 + 6],
                &j[arm * 7..arm * 7 + 6],
                "tick {t}"
            );
            let g = rig.arms[arm].gripper.as_ref().unwrap();
            let width = g.model.width_m(&[f64::from(j[arm * 7 + 6])]);
            assert!((f64::from(s[arm * 7 + 6]) - width).abs() < 1e-6);
        }
    }
    // No command topic carries joints here: the action is the next tick's joints.
    for t in 0..state.len() - 1 {
        assert_eq!(action[t], state[t + 1], "tick {t}");
    }
    // A TCP conversion cannot join a joint-space dataset: one clear line.
    let ep2 = dir.path().join("episode_000001.mcap");
    synth_episode(&ep2, &rig, 7, 2.0);
    let out = convert_cli(&[ep2.as_os_str(), "--out".as_ref(), ds.as_os_str()]);
    let text = String::from_utf8_lossy(&out.stdout) + String::from_utf8_lossy(&out.stderr);
    assert!(
        text.contains("tcp state and action, the dataset's are joints"),
        "{text}"
    );
}

#[test]
fn a_leader_arms_joint_states_are_the_joint_space_action() {
    let dir = tempfile::tempdir().unwrap();
    let rig = small_franka();
    let ep = dir.path().join("episode_000000.mcap");
    synth_episode(&ep, &rig, 5, 3.0);
    let arm = &rig.arms[0];
    // The arm's own joint states as its command topic (a leader arm that is the follower): the
    // action is the latest command's joints at the tick, i.e. the latest measured sample, no
    // longer the next tick's.
    let over = format!("{}_command={}", arm.name, arm.joint_state_topic);
    let ds = dir.path().join("ds");
    let out = convert_cli(&[
        ep.as_os_str(),
        "--out".as_ref(),
        ds.as_os_str(),
        "--action".as_ref(),
        "joints".as_ref(),
        "--topic".as_ref(),
        over.as_ref(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let (state, action) = (f32_rows(&ds, "observation.state"), f32_rows(&ds, "action"));
    let (near_now, moving) = follows_now(&state, &action, 7);
    assert!(moving > 5, "the arm hardly moves: {moving} moving ticks");
    assert_eq!(
        near_now, moving,
        "the command's joints, not the next tick's"
    );
}

/// Ticks where the state moves (more than 1 mm or 1 mrad over its first `dims` values), and
/// those among them whose action is within a quarter of that move of the state now: an action
/// that is the command at the tick, not the next tick's state.
fn follows_now(state: &[Vec<f32>], action: &[Vec<f32>], dims: usize) -> (usize, usize) {
    let dist = |a: &[f32], b: &[f32]| (0..dims).map(|d| (a[d] - b[d]).powi(2)).sum::<f32>().sqrt();
    let (mut near_now, mut moving) = (0, 0);
    for t in 0..state.len() - 1 {
        let step = dist(&state[t], &state[t + 1]);
        if step > 1e-3 {
            moving += 1;
            if dist(&action[t], &state[t]) < 0.25 * step {
                near_now += 1;
            }
        }
    }
    (near_now, moving)
}
