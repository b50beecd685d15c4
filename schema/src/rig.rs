//! The rig description: which arms and cameras a lab has, on which ROS 2 topics, at which rates.
//!
//! Written in TOML (see `rigs/*.toml` at the repository root). Everything the recorder subscribes
//! to, the simulator publishes and the converter aligns comes from here.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

mod camera;
mod listing;
mod remap;
mod topics;

use crate::error::{Error, Result};
use crate::kinematics::RobotModel;
pub use crate::simulator::{Simulator, SimulatorKind};
pub use camera::{Camera, CameraModel, Depth, DepthEncoding, VIDEO_CODECS};
pub use topics::{ExtraTopic, TfTopics, TopicKind, TopicSpec, CAMERA_INFO, TF_MESSAGE};

/// A whole rig: arms, cameras, and the rate a policy runs at.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rig {
    /// Short name, e.g. `franka_2zed`.
    pub name: String,
    /// Rate (Hz) at which frames are aligned and the policy acts.
    pub control_rate_hz: f64,
    /// Arms, in the order their dimensions appear in state and action vectors.
    #[serde(rename = "arm", default)]
    pub arms: Vec<Arm>,
    /// Cameras.
    #[serde(rename = "camera", default)]
    pub cameras: Vec<Camera>,
    /// The simulator this rig stands for (`metaworld/<task>` rigs): what `scaledp sim`,
    /// `collect` and `eval` run behind the bridge protocol instead of the built-in cell.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulator: Option<Simulator>,
    /// `/tf` and `/tf_static`, recorded when the table is present (`[tf]`: both by default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tf: Option<TfTopics>,
    /// Further topics to record verbatim, whatever their type (`[[topic]]`).
    #[serde(rename = "topic", default, skip_serializing_if = "Vec::is_empty")]
    pub extra_topics: Vec<ExtraTopic>,
}

/// One arm and its gripper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Arm {
    /// Name used in feature names, e.g. `left`.
    pub name: String,
    /// Kinematic model.
    pub model: RobotModel,
    /// `sensor_msgs/JointState` topic of the arm.
    pub joint_state_topic: String,
    /// The arm's joints, base to tip, as named in the JointState messages.
    pub joint_names: Vec<String>,
    /// Rate (Hz) the driver publishes joint states at.
    pub rate_hz: f64,
    /// The gripper, if any.
    pub gripper: Option<Gripper>,
    /// Forward kinematics from a URDF instead of the built-in model (the converter's choice).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub urdf: Option<UrdfSpec>,
    /// The tool centre point in the flange (or URDF tip) frame: x, y, z (m), roll, pitch, yaw
    /// (rad). Default: the Franka Hand TCP for Franka arms, the flange (`tool0`) for UR arms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tcp_xyz_rpy: Option<[f64; 6]>,
    /// A topic whose messages are the action instead of the next measured pose: a
    /// `geometry_msgs/PoseStamped` target or a leader arm's `sensor_msgs/JointState`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_topic: Option<String>,
    /// What `command_topic` carries (default: a `PoseStamped` TCP target in the base frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_type: Option<CommandType>,
    /// The box TCP targets are kept in, in the base frame: `[xmin, ymin, zmin, xmax, ymax,
    /// zmax]` (m). Default: the simulated cell's table patch (`serve --workspace` overrides it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub workspace: Option<[f64; 6]>,
}

/// The message type of an arm's command topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandType {
    /// `geometry_msgs/msg/PoseStamped`: the TCP target in the arm's base frame, as a Cartesian
    /// controller (e.g. cartesian_motion_controller's `target_frame`) takes it.
    #[default]
    PoseStamped,
    /// `sensor_msgs/msg/JointState`: a leader arm's joints, named as the follower's.
    JointState,
}

impl CommandType {
    /// The full ROS 2 type name.
    pub fn message_type(self) -> &'static str {
        match self {
            Self::PoseStamped => "geometry_msgs/msg/PoseStamped",
            Self::JointState => "sensor_msgs/msg/JointState",
        }
    }
}

/// A URDF serial chain for forward kinematics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UrdfSpec {
    /// The URDF file (relative paths are relative to the working directory).
    pub path: PathBuf,
    /// Link the pose is expressed in.
    pub base_link: String,
    /// Link whose pose is computed (then the TCP offset is applied).
    pub tip_link: String,
}

/// Gripper hardware, which fixes how joint positions map to an opening width.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GripperModel {
    /// Franka Hand: two prismatic fingers, each at width / 2 (m).
    FrankaHand,
    /// Robotiq 2F-85: one knuckle angle, 0 (open, 85 mm) to 0.8 rad (closed).
    Robotiq2f85,
    /// MetaWorld's Sawyer gripper: prismatic `r_close` (0 open … 0.04) and `l_close` (−0.03 …
    /// 0 open); the pads are 0.094 − r + l apart.
    MetaworldSawyer,
    /// gym-aloha's ViperX gripper: prismatic `left_finger` (0.021 … 0.057 m) and
    /// `right_finger` (its mirror, negative); the fingers are left − right apart, 0.116 m when
    /// commanded fully open (each finger at 0.058 m).
    AlohaViperx,
}

impl GripperModel {
    /// Opening width (m) from the gripper's joint positions (in `joint_names` order).
    pub fn width_m(self, positions: &[f64]) -> f64 {
        match self {
            Self::FrankaHand => positions.iter().sum(),
            Self::Robotiq2f85 => 0.085 * (1.0 - positions.first().copied().unwrap_or(0.0) / 0.8),
            Self::MetaworldSawyer => {
                let r = positions.first().copied().unwrap_or(0.0);
                let l = positions.get(1).copied().unwrap_or(0.0);
                0.094 - r + l
            }
            Self::AlohaViperx => {
                let l = positions.first().copied().unwrap_or(0.0);
                let r = positions.get(1).copied().unwrap_or(0.0);
                l - r
            }
        }
    }
    /// Joint positions giving an opening width (m), inverse of [`Self::width_m`].
    pub fn positions_for_width(self, width_m: f64, joints: usize) -> Vec<f64> {
        match self {
            Self::FrankaHand => vec![width_m / joints.max(1) as f64; joints],
            Self::Robotiq2f85 => vec![0.8 * (1.0 - width_m / 0.085); joints],
            Self::MetaworldSawyer => {
                let c = (0.094 - width_m) / 2.0;
                let mut q = vec![c, -c];
                q.resize(joints, 0.0);
                q
            }
            Self::AlohaViperx => {
                let mut q = vec![width_m / 2.0, -width_m / 2.0];
                q.resize(joints, 0.0);
                q
            }
        }
    }
    /// Widest opening (m).
    pub fn max_width_m(self) -> f64 {
        match self {
            Self::FrankaHand => 0.08,
            Self::Robotiq2f85 => 0.085,
            Self::MetaworldSawyer => 0.094,
            Self::AlohaViperx => 0.116,
        }
    }
}

/// A gripper and the topic its joint states arrive on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gripper {
    /// Hardware model.
    pub model: GripperModel,
    /// `sensor_msgs/JointState` topic.
    pub topic: String,
    /// Finger joints as named in the messages.
    pub joint_names: Vec<String>,
    /// Publish rate (Hz).
    pub rate_hz: f64,
    /// A `sensor_msgs/JointState` topic of finger targets (the gripper's own joint names and
    /// units, as a leader gripper publishes them); the action's gripper value when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command_topic: Option<String>,
}

const BUILTIN: &[(&str, &str)] = &[
    ("franka_2zed", include_str!("../../rigs/franka_2zed.toml")),
    (
        "bimanual_ur5_3rs",
        include_str!("../../rigs/bimanual_ur5_3rs.toml"),
    ),
    (
        "franka_2zed_v4",
        include_str!("../../rigs/franka_2zed_v4.toml"),
    ),
    ("franka_sim", include_str!("../../rigs/franka_sim.toml")),
    (
        "bimanual_ur5_sim",
        include_str!("../../rigs/bimanual_ur5_sim.toml"),
    ),
];

/// A finite rate or size above zero.
fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

impl Rig {
    /// Reads and validates a rig file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Rig {
            path: path.into(),
            reason: e.to_string(),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates rig TOML; `path` only names the source in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let err = |reason: String| Error::Rig {
            path: path.into(),
            reason,
        };
        let rig: Rig = toml::from_str(text).map_err(|e| err(e.message().to_string()))?;
        rig.validate().map_err(err)?;
        Ok(rig)
    }

    /// The rigs shipped in `rigs/`, by name: `franka_2zed` (ZED wrapper v5 topics),
    /// `franka_2zed_v4` (ZED wrapper v4 topics), `bimanual_ur5_3rs` (realsense2_camera 4.x),
    /// each with registered depth, `camera_info` and `[tf]`, and their simulated task cells with command topics and smaller images, `franka_sim` and
    /// `bimanual_ur5_sim`; and the simulation benchmarks' `metaworld/<task>` and `aloha/<task>`.
    pub fn builtin(name: &str) -> Option<Self> {
        if let Some(rig) = crate::benchmarks::builtin(name) {
            return rig.ok();
        }
        let (_, text) = BUILTIN.iter().find(|(n, _)| *n == name)?;
        Self::parse(text, &PathBuf::from(format!("rigs/{name}.toml"))).ok()
    }

    /// Names of the shipped rigs.
    pub fn builtin_names() -> impl Iterator<Item = &'static str> {
        BUILTIN.iter().map(|(n, _)| *n)
    }

    /// A rig file path, or the name of a shipped rig.
    pub fn load_or_builtin(path_or_name: &str) -> Result<Self> {
        let path = Path::new(path_or_name);
        if !path.exists() {
            if let Some(rig) = crate::benchmarks::builtin(path_or_name) {
                return rig;
            }
            if let Some(rig) = Self::builtin(path_or_name) {
                return Ok(rig);
            }
        }
        Self::load(path)
    }

    fn validate(&self) -> std::result::Result<(), String> {
        if !positive(self.control_rate_hz) {
            return Err(format!(
                "control_rate_hz must be > 0, got {}",
                self.control_rate_hz
            ));
        }
        if self.arms.is_empty() && self.cameras.is_empty() {
            return Err("a rig needs at least one [[arm]] or [[camera]]".into());
        }
        let mut names = Vec::new();
        for arm in &self.arms {
            let dof = arm.model.dof();
            if arm.joint_names.len() != dof {
                return Err(format!(
                    "arm '{}': model {} has {dof} joints, joint_names lists {}",
                    arm.name,
                    arm.model,
                    arm.joint_names.len()
                ));
            }
            if !positive(arm.rate_hz) {
                return Err(format!("arm '{}': rate_hz must be > 0", arm.name));
            }
            if let Some(w) = arm.workspace {
                if !w.iter().all(|v| v.is_finite()) || (0..3).any(|k| w[k] > w[k + 3]) {
                    return Err(format!(
                        "arm '{}': workspace {w:?} is not [xmin, ymin, zmin, xmax, ymax, zmax]",
                        arm.name
                    ));
                }
            }
            if let Some(g) = &arm.gripper {
                if g.joint_names.is_empty() || !positive(g.rate_hz) {
                    return Err(format!(
                        "arm '{}': gripper needs joint_names and rate_hz > 0",
                        arm.name
                    ));
                }
            }
            names.push(("arm", arm.name.as_str()));
        }
        for cam in &self.cameras {
            if cam.width == 0 || cam.height == 0 || !positive(cam.fps) {
                return Err(format!(
                    "camera '{}': width, height and fps must be > 0",
                    cam.name
                ));
            }
            if let Some(fov) = cam.vertical_fov_deg.filter(|f| !(*f > 0.0 && *f < 180.0)) {
                return Err(format!(
                    "camera '{}': vertical_fov_deg {fov} is not between 0 and 180",
                    cam.name
                ));
            }
            if cam.compressed && cam.video_codec().is_some() {
                return Err(format!(
                    "camera '{}': compressed (JPEG/PNG images) and a video encoding ({}) at once",
                    cam.name,
                    cam.encoding()
                ));
            }
            names.push(("camera", cam.name.as_str()));
        }
        for (i, (kind, name)) in names.iter().enumerate() {
            if name.is_empty() || names[..i].iter().any(|(k, n)| k == kind && n == name) {
                return Err(format!("{kind} name '{name}' is empty or used twice"));
            }
        }
        for t in &self.extra_topics {
            let parts: Vec<&str> = t.message_type.split('/').collect();
            if parts.len() != 3 || parts[1] != "msg" || parts.iter().any(|p| p.is_empty()) {
                return Err(format!(
                    "topic '{}': type '{}' is not a full ROS 2 type like pkg/msg/Name",
                    t.name, t.message_type
                ));
            }
            if t.rate_hz.is_some_and(|r| !positive(r)) {
                return Err(format!("topic '{}': rate_hz must be > 0", t.name));
            }
        }
        if self
            .tf
            .as_ref()
            .and_then(|t| t.rate_hz)
            .is_some_and(|r| !positive(r))
        {
            return Err("[tf] rate_hz must be > 0".into());
        }
        let topics = self.topics();
        for (i, t) in topics.iter().enumerate() {
            if !t.topic.starts_with('/') || t.topic.ends_with('/') || t.topic.contains("//") {
                return Err(format!(
                    "topic '{}' must be absolute, like /ns/name",
                    t.topic
                ));
            }
            if topics[..i].iter().any(|o| o.topic == t.topic) {
                return Err(format!("topic '{}' is used twice", t.topic));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
