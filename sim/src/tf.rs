//! The simulated rig's transforms as tf2 publishes them: `/tf_static` (each arm's base in the
//! world, each fixed camera's optical frame in the world, each wrist camera's in its flange),
//! published once and latched, and `/tf` (each arm's flange in its base, from its joints) at
//! the rig's `[tf]` rate, as robot_state_publisher would.

use glam::{DMat3, DMat4, DQuat};
use scaledp_schema::msg::{
    Header, Quaternion, TfMessage, Time, Transform, TransformStamped, Vector3,
};
use scaledp_schema::rig::{Arm, Rig};
use scaledp_schema::RobotModel;

use crate::depth::optical_frame;
use crate::messages::base_frame_id;
use crate::render::{Mount, View};
use crate::scene::Scene;
use crate::world::WorldState;

/// The frame every fixed thing is placed in.
pub const WORLD_FRAME: &str = "world";

/// `/tf`'s rate when the rig's `[tf]` gives none (Hz).
pub const DEFAULT_TF_RATE_HZ: f64 = 50.0;

/// The frame of an arm's flange: `<prefix>link8` (Franka), `<prefix>tool0` (UR), `right_hand`
/// (Sawyer), `<arm>/ee_gripper_link` (ViperX).
pub fn flange_frame_id(arm: &Arm) -> String {
    let base = base_frame_id(arm);
    match arm.model {
        RobotModel::Fr3 | RobotModel::Panda => {
            format!("{}link8", base.strip_suffix("link0").unwrap_or(&base))
        }
        RobotModel::Ur5 | RobotModel::Ur5e => {
            format!("{}tool0", base.strip_suffix("base").unwrap_or(&base))
        }
        RobotModel::Sawyer => "right_hand".into(),
        RobotModel::Vx300s => format!("{base}/ee_gripper_link"),
    }
}

fn transform(parent: &str, child: &str, m: &DMat4, stamp_ns: u64) -> TransformStamped {
    let t = m.w_axis.truncate();
    let q = DQuat::from_mat3(&DMat3::from_mat4(*m)).normalize();
    TransformStamped {
        header: Header {
            stamp: Time::from_ns(stamp_ns),
            frame_id: parent.into(),
        },
        child_frame_id: child.into(),
        transform: Transform {
            translation: Vector3 {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            rotation: Quaternion {
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            },
        },
    }
}

/// `/tf_static`: the arms' bases and the cameras' mounts (`views` in camera order).
pub fn tf_static(rig: &Rig, scene: &Scene, views: &[View], stamp_ns: u64) -> TfMessage {
    let mut transforms: Vec<TransformStamped> = scene
        .arms()
        .iter()
        .map(|a| {
            transform(
                WORLD_FRAME,
                &base_frame_id(&a.arm),
                &a.world_from_base,
                stamp_ns,
            )
        })
        .collect();
    for (cam, view) in rig.cameras.iter().zip(views) {
        let (parent, m) = match view.mount() {
            Mount::World(m) => (WORLD_FRAME.to_string(), m),
            Mount::Wrist {
                arm,
                flange_from_camera,
            } => (flange_frame_id(&rig.arms[arm]), flange_from_camera),
        };
        transforms.push(transform(&parent, &optical_frame(cam), &m, stamp_ns));
    }
    TfMessage { transforms }
}

/// `/tf`: each arm's flange in its base at its current joints.
pub fn tf_dynamic(scene: &Scene, state: &WorldState, stamp_ns: u64) -> TfMessage {
    TfMessage {
        transforms: scene
            .arms()
            .iter()
            .zip(&state.arms)
            .map(|(a, s)| {
                transform(
                    &base_frame_id(&a.arm),
                    &flange_frame_id(&a.arm),
                    &a.base_from_flange(&s.q),
                    stamp_ns,
                )
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use scaledp_schema::RosMessage;

    use super::*;
    use crate::world::World;

    #[test]
    fn static_and_dynamic_frames_chain_from_the_world_to_each_camera() {
        let rig = Rig::builtin("bimanual_ur5_3rs").unwrap();
        let scene = Arc::new(Scene::new(&rig));
        let views: Vec<View> = rig
            .cameras
            .iter()
            .enumerate()
            .map(|(i, c)| View::for_camera(&scene, c, i))
            .collect();
        let st = tf_static(&rig, &scene, &views, 5);
        let children: Vec<&str> = st
            .transforms
            .iter()
            .map(|t| t.child_frame_id.as_str())
            .collect();
        assert_eq!(
            children,
            [
                "left_base",
                "right_base",
                "high_camera_optical_frame",
                "left_wrist_camera_optical_frame",
                "right_wrist_camera_optical_frame"
            ]
        );
        assert_eq!(st.transforms[3].header.frame_id, "left_tool0");
        let state = World::with_scene(scene.clone(), 0).state();
        let dy = tf_dynamic(&scene, &state, 6);
        assert_eq!(dy.transforms[1].header.frame_id, "right_base");
        assert_eq!(dy.transforms[1].child_frame_id, "right_tool0");
        assert_eq!(TfMessage::from_cdr(&dy.to_cdr()).unwrap(), dy);
        // world → base → flange → camera is where the renderer puts the wrist camera.
        let w = |t: &TransformStamped| {
            let r = t.transform.rotation;
            let p = t.transform.translation;
            DMat4::from_rotation_translation(
                DQuat::from_xyzw(r.x, r.y, r.z, r.w),
                glam::DVec3::new(p.x, p.y, p.z),
            )
        };
        let chained = w(&st.transforms[0]) * w(&dy.transforms[0]) * w(&st.transforms[3]);
        let rendered = views[1].world_from_camera(&scene, &state);
        assert!(
            chained.abs_diff_eq(rendered, 1e-9),
            "{chained} vs {rendered}"
        );
        let franka = Rig::builtin("franka_2zed").unwrap();
        assert_eq!(flange_frame_id(&franka.arms[0]), "fr3_link8");
    }
}
