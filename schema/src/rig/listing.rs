//! The topics a rig records, in the order training data is indexed by, and the rig cut down to
//! its training streams.

use super::topics::*;
use super::Rig;

impl Rig {
    /// This rig without what it records beside its training streams (each camera's depth and
    /// `camera_info`, `/tf` and `/tf_static`, further topics): its [`Rig::topics`] are then
    /// colour, joints, grippers and commands, the streams a dataset is made of.
    pub fn training_streams(mut self) -> Rig {
        for c in &mut self.cameras {
            c.depth = None;
            c.camera_info_topic = None;
        }
        self.tf = None;
        self.extra_topics.clear();
        self
    }

    /// This rig with every camera at `width` × `height`, its topics, encodings and rates kept.
    pub fn with_image_size(mut self, width: u32, height: u32) -> Rig {
        for c in &mut self.cameras {
            (c.width, c.height) = (width, height);
        }
        self
    }

    /// Every topic of the rig, in this order: cameras, then each arm's joint states and gripper
    /// states, then each arm's command topics (arm, then gripper), all as declared; then what
    /// is recorded beside them: per camera its depth and `camera_info` topics, `/tf` and
    /// `/tf_static`, and the rig's further topics. Command topics carry the rig's control rate
    /// as their nominal rate (a policy commands at that rate; a leader device may publish
    /// faster). The first part's order is what training data is indexed by, so additions go
    /// after it.
    pub fn topics(&self) -> Vec<TopicSpec> {
        let mut out: Vec<TopicSpec> = self
            .cameras
            .iter()
            .map(|c| TopicSpec::new(&c.topic, c.message_type(), c.fps, TopicKind::Color, &c.name))
            .collect();
        for arm in &self.arms {
            out.push(TopicSpec::new(
                &arm.joint_state_topic,
                JOINT_STATE,
                arm.rate_hz,
                TopicKind::Joints,
                &arm.name,
            ));
            if let Some(g) = &arm.gripper {
                out.push(TopicSpec::new(
                    &g.topic,
                    JOINT_STATE,
                    g.rate_hz,
                    TopicKind::Gripper,
                    &arm.name,
                ));
            }
        }
        out.extend(self.command_topics());
        out.extend(self.recorded_beside());
        out
    }

    /// The head of [`Self::topics`] without what is recorded beside it: colour images, joint
    /// and gripper states, command topics (what training data is made of, in that order).
    pub fn training_topics(&self) -> Vec<TopicSpec> {
        let mut all = self.topics();
        all.truncate(all.len() - self.recorded_beside().len());
        all
    }

    /// The command topics alone: per arm, its `command_topic` and its gripper's
    /// `command_topic`.
    pub fn command_topics(&self) -> Vec<TopicSpec> {
        let mut out = Vec::new();
        for arm in &self.arms {
            if let Some(topic) = &arm.command_topic {
                out.push(TopicSpec::new(
                    topic,
                    arm.command_type.unwrap_or_default().message_type(),
                    self.control_rate_hz,
                    TopicKind::Command,
                    &arm.name,
                ));
            }
            if let Some(topic) = arm.gripper.as_ref().and_then(|g| g.command_topic.as_ref()) {
                out.push(TopicSpec::new(
                    topic,
                    JOINT_STATE,
                    self.control_rate_hz,
                    TopicKind::Command,
                    &arm.name,
                ));
            }
        }
        out
    }

    /// What is recorded beside the training streams (the tail of [`Self::topics`]): per camera
    /// its depth and `camera_info` topics, then `/tf`, `/tf_static` and the further topics.
    pub fn recorded_beside(&self) -> Vec<TopicSpec> {
        let mut out = Vec::new();
        for c in &self.cameras {
            if let Some(d) = &c.depth {
                out.push(TopicSpec::new(
                    &d.topic,
                    d.message_type(),
                    c.fps,
                    TopicKind::Depth,
                    &c.name,
                ));
            }
            let infos = [
                c.camera_info_topic.as_ref(),
                c.depth.as_ref().and_then(|d| d.camera_info_topic.as_ref()),
            ];
            for topic in infos.into_iter().flatten() {
                out.push(TopicSpec::new(
                    topic,
                    CAMERA_INFO,
                    c.fps,
                    TopicKind::CameraInfo,
                    &c.name,
                ));
            }
        }
        if let Some(tf) = &self.tf {
            if tf.dynamic {
                let rate = tf.rate_hz.unwrap_or(0.0);
                out.push(TopicSpec::new(
                    &tf.topic,
                    TF_MESSAGE,
                    rate,
                    TopicKind::Tf,
                    "",
                ));
            }
            if tf.static_ {
                out.push(TopicSpec::new(
                    &tf.static_topic,
                    TF_MESSAGE,
                    0.0,
                    TopicKind::TfStatic,
                    "",
                ));
            }
        }
        for t in &self.extra_topics {
            let mut spec = TopicSpec::new(
                &t.name,
                &t.message_type,
                t.rate_hz.unwrap_or(0.0),
                TopicKind::Extra,
                "",
            );
            spec.latched = t.latched;
            out.push(spec);
        }
        out
    }
}
