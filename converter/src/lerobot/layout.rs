//! Does an episode fit a dataset? Every episode of a dataset shares its cameras (and their
//! fields of view), action space, names, rate, image size and how images are stored.

use std::path::Path;

use super::{Dataset, VideoFormat};
use crate::episode::Episode;
use crate::error::{Error, Result};

impl Dataset {
    pub(super) fn check_layout(&self, ep: &Episode) -> Result<()> {
        let Some(s) = &self.sidecar else {
            return Ok(());
        };
        let cams: Vec<String> = ep.cameras.iter().map(|c| c.name.clone()).collect();
        let depth = super::depth::depth_features(ep);
        let mismatch = if s.cameras != cams {
            Some(format!("cameras {cams:?}, the dataset has {:?}", s.cameras))
        } else if s.depth != depth {
            let list = |d: &[super::depth::DepthFeature]| {
                let v: Vec<String> = d
                    .iter()
                    .map(|d| format!("{} {}", d.camera, d.encoding.as_str()))
                    .collect();
                format!("[{}]", v.join(", "))
            };
            Some(format!(
                "depth of cameras {}, the dataset has {} (convert with or without --no-depth \
                 as the dataset was)",
                list(&depth),
                list(&s.depth)
            ))
        } else if s.action_space != ep.action_space {
            Some(format!(
                "{} state and action, the dataset's are {} (convert with --action {})",
                ep.action_space, s.action_space, s.action_space
            ))
        } else if s.state_names != ep.state_names {
            Some(format!(
                "state {:?}, the dataset has {:?}",
                ep.state_names, s.state_names
            ))
        } else if s.joint_names != ep.joint_names {
            Some(format!(
                "joints {:?}, the dataset has {:?}",
                ep.joint_names, s.joint_names
            ))
        } else if (s.fps - ep.fps).abs() > 1e-9 || s.image_size != ep.image_size {
            Some(format!(
                "{} fps {:?} images, the dataset has {} fps {:?}",
                ep.fps, ep.image_size, s.fps, s.image_size
            ))
        } else if let Some(c) = scaledp_schema::Rig::parse(&s.rig, Path::new("meta/info.json"))
            .ok()
            .and_then(|r| r.fov_change(&ep.rig))
        {
            Some(format!(
                "camera {} at a vertical field of view of {}, the dataset's at {}",
                c.camera,
                scaledp_schema::fov_label(c.to),
                scaledp_schema::fov_label(c.from)
            ))
        } else if s.video != ep.video.as_ref().map(VideoFormat::of) {
            Some(format!(
                "cameras as {}, the dataset has them as {}",
                stored_as(ep.video.as_ref().map(VideoFormat::of).as_ref()),
                stored_as(s.video.as_ref())
            ))
        } else if s.video.is_none() && s.jpeg_quality.is_some_and(|q| q != ep.jpeg_quality) {
            Some(format!(
                "JPEG quality {}, the dataset has {:?}",
                ep.jpeg_quality, s.jpeg_quality
            ))
        } else {
            None
        };
        match mismatch {
            Some(m) => Err(Error::Rejected {
                path: ep.source.clone(),
                reason: format!("does not fit the dataset: {m}"),
            }),
            None => Ok(()),
        }
    }
}

fn stored_as(v: Option<&VideoFormat>) -> String {
    v.map_or("JPEG images".into(), |v| format!("{} video", v.codec))
}

impl Dataset {
    /// An episode's arrays must have the shapes its names announce: a bug upstream (or an
    /// episode built by hand) is refused here, for this input, instead of failing the column
    /// writer with a message about arrays.
    pub(super) fn check_shapes(ep: &Episode) -> Result<()> {
        let n = ep.len();
        let (dim, joints) = (ep.state_names.len(), ep.joint_names.len());
        let wrong = if n == 0 {
            Some("no frames".to_string())
        } else if dim == 0 {
            Some("no state dimensions (no arm)".into())
        } else if ep.state.len() != n * dim || ep.action.len() != n * dim {
            Some(format!(
                "{} state and {} action values for {n} frames of {dim} dimensions",
                ep.state.len(),
                ep.action.len()
            ))
        } else if ep.joints.len() != n * joints {
            Some(format!(
                "{} joint values for {n} frames of {joints} joints",
                ep.joints.len()
            ))
        } else {
            let frames = |c: &crate::episode::CameraFrames| match &c.video {
                Some(v) => v.samples.len(),
                None => c.jpeg.len(),
            };
            let depth_wrong = |c: &crate::episode::CameraFrames| {
                let d = c.depth.as_ref()?;
                let want = super::depth::frame_bytes(d.encoding, ep.image_size);
                (d.frames.len() != n || d.frames.iter().any(|f| f.len() != want)).then(|| {
                    format!(
                        "depth of camera '{}' has {} frames (of {want} bytes each?), the episode {n}",
                        c.name,
                        d.frames.len()
                    )
                })
            };
            ep.cameras
                .iter()
                .find(|c| frames(c) != n)
                .map(|c| {
                    format!(
                        "camera '{}' has {} frames, the episode {n}",
                        c.name,
                        frames(c)
                    )
                })
                .or_else(|| ep.cameras.iter().find_map(depth_wrong))
        };
        match wrong {
            Some(why) => Err(Error::Rejected {
                path: ep.source.clone(),
                reason: format!("malformed episode: {why}"),
            }),
            None => Ok(()),
        }
    }
}
