//! A camera's intrinsics as a dataset records them: its `sensor_msgs/msg/CameraInfo` (K, D,
//! distortion model, R, P) made to describe the images the dataset stores, which `convert`
//! resizes whole to `--size` (no crop): fx, cx (and K's skew, P's first row) scale by the width
//! ratio, fy, cy (P's second row) by the height ratio — as image_proc's resize node scales
//! them; D and R do not change. A camera_info whose size is not the images' (another stream's,
//! or binned / ROI-cropped, which is not applied here), or an uncalibrated one (K all zero),
//! gives no intrinsics, with a warning.

use std::path::Path;

use scaledp_schema::msg::CameraInfo;
use scaledp_schema::RosMessage;
use serde::{Deserialize, Serialize};

use crate::source::{RawMessage, Serialization};

/// Decodes a stored `sensor_msgs/msg/CameraInfo` of either serialization.
pub(crate) fn decode(m: &RawMessage) -> Result<CameraInfo, String> {
    match m.serialization {
        Serialization::Cdr => CameraInfo::from_cdr(&m.data)
            .map_err(|e| format!("not a sensor_msgs/msg/CameraInfo: {e}")),
        Serialization::Ros1 => crate::ros1::decode::camera_info(&m.data).map_err(String::from),
    }
}

/// A camera's intrinsics for the images a dataset stores (`scaledp.cameras.<camera>.intrinsics`
/// in `meta/info.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// The `camera_info` topic they come from.
    pub topic: String,
    /// The optical frame (`header.frame_id`).
    pub frame_id: String,
    /// Width of the stored images, which K and P describe.
    pub width: u32,
    /// Height of the stored images.
    pub height: u32,
    /// Width the camera_info gave (the recorded images').
    pub source_width: u32,
    /// Height the camera_info gave.
    pub source_height: u32,
    /// `plumb_bob`, `rational_polynomial`, `equidistant`, …
    pub distortion_model: String,
    /// Distortion coefficients (unchanged by resizing).
    pub d: Vec<f64>,
    /// 3×3 camera matrix, row-major, scaled to `width × height`.
    pub k: [f64; 9],
    /// 3×3 rectification rotation, row-major.
    pub r: [f64; 9],
    /// 3×4 projection matrix, row-major, scaled to `width × height`.
    pub p: [f64; 12],
}

impl Intrinsics {
    /// `info` (of `topic`) for images resized from `source` to `stored` (width, height); why
    /// not, as one line, when the camera_info does not describe those images.
    pub(crate) fn scaled(
        topic: &str,
        info: &CameraInfo,
        source: (u32, u32),
        stored: (u32, u32),
    ) -> Result<Self, String> {
        if (info.width, info.height) != source {
            return Err(format!(
                "camera_info {topic} is {}×{}, the images are {}×{}",
                info.width, info.height, source.0, source.1
            ));
        }
        let roi = &info.roi;
        let whole_image = roi.height == 0
            || roi.width == 0
            || (roi.x_offset, roi.y_offset, roi.height, roi.width)
                == (0, 0, info.height, info.width);
        if info.binning_x > 1 || info.binning_y > 1 || !whole_image {
            return Err(format!(
                "camera_info {topic} has binning {}×{} or a region of interest {}×{} at ({}, {}), \
                 which the converter does not apply",
                info.binning_x, info.binning_y, roi.width, roi.height, roi.x_offset, roi.y_offset
            ));
        }
        if info.k.iter().all(|&v| v == 0.0) {
            return Err(format!(
                "camera_info {topic} is uncalibrated (K is all zero)"
            ));
        }
        let all = info.k.iter().chain(&info.r).chain(&info.p).chain(&info.d);
        if all.clone().any(|v| !v.is_finite()) {
            return Err(format!(
                "camera_info {topic} has a value that is not finite"
            ));
        }
        let sx = f64::from(stored.0) / f64::from(source.0);
        let sy = f64::from(stored.1) / f64::from(source.1);
        let mut k = info.k;
        for i in 0..3 {
            k[i] *= sx;
            k[3 + i] *= sy;
        }
        let mut p = info.p;
        for i in 0..4 {
            p[i] *= sx;
            p[4 + i] *= sy;
        }
        Ok(Self {
            topic: topic.to_string(),
            frame_id: info.header.frame_id.clone(),
            width: stored.0,
            height: stored.1,
            source_width: source.0,
            source_height: source.1,
            distortion_model: info.distortion_model.clone(),
            d: info.d.clone(),
            k,
            r: info.r,
            p,
        })
    }
}

/// The intrinsics from the first camera_info message of `topic` in `messages` (the episode's
/// window), for images of `source` size stored at `stored` size; None with one warning naming
/// the input, the topic and why, when there is none or it does not fit.
pub(crate) fn intrinsics_of(
    path: &Path,
    camera: &str,
    topic: &str,
    messages: &[&RawMessage],
    source: (u32, u32),
    stored: (u32, u32),
) -> Option<Intrinsics> {
    let warn = |why: String| {
        tracing::warn!(
            "{}: camera '{camera}': {why}: intrinsics left out",
            path.display()
        );
        None
    };
    let Some(m) = messages.first() else {
        return warn(format!("no camera_info on {topic}"));
    };
    match decode(m).and_then(|i| Intrinsics::scaled(topic, &i, source, stored)) {
        Ok(i) => Some(i),
        Err(why) => warn(why),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use scaledp_schema::msg::Header;

    #[test]
    fn intrinsics_scale_with_the_stored_size() {
        let mut info = CameraInfo::pinhole(Header::default(), 640, 480, 615.0, 320.5, 240.25);
        info.k[4] = 614.0;
        info.p[5] = 614.0;
        info.d = vec![0.1, -0.2, 0.0, 0.0, 0.01];
        let info = CameraInfo::from_cdr(&info.to_cdr()).unwrap();
        assert_eq!((info.width, info.height, info.d.len()), (640, 480, 5));
        let i = Intrinsics::scaled("/cam/camera_info", &info, (640, 480), (320, 240)).unwrap();
        assert_eq!(
            i.k,
            [307.5, 0.0, 160.25, 0.0, 307.0, 120.125, 0.0, 0.0, 1.0]
        );
        assert_eq!(
            (i.p[0], i.p[2], i.p[5], i.p[6], i.p[10]),
            (307.5, 160.25, 307.0, 120.125, 1.0)
        );
        assert_eq!(i.d, vec![0.1, -0.2, 0.0, 0.0, 0.01]);
        // Another aspect ratio: x and y scale apart.
        let j = Intrinsics::scaled("/c", &info, (640, 480), (64, 120)).unwrap();
        assert_eq!((j.k[0], j.k[4], j.k[5]), (61.5, 153.5, 60.0625));
        let e = Intrinsics::scaled("/cam/camera_info", &info, (1280, 720), (320, 240)).unwrap_err();
        assert_eq!(
            e,
            "camera_info /cam/camera_info is 640×480, the images are 1280×720"
        );
        let zero = CameraInfo {
            k: [0.0; 9],
            ..info.clone()
        };
        assert!(Intrinsics::scaled("/c", &zero, (640, 480), (320, 240))
            .unwrap_err()
            .contains("uncalibrated"));
        let binned = CameraInfo {
            binning_x: 2,
            ..info
        };
        assert!(Intrinsics::scaled("/c", &binned, (640, 480), (320, 240))
            .unwrap_err()
            .contains("binning"));
        let m = RawMessage {
            topic: "/c".into(),
            message_type: "sensor_msgs/msg/CameraInfo".into(),
            log_time_ns: 0,
            data: vec![0, 1, 0, 0, 1, 2],
            serialization: Serialization::Cdr,
        };
        assert!(decode(&m).unwrap_err().starts_with("not a sensor_msgs"));
    }
}
