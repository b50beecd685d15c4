//! `sensor_msgs` beside images: joint states and a camera's intrinsics.

use super::base::{Header, RosMessage};
use crate::cdr::{CdrReader, CdrWriter};
use crate::error::Result;

/// `sensor_msgs/msg/JointState`. Arrays are parallel to `name`; map joints by name, not index.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct JointState {
    /// Sample stamp.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions (rad or m).
    pub position: Vec<f64>,
    /// Velocities (may be empty).
    pub velocity: Vec<f64>,
    /// Efforts (may be empty).
    pub effort: Vec<f64>,
}

impl RosMessage for JointState {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/JointState";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string_seq(&self.name);
        w.f64_seq(&self.position);
        w.f64_seq(&self.velocity);
        w.f64_seq(&self.effort);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            header: Header::read(r)?,
            name: r.string_seq()?,
            position: r.f64_seq()?,
            velocity: r.f64_seq()?,
            effort: r.f64_seq()?,
        })
    }
}

/// `sensor_msgs/msg/RegionOfInterest`: the part of the full image a camera_info describes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RegionOfInterest {
    /// Leftmost pixel of the region.
    pub x_offset: u32,
    /// Topmost pixel of the region.
    pub y_offset: u32,
    /// Rows (0: the full image).
    pub height: u32,
    /// Columns (0: the full image).
    pub width: u32,
    /// True when the region is to be rectified.
    pub do_rectify: bool,
}

impl RosMessage for RegionOfInterest {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/RegionOfInterest";
    fn write(&self, w: &mut CdrWriter) {
        w.u32(self.x_offset);
        w.u32(self.y_offset);
        w.u32(self.height);
        w.u32(self.width);
        w.u8(u8::from(self.do_rectify));
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        Ok(Self {
            x_offset: r.u32()?,
            y_offset: r.u32()?,
            height: r.u32()?,
            width: r.u32()?,
            do_rectify: r.u8()? != 0,
        })
    }
}

/// `sensor_msgs/msg/CameraInfo`: a camera's calibration for images of `width` × `height`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CameraInfo {
    /// Stamp and optical frame of the images it describes.
    pub header: Header,
    /// Rows of the calibrated image.
    pub height: u32,
    /// Columns of the calibrated image.
    pub width: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`, …
    pub distortion_model: String,
    /// Distortion coefficients (5 for `plumb_bob`: k1, k2, t1, t2, k3).
    pub d: Vec<f64>,
    /// Intrinsics, row-major 3×3: `[fx 0 cx; 0 fy cy; 0 0 1]` (pixels).
    pub k: [f64; 9],
    /// Rectification rotation, row-major 3×3 (identity for a monocular camera).
    pub r: [f64; 9],
    /// Projection, row-major 3×4: `[fx' 0 cx' Tx; 0 fy' cy' Ty; 0 0 1 0]`.
    pub p: [f64; 12],
    /// Horizontal binning (0 or 1: none).
    pub binning_x: u32,
    /// Vertical binning (0 or 1: none).
    pub binning_y: u32,
    /// The region of the full image (all zero: the full image).
    pub roi: RegionOfInterest,
}

impl CameraInfo {
    /// A distortion-free pinhole camera: focal length `f_px` and principal point (`cx`, `cy`)
    /// in pixels, `plumb_bob` with zero coefficients, identity rectification.
    pub fn pinhole(header: Header, width: u32, height: u32, f_px: f64, cx: f64, cy: f64) -> Self {
        Self {
            header,
            height,
            width,
            distortion_model: "plumb_bob".into(),
            d: vec![0.0; 5],
            k: [f_px, 0.0, cx, 0.0, f_px, cy, 0.0, 0.0, 1.0],
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: [f_px, 0.0, cx, 0.0, 0.0, f_px, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
            binning_x: 0,
            binning_y: 0,
            roi: RegionOfInterest::default(),
        }
    }
}

impl RosMessage for CameraInfo {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/CameraInfo";
    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.u32(self.height);
        w.u32(self.width);
        w.string(&self.distortion_model);
        w.f64_seq(&self.d);
        for v in self.k.iter().chain(&self.r).chain(&self.p) {
            w.f64(*v);
        }
        w.u32(self.binning_x);
        w.u32(self.binning_y);
        self.roi.write(w);
    }
    fn read(r: &mut CdrReader<'_>) -> Result<Self> {
        let header = Header::read(r)?;
        let (height, width) = (r.u32()?, r.u32()?);
        let distortion_model = r.string()?;
        let d = r.f64_seq()?;
        let mut fixed = [0.0; 30];
        for v in &mut fixed {
            *v = r.f64()?;
        }
        let mut k = [0.0; 9];
        let mut rr = [0.0; 9];
        let mut p = [0.0; 12];
        k.copy_from_slice(&fixed[..9]);
        rr.copy_from_slice(&fixed[9..18]);
        p.copy_from_slice(&fixed[18..]);
        Ok(Self {
            header,
            height,
            width,
            distortion_model,
            d,
            k,
            r: rr,
            p,
            binning_x: r.u32()?,
            binning_y: r.u32()?,
            roi: RegionOfInterest::read(r)?,
        })
    }
}

/// The (height, width) a `sensor_msgs/CameraInfo` payload calibrates, read without the rest.
pub fn camera_info_size(payload: &[u8]) -> Result<(u32, u32)> {
    let mut r = CdrReader::new(payload)?;
    Header::read(&mut r)?;
    Ok((r.u32()?, r.u32()?))
}
