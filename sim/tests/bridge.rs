//! MetaWorld behind the bridge protocol (needs `.venv-sims`: `scripts/setup-sims.sh`, which
//! `scripts/test.sh` runs): the Sawyer's forward kinematics against MetaWorld's own hand pose,
//! seeds that fix a scene, the expert's commands replayed through `step`, episodes that do not
//! inherit the last one's gripper, and clear errors.
#![allow(clippy::unwrap_used)] // test code: a panic is the failure report

use glam::{DMat3, DQuat};
use scaledp_converter::live::ArmKinematics;
use scaledp_schema::Rig;
use scaledp_sim::bridge::Bridge;
use scaledp_sim::ArmCommand;

fn rig(task: &str) -> Rig {
    Rig::load_or_builtin(&format!("metaworld/{task}")).unwrap()
}

/// The converter's TCP (the rig's FK to MetaWorld's `hand` body, then the rig's TCP frame)
/// against the simulator's own `hand` pose in the same TCP frame, at every step of expert
/// episodes of four tasks (one per level): within 1 mm and 1 mrad; and MetaWorld's fixed hand
/// orientation is near roll = pitch = yaw = 0 in that frame (far from the gimbal lock at
/// pitch π/2 of the hand's own frame).
#[test]
fn sawyer_kinematics_match_metaworlds_hand_within_a_millimetre() {
    let (mut worst_m, mut worst_rad, mut poses) = (0f64, 0f64, 0);
    for task in ["reach", "coffee-push", "assembly", "stick-pull"] {
        let rig = rig(task);
        let kin = ArmKinematics::new(&rig.arms[0]).unwrap();
        let [x, y, z, r, p, yw] = rig.arms[0].tcp_xyz_rpy.unwrap();
        let flange_from_tcp = glam::DMat4::from_translation(glam::DVec3::new(x, y, z))
            * glam::DMat4::from_mat3(scaledp_schema::kinematics::rotation_from_rpy([r, p, yw]));
        let mut bridge = Bridge::spawn(&rig).unwrap();
        for seed in [0u64, 7] {
            let mut obs = bridge.reset(seed, false).unwrap();
            for _ in 0..80 {
                let a = &obs.arms[0];
                let fk = kin.base_from_tcp(&a.q).unwrap();
                let sim = a.flange_pose() * flange_from_tcp;
                let rpy = kin.tcp_pose(&a.q).unwrap();
                assert!(
                    rpy[3..].iter().all(|v| v.abs() < 0.3),
                    "{task}: rpy {rpy:?}"
                );
                let dp = (fk.w_axis - sim.w_axis).truncate().length();
                let qa = DQuat::from_mat3(&DMat3::from_mat4(fk));
                let qb = DQuat::from_mat3(&DMat3::from_mat4(sim));
                let dr = qa.angle_between(qb);
                worst_m = worst_m.max(dp);
                worst_rad = worst_rad.max(dr);
                poses += 1;
                if obs.done || obs.success {
                    break;
                }
                obs = bridge.expert_step(false).unwrap();
            }
        }
    }
    eprintln!(
        "{poses} poses: FK vs MetaWorld's hand at most {:.3} mm and {:.4} mrad apart",
        worst_m * 1e3,
        worst_rad * 1e3
    );
    assert!(poses > 200, "{poses} poses");
    assert!(worst_m < 1e-3, "{} mm", worst_m * 1e3);
    assert!(worst_rad < 1e-3, "{} mrad", worst_rad * 1e3);
}

/// A seed fixes the scene (the same pictures twice); another seed places the objects elsewhere;
/// the expert's commands replayed through `step` reproduce its episode and its success; the
/// expert's episode passes MetaWorld's stages in order (near the object, grasped, success).
#[test]
fn seeds_fix_scenes_and_the_experts_commands_replay_its_episode() {
    let rig = rig("pick-place");
    let mut bridge = Bridge::spawn(&rig).unwrap();
    assert_eq!(bridge.step_ns(), 12_500_000, "MetaWorld steps at 80 Hz");
    assert!(bridge.hello().versions.contains_key("mujoco"));
    // The bridge's behaviour, recorded with every result (a number, raised on each change).
    let behaviour = bridge.hello().versions.get("scaledp-bridge").cloned();
    assert!(
        behaviour
            .as_deref()
            .is_some_and(|v| v.parse::<u32>().is_ok()),
        "{behaviour:?}"
    );
    let a = bridge.reset(3, true).unwrap();
    let b = bridge.reset(3, true).unwrap();
    let c = bridge.reset(4, true).unwrap();
    assert_eq!(a.images.len(), 2);
    assert_eq!(a.images[0].len(), 84 * 84 * 3);
    assert_eq!(a.images, b.images, "seed 3 twice");
    assert_ne!(
        a.images[0], c.images[0],
        "seeds 3 and 4 place the objects alike"
    );
    assert_eq!(
        bridge.hello().stages,
        ["near the object", "grasped", "success"]
    );
    let mut obs = bridge.reset(5, false).unwrap();
    assert_eq!(obs.stage, 0.0, "nothing reached at the reset");
    let mut commands = Vec::new();
    // The first step at which each stage, or a later one, was reached.
    let mut first_at = [None; 4];
    while !obs.success && !obs.done {
        obs = bridge.expert_step(false).unwrap();
        assert_eq!(obs.commands.len(), 1);
        commands.push(obs.commands[0].clone());
        let s = obs.stage as usize;
        assert!(s <= 3 && obs.stage.fract() == 0.0, "stage {}", obs.stage);
        for at in &mut first_at[..=s] {
            at.get_or_insert(obs.step);
        }
    }
    assert!(obs.success, "the expert solves pick-place seed 5");
    assert_eq!(obs.stage, 3.0, "success is the last stage");
    let [_, near, grasped, success] = first_at.map(Option::unwrap);
    assert!(
        near <= grasped && grasped < success,
        "stages out of order: {first_at:?}"
    );
    let end = obs.arms[0].flange;
    let mut replay = bridge.reset(5, false).unwrap();
    for c in &commands {
        replay = bridge.step(std::slice::from_ref(c), false).unwrap();
    }
    assert!(replay.success, "the replay succeeds too");
    let gap: f64 = end
        .iter()
        .zip(replay.arms[0].flange)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(gap < 1e-6, "the replay ends {gap} away");
}

/// An episode does not inherit the last one's gripper: steps without a gripper command hold
/// the reset's open fingers, whatever the previous episode's last command was (an evaluation's
/// episodes run in one bridge, and its first ticks, before the first chunk, send none).
#[test]
fn a_reset_forgets_the_previous_episodes_gripper() {
    let rig = rig("pick-place");
    let mut bridge = Bridge::spawn(&rig).unwrap();
    // Fingers after ten uncommanded steps from seed 5's reset.
    fn fingers_after_reset(bridge: &mut Bridge) -> Vec<f64> {
        bridge.reset(5, false).unwrap();
        let hold = [ArmCommand::default()];
        let mut obs = bridge.step(&hold, false).unwrap();
        for _ in 0..9 {
            obs = bridge.step(&hold, false).unwrap();
        }
        obs.arms[0].gripper_q.clone()
    }
    let fresh = fingers_after_reset(&mut bridge);
    // An episode that ends with the gripper commanded shut.
    bridge.reset(5, false).unwrap();
    let shut = [ArmCommand {
        gripper_width_m: Some(0.0),
        ..ArmCommand::default()
    }];
    let mut closed = Vec::new();
    for _ in 0..10 {
        closed = bridge.step(&shut, false).unwrap().arms[0].gripper_q.clone();
    }
    assert!(
        closed.iter().zip(&fresh).any(|(c, f)| (c - f).abs() > 1e-3),
        "shutting the gripper moved no finger: {closed:?} against {fresh:?}"
    );
    let after = fingers_after_reset(&mut bridge);
    assert_eq!(
        after, fresh,
        "the next episode started from the shut gripper"
    );
}

/// Bad input is one clear error and the bridge keeps serving; an unknown task names the valid
/// ones before anything starts.
#[test]
fn bad_input_is_one_clear_error() {
    let e = Rig::load_or_builtin("metaworld/juggle")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no task \"juggle\"") && e.contains("pick-place"),
        "{e}"
    );
    let rig = rig("reach");
    let mut bridge = Bridge::spawn(&rig).unwrap();
    bridge.reset(0, false).unwrap();
    let two = vec![scaledp_sim::ArmCommand::default(); 2];
    let e = bridge.step(&two, false).unwrap_err().to_string();
    assert!(
        e.contains("metaworld/reach: step") && e.contains("one arm"),
        "{e}"
    );
    // Still serving after the error.
    bridge.step(&two[..1], false).unwrap();
    let mut text = include_str!("../../rigs/metaworld.toml").replace("TASK", "reach");
    text = text.replace("name = \"corner4\"", "name = \"nowhere\"");
    let bad = Rig::parse(&text, std::path::Path::new("bad.toml")).unwrap();
    let e = Bridge::spawn(&bad).unwrap_err().to_string();
    assert!(
        e.contains("no camera 'nowhere'") || e.contains("nowhere"),
        "{e}"
    );
}
