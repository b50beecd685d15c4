//! gym-aloha behind the bridge protocol (needs `.venv-sims`: `scripts/setup-sims.sh`, which
//! `scripts/test.sh` runs): the ViperX's forward kinematics against the simulator's own
//! `gripper_link`, the scripted experts and their joint commands replayed through `step`, and
//! clear errors.
#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use glam::{DMat3, DMat4, DQuat};
use scaledp_converter::live::ArmKinematics;
use scaledp_schema::Rig;
use scaledp_sim::bridge::Bridge;
use scaledp_sim::ArmCommand;

fn rig(task: &str) -> Rig {
    Rig::load_or_builtin(&format!("aloha/{task}")).unwrap()
}

/// The rig's FK (gym-aloha's ViperX chain, from each arm's root body to `gripper_link`)
/// against the simulator's own `gripper_link` pose in that root body, at every 5th step of an
/// expert episode of each task, both arms: within 1 mm and 1 mrad.
#[test]
fn viperx_kinematics_match_alohas_gripper_link() {
    let (mut worst_m, mut worst_rad, mut poses) = (0f64, 0f64, 0);
    for task in ["transfer-cube", "insertion"] {
        let rig = rig(task);
        let kin: Vec<ArmKinematics> = rig
            .arms
            .iter()
            .map(|a| ArmKinematics::new(a).unwrap())
            .collect();
        let mut bridge = Bridge::spawn(&rig).unwrap();
        let mut obs = bridge.reset(1, false).unwrap();
        for step in 0..400 {
            if step % 5 == 0 {
                for (k, a) in kin.iter().zip(&obs.arms) {
                    let fk: DMat4 = k.base_from_tcp(&a.q).unwrap();
                    let sim = a.flange_pose();
                    let dp = (fk.w_axis - sim.w_axis).truncate().length();
                    let qa = DQuat::from_mat3(&DMat3::from_mat4(fk));
                    let qb = DQuat::from_mat3(&DMat3::from_mat4(sim));
                    worst_m = worst_m.max(dp);
                    worst_rad = worst_rad.max(qa.angle_between(qb));
                    poses += 1;
                }
            }
            if obs.done {
                break;
            }
            obs = bridge.expert_step(false).unwrap();
        }
    }
    eprintln!(
        "{poses} poses: FK vs ALOHA's gripper_link at most {:.2e} m and {:.2e} rad apart",
        worst_m, worst_rad
    );
    assert!(poses >= 300, "{poses} poses");
    assert!(worst_m < 1e-3, "{} mm", worst_m * 1e3);
    assert!(worst_rad < 1e-3, "{} mrad", worst_rad * 1e3);
}

/// Each task's expert succeeds on a seed, reporting joint targets and gripper openings; those
/// commands replayed through `step` reproduce its success and its end pose; a seed fixes the
/// scene and another moves the objects. Its reward climbs gym-aloha's four named stages, the
/// last one being the success.
#[test]
fn experts_succeed_and_their_joint_commands_replay() {
    for (task, seed) in [("transfer-cube", 2u64), ("insertion", 3)] {
        let rig = rig(task);
        let mut bridge = Bridge::spawn(&rig).unwrap();
        assert_eq!(bridge.step_ns(), 20_000_000, "ALOHA steps at 50 Hz");
        let a = bridge.reset(seed, true).unwrap();
        let b = bridge.reset(seed, true).unwrap();
        let c = bridge.reset(seed + 10, true).unwrap();
        assert_eq!(a.images.len(), 1);
        assert_eq!(a.images[0].len(), 128 * 96 * 3);
        assert_eq!(a.images, b.images, "{task}: seed {seed} twice");
        assert_ne!(a.images, c.images, "{task}: another seed moves the objects");
        let behaviour = bridge.hello().versions.get("scaledp-bridge").cloned();
        assert!(
            behaviour
                .as_deref()
                .is_some_and(|v| v.parse::<u32>().is_ok()),
            "{task}: {behaviour:?}"
        );
        assert_eq!(
            bridge.hello().stages.len(),
            4,
            "{task}: {:?}",
            bridge.hello()
        );
        let mut obs = bridge.reset(seed, false).unwrap();
        let mut commands: Vec<Vec<ArmCommand>> = Vec::new();
        // The first step at which the reward reached each stage.
        let mut reached: [Option<u64>; 4] = [None; 4];
        while !obs.done {
            obs = bridge.expert_step(false).unwrap();
            assert_eq!(obs.success, obs.reward >= 4.0, "{task}: step {}", obs.step);
            for (k, r) in reached.iter_mut().enumerate() {
                if obs.reward >= (k + 1) as f64 {
                    r.get_or_insert(obs.step);
                }
            }
            assert_eq!(obs.commands.len(), 2);
            for c in &obs.commands {
                assert_eq!(c.joints.as_ref().map(Vec::len), Some(6), "{task}: {c:?}");
                assert!(c.pose.is_none());
                let w = c.gripper_width_m.unwrap();
                assert!((0.0..=0.117).contains(&w), "{task}: gripper {w}");
            }
            commands.push(obs.commands.clone());
        }
        assert!(obs.succeeded, "{task}: the expert succeeds on seed {seed}");
        let steps: Vec<u64> = reached.iter().map(|r| r.unwrap()).collect();
        assert!(steps.windows(2).all(|w| w[0] <= w[1]), "{task}: {steps:?}");
        assert_eq!(obs.step, 400, "{task}: ALOHA's episodes are 400 steps");
        let mut replay = bridge.reset(seed, false).unwrap();
        for c in &commands {
            replay = bridge.step(c, false).unwrap();
        }
        assert!(replay.succeeded, "{task}: the replay succeeds too");
        let gap = (0..2)
            .flat_map(|k| obs.arms[k].q.iter().zip(&replay.arms[k].q))
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(gap < 1e-6, "{task}: the replay ends {gap} rad away");
    }
}

/// Bad input is one clear error and the bridge keeps serving: a TCP pose where ALOHA takes
/// joints, the wrong number of arms or joints, an unknown task.
#[test]
fn bad_commands_are_one_clear_error() {
    let e = Rig::load_or_builtin("aloha/juggle")
        .unwrap_err()
        .to_string();
    assert!(e.contains("transfer-cube, insertion"), "{e}");
    let rig = rig("transfer-cube");
    let mut bridge = Bridge::spawn(&rig).unwrap();
    bridge.reset(0, false).unwrap();
    let pose = ArmCommand {
        pose: Some(DMat4::IDENTITY),
        ..ArmCommand::default()
    };
    let e = bridge
        .step(&[pose.clone(), pose], false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("joint targets"), "{e}");
    let e = bridge
        .step(&[ArmCommand::default()], false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("two arms"), "{e}");
    let five = ArmCommand {
        joints: Some(vec![0.0; 5]),
        ..ArmCommand::default()
    };
    let e = bridge
        .step(&[five, ArmCommand::default()], false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("5 joint targets"), "{e}");
    // Still serving; no command holds the starting posture.
    let start = bridge.reset(0, false).unwrap();
    let held = bridge.step(&vec![ArmCommand::default(); 2], false).unwrap();
    let drift = start.arms[0]
        .q
        .iter()
        .zip(&held.arms[0].q)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(drift < 0.02, "holding the start drifts {drift} rad");
}

/// The rig's zoom reaches the simulator: the top camera renders at the rig's
/// `vertical_fov_deg`, and the cube then covers at least twice the pixels it covers at
/// gym-aloha's own 78°; a field of view out of range is refused when the rig loads.
#[test]
fn the_rigs_zoom_enlarges_the_cube() {
    let red_pixels = |rig: &Rig| {
        let mut bridge = Bridge::spawn(rig).unwrap();
        let fovy = bridge.hello().cameras[0].fovy_deg;
        let obs = bridge.reset(1_000_000, true).unwrap();
        let red = obs.images[0]
            .chunks_exact(3)
            .filter(|p| p[0] > 150 && p[1] < 80 && p[2] < 80)
            .count();
        (fovy, red)
    };
    let zoomed = rig("transfer-cube");
    let want = zoomed.cameras[0].vertical_fov_deg.unwrap();
    let mut wide = zoomed.clone();
    wide.cameras[0].vertical_fov_deg = None;
    let (fovy_zoomed, red_zoomed) = red_pixels(&zoomed);
    let (fovy_wide, red_wide) = red_pixels(&wide);
    eprintln!("cube: {red_wide} px at {fovy_wide}°, {red_zoomed} px at {fovy_zoomed}°");
    assert_eq!(fovy_zoomed, want);
    assert_eq!(fovy_wide, 78.0);
    assert!(
        red_wide > 0 && red_zoomed >= 2 * red_wide,
        "{red_wide} → {red_zoomed} px"
    );

    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../rigs/aloha.toml");
    let text = std::fs::read_to_string(path)
        .unwrap()
        .replace("TASK", "transfer-cube")
        .replace("vertical_fov_deg = 45.0", "vertical_fov_deg = 190.0");
    let e = Rig::parse(&text, std::path::Path::new(path))
        .unwrap_err()
        .to_string();
    assert!(e.contains("vertical_fov_deg 190"), "{e}");
}
