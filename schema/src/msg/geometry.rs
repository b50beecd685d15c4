//! `geometry_msgs` (points, poses, transforms) and `tf2_msgs/TFMessage`, what `/tf` and
//! `/tf_static` carry.

use super::base::{Header, RosMessage};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::Result;

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Point {
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// z (m).
    pub z: f64,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PoseStamped {
    /// Stamp and reference frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// `geometry_msgs/msg/Transform`: the child frame's pose in the parent frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Transform {
    /// Translation (m).
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`: `header.frame_id` (parent) ← `child_frame_id`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The frame the transform places.
    pub child_frame_id: String,
    /// The child's pose in the parent frame.
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`: what tf2 publishes on `/tf` and `/tf_static`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TfMessage {
    /// The transforms, each with its own stamp.
    pub transforms: Vec<TransformStamped>,
}

macro_rules! float_fields {
    ($ty:ident, $name:literal, $($f:ident),+) => {
        impl RosMessage for $ty {
            const TYPE_NAME: &'static str = $name;
            fn write(&self, w: &mut CdrWriter) {
                $(w.f64(self.$f);)+
            }
            fn read(r: &mut CdrReader<'_>) -> Result<Self> {
                Ok(Self { $($f: r.f64()?),+ })
            }
        }
    };
}
float_fields!(Point, "geometry_msgs/msg/Point", x, y, z);
float_fields!(Vector3, "geometry_msgs/msg/Vector3", x, y, z);
float_fields!(Quaternion, "geometry_msgs/msg/Quaternion", x, y, z, w);

impl RosMessage for Pose {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Pose";
    fn write(&self, w: &mut CdrWriter) {
        self.position.write(w);
        self.orientation.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            position: Point::read(r)?,
            orientation: Quaternion::read(r)?,
        })
    }
}

impl RosMessage for PoseStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseStamped";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.pose.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            pose: Pose::read(r)?,
        })
    }
}

impl RosMessage for Transform {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Transform";
    fn write(&self, w: &mut CdrWriter) {
        self.translation.write(w);
        self.rotation.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            translation: Vector3::read(r)?,
            rotation: Quaternion::read(r)?,
        })
    }
}

impl RosMessage for TransformStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/TransformStamped";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        self.transform.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            child_frame_id: r.string()?,
            transform: Transform::read(r)?,
        })
    }
}

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    fn write(&self, w: &mut CdrWriter) {
        w.sequence_len(self.transforms.len());
        for t in &self.transforms {
            t.write(w);
        }
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        // Each element holds at least a stamp, an empty frame id and a child frame id, and a
        // transform: 8 + 4 + 4 + 56 bytes.
        let n = r.sequence_len(72)?;
        let transforms = (0..n)
            .map(|_| TransformStamped::read(r))
            .collect::<Result<_>>()?;
        Ok(Self { transforms })
    }
}
