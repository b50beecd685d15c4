//! ROS-style remapping of a rig's topics (`FROM:=TO`), so a rig file fits a lab whose drivers
//! run under other names without editing it.

use super::Rig;
use crate::error::{Error, Result};

impl Rig {
    /// Every topic field of the rig, mutable: cameras (colour, `camera_info`, depth and its
    /// `camera_info`), arms (joint states, command), grippers (joint states, command), `/tf`,
    /// `/tf_static` and the further topics.
    fn topic_fields_mut(&mut self) -> Vec<&mut String> {
        let mut out: Vec<&mut String> = Vec::new();
        for c in &mut self.cameras {
            out.push(&mut c.topic);
            out.extend(c.camera_info_topic.as_mut());
            if let Some(d) = c.depth.as_mut() {
                out.push(&mut d.topic);
                out.extend(d.camera_info_topic.as_mut());
            }
        }
        for a in &mut self.arms {
            out.push(&mut a.joint_state_topic);
            out.extend(a.command_topic.as_mut());
            if let Some(g) = a.gripper.as_mut() {
                out.push(&mut g.topic);
                out.extend(g.command_topic.as_mut());
            }
        }
        if let Some(tf) = self.tf.as_mut() {
            out.push(&mut tf.topic);
            out.push(&mut tf.static_topic);
        }
        for t in &mut self.extra_topics {
            out.push(&mut t.name);
        }
        out
    }

    /// Renames topic `from` to `to` wherever the rig names it, as ROS's `FROM:=TO` remaps a
    /// node's topic (a name without a leading `/` is taken from the root). Fails, naming both,
    /// when the rig has no topic `from` or when the result is not a valid rig (`to` relative,
    /// or already another of its topics).
    pub fn remap(&mut self, from: &str, to: &str) -> Result<()> {
        let absolute = |n: &str| {
            if n.starts_with('/') {
                n.to_string()
            } else {
                format!("/{n}")
            }
        };
        let (from, to) = (absolute(from), absolute(to));
        let err = |reason: String| Error::Remap {
            from: from.clone(),
            to: to.clone(),
            reason,
        };
        // On a copy: a remapping that fails leaves the rig as it was.
        let mut rig = self.clone();
        let mut renamed = 0;
        for field in rig.topic_fields_mut() {
            if *field == from {
                field.clone_from(&to);
                renamed += 1;
            }
        }
        if renamed == 0 {
            return Err(err(format!("rig {} has no topic {from}", self.name)));
        }
        rig.validate().map_err(err)?;
        *self = rig;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remapping_renames_every_use_and_refuses_what_is_not_there() {
        let mut rig = Rig::builtin("franka_2zed").unwrap();
        rig.remap("/tf", "robot1/tf").unwrap();
        rig.remap(
            "/zed_front/zed_node/rgb/color/rect/image",
            "/cam/front/image",
        )
        .unwrap();
        let topics: Vec<String> = rig.topics().into_iter().map(|t| t.topic).collect();
        assert!(topics.contains(&"/robot1/tf".to_string()), "{topics:?}");
        assert!(!topics.contains(&"/tf".to_string()));
        assert_eq!(rig.cameras[0].topic, "/cam/front/image");
        // The remapped rig survives its TOML round trip (what episodes store).
        let text = toml::to_string(&rig).unwrap();
        let back = Rig::parse(&text, std::path::Path::new("remapped.toml")).unwrap();
        assert_eq!(back, rig);

        let e = rig.remap("/nope", "/x").unwrap_err().to_string();
        assert_eq!(
            e, "remap /nope:=/x: rig franka_2zed has no topic /nope",
            "{e}"
        );
        let e = rig
            .remap("/franka/joint_states", "/franka_gripper/joint_states")
            .unwrap_err()
            .to_string();
        assert!(e.contains("used twice"), "{e}");
        assert_eq!(
            rig.arms[0].joint_state_topic, "/franka/joint_states",
            "left as it was"
        );
        let e = rig.remap("/robot1/tf", "/a//b").unwrap_err().to_string();
        assert!(e.contains("must be absolute"), "{e}");
    }
}
