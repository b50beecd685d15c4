//! Which rig an input was recorded with: the `--rig` given, else the rig our recorder stored in
//! the episode's metadata, else one detected from message types and joint names.

use std::path::Path;

use scaledp_schema::rig::{Arm, Camera, CameraModel, Gripper, GripperModel, Rig};
use scaledp_schema::{EpisodeMetadata, RobotModel};

use crate::error::{Error, Result};
use crate::source::Recording;
use scaledp_align::median_interval_s;

/// The episode metadata our recorder (or the simulator) stored, if any.
pub fn episode_metadata(path: &Path, rec: &Recording) -> Result<Option<EpisodeMetadata>> {
    EpisodeMetadata::from_records(&rec.metadata)
        .transpose()
        .map_err(|e| Error::input(path, e.to_string()))
}

/// The rig stored by `scaledp record` in its episode metadata, if any.
pub fn from_metadata(path: &Path, rec: &Recording) -> Result<Option<Rig>> {
    match episode_metadata(path, rec)?.and_then(|m| m.rig_toml) {
        Some(text) => Rig::parse(&text, path)
            .map(Some)
            .map_err(|e| Error::input(path, format!("stored rig: {e}"))),
        None => Ok(None),
    }
}

/// The task stored by `scaledp record`, if any.
pub fn task_from_metadata(path: &Path, rec: &Recording) -> Result<Option<String>> {
    Ok(episode_metadata(path, rec)?
        .map(|m| m.task)
        .filter(|t| !t.is_empty()))
}

/// Applies `--topic NAME=TOPIC` overrides to a rig; an unknown name is an error.
pub fn override_topics(path: &Path, rig: &mut Rig, overrides: &[(String, String)]) -> Result<()> {
    for (name, topic) in overrides {
        let mut hit = false;
        for c in rig.cameras.iter_mut().filter(|c| &c.name == name) {
            c.topic = topic.clone();
            hit = true;
        }
        for a in &mut rig.arms {
            if &a.name == name {
                a.joint_state_topic = topic.clone();
                hit = true;
            } else if *name == format!("{}_gripper", a.name) {
                if let Some(g) = &mut a.gripper {
                    g.topic = topic.clone();
                    hit = true;
                }
            } else if *name == format!("{}_command", a.name) {
                a.command_topic = Some(topic.clone());
                hit = true;
            }
        }
        if !hit {
            let cams: Vec<&str> = rig.cameras.iter().map(|c| c.name.as_str()).collect();
            let arms: Vec<&str> = rig.arms.iter().map(|a| a.name.as_str()).collect();
            return Err(Error::input(
                path,
                format!("--topic {name}: no camera {cams:?} or arm {arms:?} of that name"),
            ));
        }
    }
    Ok(())
}

fn rate_hz(rec: &Recording, topic: &str) -> f64 {
    let stamps: Vec<u64> = rec
        .messages
        .iter()
        .filter(|m| m.topic == topic)
        .map(|m| m.log_time_ns)
        .collect();
    median_interval_s(&stamps).map_or(30.0, |p| (1.0 / p).round().max(1.0))
}

/// A short feature name for a topic: its first path segment unless that is generic.
fn camera_name(topic: &str, taken: &[Camera]) -> String {
    let parts: Vec<&str> = topic.trim_matches('/').split('/').collect();
    let mut name = parts.first().copied().unwrap_or("camera").to_string();
    if name == "camera" && parts.len() > 1 {
        name = parts[1].to_string();
    }
    let base = name.replace(|c: char| !c.is_ascii_alphanumeric() && c != '_', "_");
    let mut name = base.clone();
    let mut k = 1;
    while taken.iter().any(|c| c.name == name) {
        k += 1;
        name = format!("{base}_{k}");
    }
    name
}

const UR_JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

/// Matches a joint-name list to a known arm: (model, the arm's joint names in order, prefix).
fn match_arm(names: &[String]) -> Option<(RobotModel, Vec<String>, String)> {
    for (model, stem) in [
        (RobotModel::Fr3, "fr3_joint"),
        (RobotModel::Panda, "panda_joint"),
    ] {
        let joints: Vec<String> = (1..=7).map(|i| format!("{stem}{i}")).collect();
        if joints.iter().all(|j| names.contains(j)) {
            return Some((model, joints, stem.trim_end_matches("_joint").to_string()));
        }
    }
    let first = names.iter().find(|n| n.ends_with("shoulder_pan_joint"))?;
    let prefix = first.trim_end_matches("shoulder_pan_joint").to_string();
    let joints: Vec<String> = UR_JOINTS.iter().map(|j| format!("{prefix}{j}")).collect();
    joints
        .iter()
        .all(|j| names.contains(j))
        .then_some((RobotModel::Ur5, joints, prefix))
}

/// The codec of a video topic as its recording's rig names it (none without one: the frames
/// are decoded by then, and the name only describes the rig).
fn video_format(path: &Path, rec: &Recording, topic: &str) -> Option<String> {
    from_metadata(path, rec).ok().flatten().and_then(|r| {
        r.cameras
            .iter()
            .find(|c| c.topic == topic)
            .and_then(|c| c.video_codec().map(str::to_string))
    })
}

/// Detects cameras (Image / CompressedImage / CompressedVideo topics) and arms and grippers (JointState topics
/// whose names match FR3, Panda, UR or a Franka Hand / Robotiq gripper). UR arms are taken as
/// UR5; pass `--rig` for a UR5e.
pub fn detect(path: &Path, rec: &Recording, control_rate_hz: f64) -> Result<Rig> {
    let mut cameras: Vec<Camera> = Vec::new();
    let mut arms: Vec<Arm> = Vec::new();
    let mut grippers: Vec<(String, Gripper)> = Vec::new();
    for t in &rec.topics {
        let Some(first) = rec.messages.iter().find(|m| m.topic == t.topic) else {
            continue;
        };
        match t.message_type.as_str() {
            "sensor_msgs/msg/Image"
            | "sensor_msgs/msg/CompressedImage"
            | "foxglove_msgs/msg/CompressedVideo" => {
                // A video topic's first message was read as its first picture (crate::video).
                let frame = crate::decode::frame(path, first)?;
                let (w, h, enc) = match &frame {
                    crate::decode::Frame::Raw(i) => (i.width, i.height, Some(i.encoding.clone())),
                    crate::decode::Frame::Compressed(_) => (0, 0, None),
                };
                cameras.push(Camera {
                    name: camera_name(&t.topic, &cameras),
                    topic: t.topic.clone(),
                    model: if enc.as_deref() == Some("bgra8") {
                        CameraModel::Zed
                    } else {
                        CameraModel::Realsense
                    },
                    width: w.max(1),
                    height: h.max(1),
                    fps: rate_hz(rec, &t.topic),
                    encoding: match crate::video::is_video(&t.message_type) {
                        true => video_format(path, rec, &t.topic),
                        false => enc,
                    },
                    compressed: t.message_type.ends_with("CompressedImage"),
                    depth: None,
                    camera_info_topic: None,
                    vertical_fov_deg: None,
                });
            }
            "sensor_msgs/msg/JointState" => {
                let js = crate::decode::joint_state(path, first)?;
                let rate = rate_hz(rec, &t.topic);
                if let Some((model, joint_names, prefix)) = match_arm(&js.name) {
                    let name = match prefix.trim_end_matches('_') {
                        "" | "fr3" | "panda" => format!(
                            "arm{}",
                            if arms.is_empty() {
                                String::new()
                            } else {
                                arms.len().to_string()
                            }
                        ),
                        p => p.to_string(),
                    };
                    arms.push(Arm {
                        name,
                        model,
                        joint_state_topic: t.topic.clone(),
                        joint_names,
                        rate_hz: rate,
                        gripper: None,
                        urdf: None,
                        tcp_xyz_rpy: None,
                        command_topic: None,
                        command_type: None,
                        workspace: None,
                    });
                } else if let Some(f) = js.name.iter().find(|n| n.ends_with("finger_joint1")) {
                    let prefix = f.trim_end_matches("finger_joint1").to_string();
                    let names = js
                        .name
                        .iter()
                        .filter(|n| n.contains("finger_joint"))
                        .cloned()
                        .collect();
                    grippers.push((
                        prefix,
                        Gripper {
                            model: GripperModel::FrankaHand,
                            topic: t.topic.clone(),
                            joint_names: names,
                            rate_hz: rate,
                            command_topic: None,
                        },
                    ));
                } else if let Some(k) = js
                    .name
                    .iter()
                    .find(|n| n.ends_with("robotiq_85_left_knuckle_joint"))
                {
                    let prefix = k
                        .trim_end_matches("robotiq_85_left_knuckle_joint")
                        .to_string();
                    grippers.push((
                        prefix,
                        Gripper {
                            model: GripperModel::Robotiq2f85,
                            topic: t.topic.clone(),
                            joint_names: vec![k.clone()],
                            rate_hz: rate,
                            command_topic: None,
                        },
                    ));
                }
            }
            _ => {}
        }
    }
    for (prefix, g) in grippers {
        // A gripper goes to the arm whose joints share its name prefix (fr3_, left_, …), else the
        // only arm.
        let n = arms.len();
        let arm = arms
            .iter_mut()
            .find(|a| !prefix.is_empty() && a.joint_names[0].starts_with(&prefix));
        match arm {
            Some(a) => a.gripper = Some(g),
            None if n == 1 => arms[0].gripper = Some(g),
            None => tracing::warn!(
                "{}: gripper on {} matches no arm; ignored",
                path.display(),
                g.topic
            ),
        }
    }
    if cameras.is_empty() && arms.is_empty() {
        return Err(Error::input(
            path,
            "no camera or arm topics found (pass --rig to map topics)",
        ));
    }
    // A detected rig makes visuomotor data: without a camera it would define a state-only
    // dataset (and, sorted first in a batch, reject every input that has cameras). A rig given
    // with --rig may have none.
    if cameras.is_empty() {
        return Err(Error::Rejected {
            path: path.into(),
            reason: "no camera: arm joint states but no Image or CompressedImage topic (pass \
                     --rig to map cameras, or a rig without cameras for state-only data)"
                .into(),
        });
    }
    let rig = Rig {
        name: "detected".into(),
        control_rate_hz,
        arms,
        cameras,
        simulator: None,
        tf: None,
        extra_topics: Vec::new(),
    };
    Rig::parse(&toml::to_string(&rig).unwrap_or_default(), path)
        .map_err(|e| Error::input(path, format!("detected rig is inconsistent: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_overrides_rename_cameras_arms_grippers_and_commands() {
        let mut rig = Rig::builtin("franka_2zed").unwrap();
        let arm = rig.arms[0].name.clone();
        let cam = rig.cameras[1].name.clone();
        let overrides = vec![
            (cam.clone(), "/other/image".to_string()),
            (arm.clone(), "/other/joints".to_string()),
            (format!("{arm}_gripper"), "/other/gripper".to_string()),
            (format!("{arm}_command"), "/leader/joints".to_string()),
        ];
        override_topics(Path::new("x.mcap"), &mut rig, &overrides).unwrap();
        assert_eq!(rig.cameras[1].topic, "/other/image");
        assert_eq!(rig.arms[0].joint_state_topic, "/other/joints");
        assert_eq!(
            rig.arms[0].gripper.as_ref().unwrap().topic,
            "/other/gripper"
        );
        assert_eq!(rig.arms[0].command_topic.as_deref(), Some("/leader/joints"));

        let bad = vec![("nope".to_string(), "/t".to_string())];
        let e = override_topics(Path::new("x.mcap"), &mut rig, &bad).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("x.mcap") && msg.contains("--topic nope"),
            "{msg}"
        );
    }
}
