//! Grasp, carry, release and scoring, driven by scripted commands through `World::step`.

use glam::{DMat4, DVec3};
use scaledp_schema::Rig;

use super::*;
use crate::scene::CUBE_HALF_M;
use crate::task::SUCCESS_RADIUS_M;

/// Commands arm `arm`'s fingertips to `p` (world, grasp orientation) and the gripper to
/// `width_m`, then steps `seconds` in 10 ms steps.
fn go(world: &mut World, arm: usize, p: DVec3, width_m: f64, seconds: f64) {
    let layout = world.scene().arms()[arm].clone();
    let fingertips = DMat4::from_translation(p) * DMat4::from_mat3(layout.grasp_rotation);
    let tcp = layout.world_from_base.inverse() * fingertips * layout.fingertips_from_tcp();
    let mut cmds = vec![ArmCommand::default(); world.scene().arms().len()];
    cmds[arm] = ArmCommand {
        pose: Some(tcp),
        joints: None,
        gripper_width_m: Some(width_m),
    };
    for _ in 0..(seconds * 100.0).round() as usize {
        world.step(0.01, &cmds);
    }
}

/// Pick cube `arm` up at its start (offset by `miss`), carry it to its target offset by
/// `place_offset` and open. Returns the world afterwards.
fn pick_and_place(rig: &str, seed: u64, arm: usize, miss: DVec3, place_offset: DVec3) -> World {
    let mut w = World::new(&Rig::builtin(rig).unwrap(), seed);
    let cube = w.task().cubes[arm].position;
    let target = w.task().cubes[arm].target;
    let up = DVec3::Z * 0.12;
    let grasp = cube + miss - DVec3::Z * 0.008;
    go(&mut w, arm, grasp + up, 0.08, 2.0);
    go(&mut w, arm, grasp, 0.08, 1.5);
    go(&mut w, arm, grasp, 0.0, 1.0);
    go(&mut w, arm, grasp + up, 0.0, 1.5);
    let place = target + place_offset + DVec3::Z * (CUBE_HALF_M - 0.008 + 0.006);
    go(&mut w, arm, place + up, 0.0, 2.0);
    go(&mut w, arm, place, 0.0, 1.5);
    go(&mut w, arm, place, 0.08, 1.0);
    go(&mut w, arm, place + up, 0.08, 1.0);
    w
}

#[test]
fn a_cube_is_grasped_carried_and_released_over_its_target() {
    for rig in ["franka_2zed", "bimanual_ur5_3rs"] {
        let w = pick_and_place(rig, 3, 0, DVec3::ZERO, DVec3::ZERO);
        let s = w.task_state();
        let c = &s.cubes[0];
        assert_eq!(c.held_by, None, "{rig}: still held");
        assert!(c.resting, "{rig}: not on the table: {:?}", c.position_m);
        assert!(
            c.distance_m < 0.01,
            "{rig}: {} m from the target",
            c.distance_m
        );
        assert!(c.placed);
        if rig == "franka_2zed" {
            assert!(s.success, "{rig}: the only cube is placed");
            let t = s.time_to_success_s.expect("a time to success");
            assert!(t > 8.0 && t < w.time_s(), "{rig}: success at {t} s");
        } else {
            // The right arm's cube never moved: the two-cube task is not done.
            assert!(!s.cubes[1].placed && !s.success && s.time_to_success_s.is_none());
        }
    }
}

#[test]
fn the_cube_rides_in_the_fingers_and_the_fingers_stop_on_it() {
    let mut w = World::new(&Rig::builtin("franka_2zed").unwrap(), 5);
    let cube = w.task().cubes[0].position;
    let grasp = cube - DVec3::Z * 0.008;
    go(&mut w, 0, grasp + DVec3::Z * 0.1, 0.08, 2.0);
    go(&mut w, 0, grasp, 0.08, 1.5);
    go(&mut w, 0, grasp, 0.0, 1.0);
    let s = w.state();
    assert_eq!(s.task.cubes[0].held_by, Some(0));
    assert!((s.arms[0].gripper_width_m - 2.0 * CUBE_HALF_M).abs() < 1e-9);
    assert_eq!(s.arms[0].gripper_command_m, 0.0);
    let lifted = grasp + DVec3::new(0.05, -0.03, 0.15);
    go(&mut w, 0, lifted, 0.0, 2.0);
    let c = w.task().cubes[0].position;
    let fingertips = w.scene().arms()[0].world_from_fingertips(&w.state().arms[0].q);
    assert!(
        (c - fingertips.w_axis.truncate()).length() < 0.02,
        "the cube left the fingers"
    );
    assert!(c.z > 0.14, "not lifted: {c}");
}

#[test]
fn a_grasp_that_misses_leaves_the_cube_where_it_was() {
    // 6 cm beside the cube along the finger pads: the fingers close on air.
    let rig = Rig::builtin("franka_2zed").unwrap();
    let start = World::new(&rig, 4).task().cubes[0].clone();
    for miss in [DVec3::new(0.06, 0.0, 0.0), DVec3::new(0.0, 0.0, 0.05)] {
        let mut w = World::new(&rig, 4);
        let grasp = start.position + miss - DVec3::Z * 0.008;
        go(&mut w, 0, grasp + DVec3::Z * 0.1, 0.08, 2.0);
        go(&mut w, 0, grasp, 0.08, 1.5);
        go(&mut w, 0, grasp, 0.0, 1.0);
        assert!(
            w.state().arms[0].gripper_width_m < 1e-9,
            "the gripper closed fully"
        );
        go(&mut w, 0, grasp + DVec3::Z * 0.15, 0.0, 1.5);
        let c = &w.task().cubes[0];
        assert_eq!(c.held_by, None, "miss {miss}: grasped");
        assert_eq!(c.position, start.position, "miss {miss}: the cube moved");
        assert!(!w.task_state().success);
    }
}

#[test]
fn releasing_five_centimetres_from_the_target_fails() {
    let w = pick_and_place("franka_2zed", 3, 0, DVec3::ZERO, DVec3::new(0.0, 0.05, 0.0));
    let s = w.task_state();
    assert!(s.cubes[0].resting && s.cubes[0].held_by.is_none());
    assert!(
        s.cubes[0].distance_m > SUCCESS_RADIUS_M,
        "{}",
        s.cubes[0].distance_m
    );
    assert!(!s.success && s.time_to_success_s.is_none());
}

#[test]
fn stepping_is_deterministic_and_independent_of_the_step_size() {
    let rig = Rig::builtin("bimanual_ur5_3rs").unwrap();
    let run = |dt: f64| {
        let mut w = World::new(&rig, 9);
        let target = w.state().arms[1].tcp * DMat4::from_translation(DVec3::new(0.05, 0.0, 0.02));
        let cmds = [
            ArmCommand::default(),
            ArmCommand {
                pose: Some(target),
                joints: None,
                gripper_width_m: Some(0.01),
            },
        ];
        w.step(0.0, &cmds);
        for _ in 0..(1.0 / dt).round() as usize {
            w.step(dt, &[]);
        }
        w.state()
    };
    let (a, b) = (run(0.008), run(0.001));
    assert_eq!(a, run(0.008));
    // Controller ticks fall at the arm's rate (125 Hz) however the world is stepped.
    assert_eq!(a.arms, b.arms);
    assert_ne!(
        a.arms[1].q,
        World::new(&rig, 9).state().arms[1].q,
        "the arm did not move"
    );
}
