//! An arm in 3-D: forward kinematics of the rig's arm (the schema crate's DH models, or the
//! converter's URDF chain) to the link frames, the chain through their origins, and the TCP the
//! converter computes state and action for (flange · the rig's TCP offset, else the model's
//! default hand).

use glam::{DMat4, DVec3};
use rerun::{LineStrips3D, RecordingStream, Transform3D, TransformAxes3D};
use scaledp_converter::live::ArmKinematics;
use scaledp_schema::rig::Arm;
use scaledp_schema::RobotModel;

use crate::error::{Error, Result};
use crate::layout;

/// Length of the axes drawn at the TCP (m).
const TCP_AXES_M: f32 = 0.08;
/// Length of the axes drawn at each link frame (m).
const LINK_AXES_M: f32 = 0.04;
/// Bases of several arms, side by side along y (a rig names no base placement).
const ARM_SPACING_M: f64 = 0.8;

/// One arm's kinematics and where it is drawn.
pub(crate) struct ArmModel {
    name: String,
    /// Base → TCP, exactly as the converter computes the state's pose.
    tcp: ArmKinematics,
    /// The built-in model's link frames (none for a URDF chain: base → TCP only).
    links: Option<RobotModel>,
    /// Joint positions this arm takes.
    dof: usize,
}

impl ArmModel {
    /// The model of `arm` (its URDF is read when it names one).
    pub fn new(arm: &Arm) -> Result<Self> {
        Ok(Self {
            name: arm.name.clone(),
            tcp: ArmKinematics::new(arm)?,
            links: arm.urdf.is_none().then_some(arm.model),
            dof: arm.joint_names.len(),
        })
    }

    /// `base_from_frame` of every link frame, base → flange (none for a URDF chain).
    fn frames(&self, q: &[f64]) -> Result<Vec<DMat4>> {
        match self.links {
            Some(m) => m
                .frames(q)
                .map_err(|e| Error::input(format!("arm '{}'", self.name), e)),
            None => Ok(Vec::new()),
        }
    }

    /// Logs the links, chain and TCP for joint positions `q` at the stream's current time.
    pub fn log_pose(&self, rec: &RecordingStream, q: &[f64]) -> Result<()> {
        let frames = self.frames(q)?;
        let tcp = self
            .tcp
            .base_from_tcp(q)
            .map_err(|e| Error::input(format!("arm '{}'", self.name), e))?;
        let mut points = vec![[0.0f32; 3]];
        points.extend(frames.iter().map(|f| point(f.w_axis.truncate())));
        points.push(point(tcp.w_axis.truncate()));
        points.dedup();
        let r = |e: rerun::RecordingStreamError| Error::rerun(e);
        rec.log(
            layout::chain(&self.name),
            &LineStrips3D::new([points]).with_radii([0.006]),
        )
        .map_err(r)?;
        for (k, f) in frames.iter().enumerate() {
            rec.log(layout::link(&self.name, k + 1), &transform(f))
                .map_err(r)?;
        }
        rec.log(layout::tcp(&self.name), &transform(&tcp))
            .map_err(r)
    }

    /// Static parts: the base placement (arm `index` of `count`) and the axes of the frames.
    pub fn log_static(&self, rec: &RecordingStream, index: usize, count: usize) -> Result<()> {
        let y = (index as f64 - (count as f64 - 1.0) / 2.0) * ARM_SPACING_M;
        let r = |e: rerun::RecordingStreamError| Error::rerun(e);
        rec.log_static(
            layout::world_arm(&self.name),
            &Transform3D::from_translation([0.0, y as f32, 0.0]),
        )
        .map_err(r)?;
        rec.log_static(layout::tcp(&self.name), &TransformAxes3D::new(TCP_AXES_M))
            .map_err(r)?;
        let links = self.frames(&vec![0.0; self.dof]).map_or(0, |f| f.len());
        for k in 1..=links {
            rec.log_static(
                layout::link(&self.name, k),
                &TransformAxes3D::new(LINK_AXES_M),
            )
            .map_err(r)?;
        }
        Ok(())
    }
}

fn point(v: DVec3) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A rigid transform as rerun's translation + 3×3 matrix.
pub(crate) fn transform(t: &DMat4) -> Transform3D {
    let m = glam::DMat3::from_mat4(*t);
    let cols = [m.x_axis, m.y_axis, m.z_axis].map(|c| [c.x as f32, c.y as f32, c.z as f32]);
    Transform3D::from_translation_mat3x3(
        point(t.w_axis.truncate()),
        rerun::datatypes::Mat3x3::from(cols),
    )
}
