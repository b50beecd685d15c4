//! A rig's cameras: the colour stream, and beside it what the drivers publish that cannot be
//! recovered once a session is over: registered depth and the intrinsics (`camera_info`).

use serde::{Deserialize, Serialize};

/// Camera hardware, which fixes the raw encoding its ROS 2 wrapper publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraModel {
    /// Stereolabs ZED (zed-ros2-wrapper): `bgra8`.
    Zed,
    /// Intel RealSense (realsense-ros): `rgb8`.
    Realsense,
    /// A simulator's camera (the simulation benchmarks' bridges): `rgb8`.
    Sim,
}

impl CameraModel {
    /// The encoding the vendor's ROS 2 wrapper publishes on its color topic.
    pub fn default_encoding(self) -> &'static str {
        match self {
            Self::Zed => "bgra8",
            Self::Realsense | Self::Sim => "rgb8",
        }
    }
}

/// One camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Name used in feature names, e.g. `wrist`.
    pub name: String,
    /// Color image topic.
    pub topic: String,
    /// Hardware model.
    pub model: CameraModel,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Frame rate (Hz).
    pub fps: f64,
    /// Pixel encoding of raw images (`bgra8`, `rgb8`, …; the model's default when absent), or
    /// the codec of a compressed video stream (`h264`, `h265`, `av1`): the topic then carries
    /// `foxglove_msgs/msg/CompressedVideo`.
    pub encoding: Option<String>,
    /// True when the topic carries `sensor_msgs/CompressedImage`.
    #[serde(default)]
    pub compressed: bool,
    /// Depth registered to this camera's colour image, when the driver publishes it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<Depth>,
    /// `sensor_msgs/msg/CameraInfo` of the colour image (intrinsics: K, D, distortion model,
    /// size), recorded beside it and written into the dataset's metadata by `convert`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_info_topic: Option<String>,
    /// A simulated camera's vertical field of view (degrees), replacing the simulator's own: on
    /// a MuJoCo bridge (MetaWorld, ALOHA) a zoom that spends a small image's pixels on the
    /// workspace; the built-in cell places its fixed cameras to frame the workspace whatever
    /// their field, so there it zooms the wrist cameras. Real cameras ignore it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vertical_fov_deg: Option<f64>,
}

impl Camera {
    /// The encoding of this camera's raw images.
    pub fn encoding(&self) -> &str {
        self.encoding
            .as_deref()
            .unwrap_or(self.model.default_encoding())
    }
    /// The video codec when the topic carries `foxglove_msgs/msg/CompressedVideo`.
    pub fn video_codec(&self) -> Option<&str> {
        self.encoding
            .as_deref()
            .filter(|e| VIDEO_CODECS.contains(e))
    }
    /// The ROS 2 message type on the topic.
    pub fn message_type(&self) -> &'static str {
        if self.compressed {
            "sensor_msgs/msg/CompressedImage"
        } else if self.video_codec().is_some() {
            "foxglove_msgs/msg/CompressedVideo"
        } else {
            "sensor_msgs/msg/Image"
        }
    }
}

/// Codecs of `foxglove_msgs/msg/CompressedVideo` camera topics (a camera's `encoding`).
pub const VIDEO_CODECS: &[&str] = &["h264", "h265", "av1"];

/// Depth registered to a camera's colour image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Depth {
    /// The depth image topic (realsense2_camera `aligned_depth_to_color/image_raw`, the ZED
    /// wrapper's `depth/depth_registered`).
    pub topic: String,
    /// `16UC1` (millimetres, RealSense) or `32FC1` (metres, NaN or ±inf where unknown, ZED).
    pub encoding: DepthEncoding,
    /// True when the topic is image_transport's `compressedDepth` (`sensor_msgs/CompressedImage`,
    /// PNG behind a 12-byte header) instead of a raw `sensor_msgs/Image`.
    #[serde(default)]
    pub compressed: bool,
    /// The depth image's own `camera_info`, when the driver publishes one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera_info_topic: Option<String>,
}

/// The pixel encoding of a depth image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum DepthEncoding {
    /// Unsigned 16-bit millimetres, 0 where unknown.
    #[serde(rename = "16UC1")]
    U16Millimetres,
    /// 32-bit float metres, NaN or ±inf where unknown.
    #[serde(rename = "32FC1")]
    F32Metres,
}

impl DepthEncoding {
    /// As `sensor_msgs/Image.encoding` spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::U16Millimetres => "16UC1",
            Self::F32Metres => "32FC1",
        }
    }
    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::U16Millimetres => 2,
            Self::F32Metres => 4,
        }
    }
    /// The unit of its values.
    pub fn unit(self) -> &'static str {
        match self {
            Self::U16Millimetres => "mm",
            Self::F32Metres => "m",
        }
    }
}

impl Depth {
    /// The ROS 2 message type on the topic.
    pub fn message_type(&self) -> &'static str {
        if self.compressed {
            "sensor_msgs/msg/CompressedImage"
        } else {
            "sensor_msgs/msg/Image"
        }
    }
}
