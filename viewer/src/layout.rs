//! Entity paths, timelines and the default blueprint: the one place that says where each thing
//! is shown. The layout is documented in the crate docs (`lib.rs`).

use rerun::blueprint::components::PanelState;
use rerun::blueprint::{
    Blueprint, BlueprintPanel, ContainerLike, Grid, Horizontal, SelectionPanel, Spatial2DView,
    Spatial3DView, Tabs, TextLogView, TimePanel, TimeSeriesView, Vertical,
};
use scaledp_schema::ActionSpace;

/// Capture (header) stamps, ns since the epoch: every message and tick of a recording.
pub const CAPTURE_TIME: &str = "capture_time";
/// Receive (log) times of a recording's messages (named apart from rerun's own `log_time`,
/// the wall clock of logging, which scaledp's streams do not record).
pub const RECEIVE_TIME: &str = "receive_time";
/// Aligned ticks of a recording (the frames a conversion would make).
pub const TICK: &str = "tick";
/// Frame index of a dataset episode.
pub const FRAME_INDEX: &str = "frame_index";
/// A dataset frame's `timestamp` (s since the episode's first frame).
pub const TIMESTAMP: &str = "timestamp";
/// Training step (the training view).
pub const STEP: &str = "step";

/// Dimensions of state and action per arm, in order.
pub const POSE_DIMS: [&str; 7] = ["x", "y", "z", "roll", "pitch", "yaw", "gripper"];

/// A camera's images.
pub fn camera(name: &str) -> String {
    format!("cameras/{}", part(name))
}
/// A camera's registered depth (a depth image with its meter).
pub fn depth(camera: &str) -> String {
    format!("depth/{}", part(camera))
}
/// A tf frame, placed by the transform from its parent (`/tf`, `/tf_static`).
pub fn tf(frame: &str) -> String {
    format!("{WORLD}/tf/{}", part(frame))
}
/// An arm's joint positions (one series per joint).
pub fn joints(arm: &str) -> String {
    format!("joints/{}", part(arm))
}
/// An arm's gripper opening (m), as measured.
pub fn gripper(arm: &str) -> String {
    format!("gripper/{}", part(arm))
}
/// A joint-state topic no arm of the rig reads.
pub fn topic(topic: &str) -> String {
    let parts: Vec<String> = topic
        .split('/')
        .filter(|p| !p.is_empty())
        .map(part)
        .collect();
    format!("topics/{}", parts.join("/"))
}
/// State and action of one dimension of one arm: two series, `state` and `action`.
pub fn pose(arm: &str, dim: &str) -> String {
    format!("pose/{}/{}", part(arm), part(dim))
}
/// A state / action dimension's plot: [`pose`] in TCP space, `joint_space/<arm>/<dim>` (a joint
/// or the gripper) in joint space.
pub fn state_action(space: ActionSpace, arm: &str, dim: &str) -> String {
    match space {
        ActionSpace::Tcp => pose(arm, dim),
        ActionSpace::Joints => format!("joint_space/{}/{}", part(arm), part(dim)),
    }
}
/// An arm's base in the 3-D scene.
pub fn world_arm(arm: &str) -> String {
    format!("world/{}", part(arm))
}
/// The kinematic chain (joint origins, base to TCP) as line segments.
pub fn chain(arm: &str) -> String {
    format!("{}/chain", world_arm(arm))
}
/// Link frame `k` (1-based, the last is the flange) as a transform from the base.
pub fn link(arm: &str, k: usize) -> String {
    format!("{}/links/{k}", world_arm(arm))
}
/// The TCP frame as a transform from the base.
pub fn tcp(arm: &str) -> String {
    format!("{}/tcp", world_arm(arm))
}
/// The whole TCP trajectory of the episode.
pub fn trajectory(arm: &str) -> String {
    format!("{}/tcp_trajectory", world_arm(arm))
}
/// The action chunk from the current frame on (what a policy is trained to predict).
pub fn action_chunk(arm: &str) -> String {
    format!("{}/action_chunk", world_arm(arm))
}
/// A chunk predicted by a policy.
pub fn predicted_chunk(arm: &str) -> String {
    format!("{}/predicted_chunk", world_arm(arm))
}
/// Largest spread of the cameras' capture stamps at a tick (ms).
pub const CAMERA_SKEW: &str = "quality/camera_skew_ms";
/// A marker (1) at every invalid tick.
pub const INVALID_TICKS: &str = "quality/invalid_ticks";
/// A marker at every gap of a stream: its length (s).
pub const GAPS: &str = "quality/gaps";
/// Episode metadata, conversion results and warnings, as a text log.
pub const LOG: &str = "log";
/// The 3-D scene root.
pub const WORLD: &str = "world";

/// An entity path part: rerun's path syntax reserves a few characters.
fn part(s: &str) -> String {
    s.chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '_' | '-' | '.' => c,
            _ => '_',
        })
        .collect()
}

/// What an episode shows, for its blueprint.
#[derive(Debug, Default, Clone)]
pub struct Shape {
    /// Camera entity paths (colour `cameras/…`, depth `depth/…`).
    pub cameras: Vec<String>,
    /// Arm names (joint, gripper and pose plots, 3-D).
    pub arms: Vec<String>,
    /// Per arm, its state / action dimensions' labels (empty: `x` … `gripper`).
    pub dims: Vec<Vec<String>>,
    /// The space of the state and action.
    pub space: ActionSpace,
    /// Other joint-state entity paths.
    pub topics: Vec<String>,
    /// Whether per-tick quality signals are shown.
    pub quality: bool,
    /// The timeline selected at start.
    pub timeline: &'static str,
}

fn grid(views: Vec<ContainerLike>, name: &str) -> ContainerLike {
    Grid::new(views).with_name(name).into()
}

/// Cameras on the left; the 3-D scene and the text log on top right; plots below, one tab per
/// arm (joints, gripper, then state vs action per dimension) and one for quality.
pub fn blueprint(shape: &Shape) -> Blueprint {
    let cameras: Vec<ContainerLike> = shape
        .cameras
        .iter()
        .map(|c| {
            Spatial2DView::new(c.strip_prefix("cameras/").unwrap_or(c))
                .with_origin(c.as_str())
                .into()
        })
        .collect();
    let mut tabs: Vec<ContainerLike> = Vec::new();
    for (i, arm) in shape.arms.iter().enumerate() {
        let measured = Horizontal::new(vec![
            TimeSeriesView::new("joints")
                .with_origin(joints(arm))
                .into(),
            TimeSeriesView::new("gripper (m)")
                .with_origin(gripper(arm))
                .into(),
        ]);
        let labels: Vec<&str> = match shape.dims.get(i) {
            Some(d) if !d.is_empty() => d.iter().map(String::as_str).collect(),
            _ => POSE_DIMS.to_vec(),
        };
        let poses = labels
            .iter()
            .map(|d| {
                let origin = state_action(shape.space, arm, d);
                ContainerLike::from(TimeSeriesView::new(*d).with_origin(origin))
            })
            .collect();
        tabs.push(
            Vertical::new(vec![measured.into(), grid(poses, "state vs action")])
                .with_name(arm)
                .with_row_shares([1.0, 2.0])
                .into(),
        );
    }
    for t in &shape.topics {
        tabs.push(
            TimeSeriesView::new(t.trim_start_matches("topics/"))
                .with_origin(t.as_str())
                .into(),
        );
    }
    if shape.quality {
        tabs.push(grid(
            vec![
                TimeSeriesView::new("camera skew (ms)")
                    .with_origin(CAMERA_SKEW)
                    .into(),
                TimeSeriesView::new("invalid ticks, gaps (s)")
                    .with_origin("quality")
                    .with_contents([format!("+ /{INVALID_TICKS}/**"), format!("+ /{GAPS}/**")])
                    .into(),
            ],
            "quality",
        ));
    }
    let top = Horizontal::new(vec![
        Spatial3DView::new("3-D").with_origin(WORLD).into(),
        TextLogView::new("log").with_origin(LOG).into(),
    ]);
    let mut right = vec![ContainerLike::from(top)];
    if !tabs.is_empty() {
        right.push(Tabs::new(tabs).into());
    }
    let mut root = Vec::new();
    let mut shares = Vec::new();
    if !cameras.is_empty() {
        root.push(Vertical::new(cameras).with_name("cameras").into());
        shares.push(1.2);
    }
    root.push(Vertical::new(right).with_row_shares([1.0, 1.5]).into());
    shares.push(2.0);
    Blueprint::new(Horizontal::new(root).with_column_shares(shares))
        .with_blueprint_panel(BlueprintPanel::new().with_state(PanelState::Collapsed))
        .with_selection_panel(SelectionPanel::new().with_state(PanelState::Collapsed))
        .with_time_panel(
            TimePanel::new()
                .with_timeline(shape.timeline)
                .with_state(PanelState::Collapsed),
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths() {
        assert_eq!(camera("front"), "cameras/front");
        assert_eq!(pose("left", "yaw"), "pose/left/yaw");
        assert_eq!(topic("/franka/joint_states"), "topics/franka/joint_states");
        assert_eq!(camera("a b[0]"), "cameras/a_b_0_");
        assert_eq!(link("arm", 8), "world/arm/links/8");
        assert_eq!(depth("wrist"), "depth/wrist");
        assert_eq!(
            tf("camera_color_optical_frame"),
            "world/tf/camera_color_optical_frame"
        );
    }
}
