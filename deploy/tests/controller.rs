//! The controller core, fed by hand in simulated time: a silenced camera stops the commands
//! (and they resume when it speaks again), an out-of-workspace action is clamped, and a
//! checkpoint that does not fit the rig is one clear error.
#![allow(clippy::unwrap_used)]

use crate::common;

use candle_core::Device;
use glam::DVec3;
use scaledp_deploy::{ControlOptions, Controller, Workspace};
use scaledp_policy::Policy;
use scaledp_schema::{Rig, RosMessage};
use scaledp_sim::render::{render, View};
use scaledp_sim::{messages, Scene, World};

const MS: u64 = 1_000_000;

/// Feeds every stream of `rig` from a resting world over (`from`, `to`] ms, cameras only when
/// `cameras` is true.
fn feed(ctl: &mut Controller, rig: &Rig, world: &World, from: u64, to: u64, cameras: bool) {
    let scene = world.scene().clone();
    let state = world.state();
    let mut px = Vec::new();
    for t in (from + 1)..=to {
        let ns = t * MS;
        if cameras && t % 33 == 0 {
            for (i, cam) in rig.cameras.iter().enumerate() {
                render(
                    &scene,
                    &View::for_camera(&scene, cam, i),
                    &state,
                    cam.encoding(),
                    &mut px,
                );
                let msg = messages::image(cam, px.clone(), ns);
                ctl.on_image(i, ns, ns, "sensor_msgs/msg/Image", msg.to_cdr());
            }
        }
        if t % 4 == 0 {
            ctl.on_arm_joints(0, ns, ns, state.arms[0].q.clone());
        }
        if t % 20 == 0 {
            let g = rig.arms[0].gripper.as_ref().unwrap();
            ctl.on_gripper_joints(0, ns, ns, g.model.positions_for_width(0.08, 2));
        }
    }
}

/// Runs ticks every 100 ms from `from` to `to` ms, predicting synchronously; returns per tick
/// (time ms, halt reason, commands).
fn run(
    ctl: &mut Controller,
    policy: &Policy,
    rig: &Rig,
    world: &World,
    from: u64,
    to: u64,
    cameras: bool,
) -> Vec<(u64, Option<String>, Option<Vec<scaledp_deploy::Command>>)> {
    let mut out = Vec::new();
    let mut t = from;
    while t < to {
        feed(ctl, rig, world, t, t + 100, cameras);
        t += 100;
        let tick = ctl.tick(t * MS);
        if let Some(req) = tick.request {
            let chunk = policy.predict(&req.observation, req.index).unwrap();
            ctl.install(req.index, &chunk);
        }
        out.push((t, tick.halted, ctl.command().ok()));
    }
    out
}

#[test]
fn a_silenced_camera_stops_the_commands_until_it_speaks_again() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let ckpt = common::write(dir.path(), &common::Spec::at_home(&rig));
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let mut ctl =
        Controller::new(policy.config(), "tiny", &rig, ControlOptions::default()).unwrap();
    let world = World::with_scene(std::sync::Arc::new(Scene::new(&rig)), 3);

    let before = run(&mut ctl, &policy, &rig, &world, 0, 1500, true);
    // The window (2 ticks) fills, then every tick has a command near the rest pose.
    assert!(
        before[0].2.is_none(),
        "no command before the window is full"
    );
    let commanded: Vec<_> = before.iter().filter_map(|r| r.2.clone()).collect();
    assert!(
        commanded.len() >= before.len() - 2,
        "{} of {}",
        commanded.len(),
        before.len()
    );
    let home = common::home_action(&rig);
    for c in commanded.iter().flatten() {
        let p = c.base_from_tcp.w_axis.truncate();
        assert!(
            (p - DVec3::new(home[0], home[1], home[2])).length() < 0.03,
            "{p}"
        );
        assert!(!c.clamped.workspace);
    }

    // The cameras fall silent: within the first tick past two frame periods, no command and a
    // reason naming the camera.
    let silent = run(&mut ctl, &policy, &rig, &world, 1500, 2000, false);
    for (t, halted, cmds) in &silent {
        let why = halted.as_deref().unwrap_or_default();
        assert!(
            cmds.is_none(),
            "a command at {t} ms with the cameras silent"
        );
        assert!(
            why.contains("camera front") && why.contains("silent"),
            "{t}: {why:?}"
        );
    }
    // They speak again: commands resume once the window has refilled.
    let after = run(&mut ctl, &policy, &rig, &world, 2000, 3000, true);
    assert!(after[0].2.is_none());
    assert!(
        after.iter().skip(2).all(|r| r.2.is_some()),
        "{:?}",
        after.iter().map(|r| &r.1).collect::<Vec<_>>()
    );
}

#[test]
fn an_out_of_workspace_target_is_clamped_to_the_box_and_one_step() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    let mut spec = common::Spec::at_home(&rig);
    spec.centre[0] = 5.0; // x five metres out
    spec.centre[2] = -1.0; // under the table
    spec.centre[6] = 0.5; // wider than the Franka Hand opens
    let ckpt = common::write(dir.path(), &spec);
    let policy = Policy::load(&ckpt, &Device::Cpu).unwrap();
    let opts = ControlOptions::default();
    let (max_step, box0) = (opts.max_step_m, Workspace::for_rig(&rig)[0]);
    let mut ctl = Controller::new(policy.config(), "far", &rig, opts).unwrap();
    let world = World::with_scene(std::sync::Arc::new(Scene::new(&rig)), 3);
    let ticks = run(&mut ctl, &policy, &rig, &world, 0, 2000, true);
    let home = common::home_action(&rig);
    let mut previous = DVec3::new(home[0], home[1], home[2]);
    let cmds: Vec<_> = ticks.iter().filter_map(|r| r.2.clone()).flatten().collect();
    assert!(cmds.len() >= 15, "{} commands", cmds.len());
    for c in &cmds {
        let p = c.base_from_tcp.w_axis.truncate();
        assert!(c.clamped.workspace && c.clamped.gripper, "{:?}", c.clamped);
        assert!(box0.contains(p), "{p} outside {box0:?}");
        assert!(
            (p - previous).length() <= max_step + 1e-9,
            "a step of {}",
            (p - previous).length()
        );
        assert_eq!(c.gripper_width_m, Some(0.08));
        previous = p;
    }
    // It walked to the box's far face and stays there, clamped.
    let last = cmds.last().unwrap().base_from_tcp.w_axis.truncate();
    assert!(
        (last.x - box0.max.x).abs() < 1e-9 && (last.z - box0.min.z).abs() < 1e-9,
        "{last}"
    );
}

#[test]
fn a_checkpoint_that_does_not_fit_the_rig_is_one_clear_error() {
    let rig = common::light_rig();
    let dir = tempfile::tempdir().unwrap();
    // Trained on the bimanual cell.
    let bimanual = Rig::builtin("bimanual_ur5_sim").unwrap();
    let ckpt = common::write(&dir.path().join("a"), &common::Spec::at_home(&bimanual));
    let cfg = Policy::load(&ckpt, &Device::Cpu).unwrap().config().clone();
    let e = Controller::new(&cfg, "a", &rig, ControlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bimanual_ur5_sim") && e.contains("franka_sim") && !e.contains('\n'),
        "{e}"
    );
    // The rig as `scaledp convert` stores it: its TOML.
    let mut spec = common::Spec::at_home(&rig);
    spec.rig = Some(include_str!("../../rigs/bimanual_ur5_sim.toml").into());
    let ckpt = common::write(&dir.path().join("t"), &spec);
    let cfg = Policy::load(&ckpt, &Device::Cpu).unwrap().config().clone();
    let e = Controller::new(&cfg, "t", &rig, ControlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("trained on rig bimanual_ur5_sim, not franka_sim"),
        "{e}"
    );
    // The same rig, but its first camera zoomed since training.
    let mut spec = common::Spec::at_home(&rig);
    spec.rig = Some(toml::to_string(&rig).unwrap());
    let mut zoomed = rig.clone();
    zoomed.cameras[0].vertical_fov_deg = Some(45.0);
    let ckpt = common::write(&dir.path().join("z"), &spec);
    let cfg = Policy::load(&ckpt, &Device::Cpu).unwrap().config().clone();
    let e = Controller::new(&cfg, "z", &zoomed, ControlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("the simulator's own") && e.contains("45°") && !e.contains('\n'),
        "{e}"
    );
    assert!(Controller::new(&cfg, "z", &rig, ControlOptions::default()).is_ok());
    // And the other way: trained zoomed, run at the simulator's own field.
    spec.rig = Some(toml::to_string(&zoomed).unwrap());
    let ckpt = common::write(&dir.path().join("w"), &spec);
    let cfg = Policy::load(&ckpt, &Device::Cpu).unwrap().config().clone();
    let e = Controller::new(&cfg, "w", &rig, ControlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("at a vertical field of view of 45°") && e.contains("the simulator's own"),
        "{e}"
    );
    // No rig named, a camera the rig lacks.
    let mut spec = common::Spec::at_home(&rig);
    spec.rig = None;
    spec.cameras[1] = "observation.images.top".into();
    let ckpt = common::write(&dir.path().join("b"), &spec);
    let cfg = Policy::load(&ckpt, &Device::Cpu).unwrap().config().clone();
    let e = Controller::new(&cfg, "b", &rig, ControlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("observation.images.top") && e.contains("wrist"),
        "{e}"
    );
    // A 14-D checkpoint on a one-arm rig.
    let mut spec = common::Spec::at_home(&rig);
    spec.rig = None;
    spec.dim = 14;
    spec.centre = [spec.centre.clone(), spec.centre.clone()].concat();
    let ckpt = common::write(&dir.path().join("c"), &spec);
    let cfg = Policy::load(&ckpt, &Device::Cpu).unwrap().config().clone();
    let e = Controller::new(&cfg, "c", &rig, ControlOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("14-D state") && e.contains("1 arm"), "{e}");
    // --action-steps beyond the chunk.
    let ok = common::write(&dir.path().join("d"), &common::Spec::at_home(&rig));
    let cfg = Policy::load(&ok, &Device::Cpu).unwrap().config().clone();
    let opts = ControlOptions {
        action_steps: 9,
        ..ControlOptions::default()
    };
    let e = Controller::new(&cfg, "d", &rig, opts)
        .unwrap_err()
        .to_string();
    assert!(e.contains("--action-steps 9") && e.contains('8'), "{e}");
}

#[test]
fn seeds_of_a_collect_manifest_are_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("collect.jsonl");
    std::fs::write(
        &path,
        "{\"episode\":\"a.mcap\",\"seed\":4}\n\n{\"episode\":null,\"seed\":7}\n",
    )
    .unwrap();
    let seeds = scaledp_deploy::eval::collected_seeds(&path).unwrap();
    assert_eq!(seeds, [4, 7].into_iter().collect());
    std::fs::write(&path, "{\"episode\":\"a.mcap\"}\n").unwrap();
    let e = scaledp_deploy::eval::collected_seeds(&path)
        .unwrap_err()
        .to_string();
    assert!(e.contains("line 1 has no seed"), "{e}");
}
