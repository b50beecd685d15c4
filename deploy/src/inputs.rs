//! The controller's input buffers: per checkpoint camera its stamped messages, per arm its
//! joint samples and its gripper's finger samples, each a [`Series`] that knows when it was
//! last heard from. The controller reads them at each tick; this module only stores.

use std::collections::VecDeque;

use scaledp_schema::msg::JointState;
use scaledp_schema::Rig;

use crate::options::ControlOptions;
use crate::streams::Series;

/// A camera's buffered messages (type, CDR bytes), parallel to its stamps.
pub(crate) type Frames = VecDeque<(String, Vec<u8>)>;

/// Every stream the controller listens to.
#[derive(Debug)]
pub(crate) struct Inputs {
    /// Rig camera index of each checkpoint camera.
    pub(crate) cams: Vec<usize>,
    /// Per checkpoint camera: stamps (in `Series`, values unused) and messages.
    pub(crate) frames: Vec<(Series, Frames)>,
    pub(crate) arms: Vec<Series>,
    pub(crate) fingers: Vec<Option<Series>>,
}

impl Inputs {
    /// Buffers for `rig`'s cameras `cams` (keeping `keep_frames_s` of frames: they are big, a
    /// raw HD720 bgra8 frame is 3.7 MB) and for every arm and gripper (about a second).
    pub(crate) fn new(rig: &Rig, cams: Vec<usize>, keep_frames_s: f64) -> Self {
        let frames = cams
            .iter()
            .map(|&i| {
                let c = &rig.cameras[i];
                let name = format!("camera {} ({})", c.name, c.topic);
                (Series::new(name, c.fps, keep_frames_s), VecDeque::new())
            })
            .collect();
        let arms = rig
            .arms
            .iter()
            .map(|a| {
                let name = format!("arm {} ({})", a.name, a.joint_state_topic);
                Series::new(name, a.rate_hz, 1.0)
            })
            .collect();
        let fingers = rig
            .arms
            .iter()
            .map(|a| {
                a.gripper.as_ref().map(|g| {
                    let name = format!("gripper of {} ({})", a.name, g.topic);
                    Series::new(name, g.rate_hz, 1.0)
                })
            })
            .collect();
        Inputs {
            cams,
            frames,
            arms,
            fingers,
        }
    }

    /// Empties every buffer (a new episode).
    pub(crate) fn clear(&mut self) {
        for (s, m) in &mut self.frames {
            *s = s.cleared();
            m.clear();
        }
        for s in self
            .arms
            .iter_mut()
            .chain(self.fingers.iter_mut().flatten())
        {
            *s = s.cleared();
        }
    }

    /// When the newest camera frame was received (receive clock), if any.
    pub(crate) fn newest_frame_ns(&self) -> Option<u64> {
        self.frames.iter().filter_map(|f| f.0.last_heard_ns).max()
    }

    /// Why the inputs cannot make an observation at `now_ns`: the first stream never heard
    /// from, or silent for longer than the options allow.
    pub(crate) fn silence(&self, now_ns: u64, opts: &ControlOptions) -> Option<String> {
        self.frames
            .iter()
            .map(|f| &f.0)
            .chain(&self.arms)
            .chain(self.fingers.iter().flatten())
            .find_map(|s| s.silence(now_ns, opts))
    }

    /// A camera message of rig camera `camera`; cameras the checkpoint does not read are
    /// ignored, and so are messages not newer than the last one kept.
    pub(crate) fn on_image(
        &mut self,
        camera: usize,
        stamp_ns: u64,
        recv_ns: u64,
        message_type: &str,
        cdr: Vec<u8>,
    ) {
        let Some(k) = self.cams.iter().position(|&c| c == camera) else {
            return;
        };
        let (series, msgs) = &mut self.frames[k];
        let before = series.stamps.len();
        let newer = series.stamps.back().is_none_or(|&s| s < stamp_ns);
        series.push(stamp_ns, recv_ns, Vec::new());
        if newer {
            msgs.push_back((message_type.to_string(), cdr));
            let dropped = (before + 1).saturating_sub(series.stamps.len());
            for _ in 0..dropped {
                msgs.pop_front();
            }
        }
    }

    /// Joint positions of arm `arm` (rig joint order).
    pub(crate) fn on_arm_joints(&mut self, arm: usize, stamp_ns: u64, recv_ns: u64, q: Vec<f64>) {
        if let Some(s) = self.arms.get_mut(arm) {
            s.push(stamp_ns, recv_ns, q);
        }
    }

    /// Finger joint positions of arm `arm`'s gripper (its joint order).
    pub(crate) fn on_gripper_joints(
        &mut self,
        arm: usize,
        stamp_ns: u64,
        recv_ns: u64,
        q: Vec<f64>,
    ) {
        if let Some(Some(s)) = self.fingers.get_mut(arm) {
            s.push(stamp_ns, recv_ns, q);
        }
    }

    /// An arm's (`gripper` false) or gripper's `JointState` on `rig`, joints mapped by name as
    /// the converter maps them; a message lacking one of them is ignored.
    pub(crate) fn on_joint_state(
        &mut self,
        rig: &Rig,
        arm: usize,
        gripper: bool,
        recv_ns: u64,
        js: &JointState,
    ) {
        let names = match (gripper, rig.arms.get(arm)) {
            (false, Some(a)) => &a.joint_names,
            (true, Some(a)) => match &a.gripper {
                Some(g) => &g.joint_names,
                None => return,
            },
            _ => return,
        };
        let q: Option<Vec<f64>> = names
            .iter()
            .map(|n| {
                js.name
                    .iter()
                    .position(|x| x == n)
                    .and_then(|i| js.position.get(i).copied())
            })
            .collect();
        let Some(q) = q else { return };
        let stamp = js.header.stamp.as_ns();
        if gripper {
            self.on_gripper_joints(arm, stamp, recv_ns, q);
        } else {
            self.on_arm_joints(arm, stamp, recv_ns, q);
        }
    }
}
