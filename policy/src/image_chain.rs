//! The image chain a checkpoint was trained on: every step from a camera frame to the pixels
//! its encoders saw, recorded in `config.json` so a controller can reproduce it exactly.
//!
//! For a dataset written by `scaledp convert` the chain is: camera frame → Lanczos3 resize to
//! the stored size → JPEG at the stored quality (what the dataset holds) → decode → the
//! loader's bilinear resize to the model's size when `train --image-size` asked for another
//! size → crop (random in training, centred at inference) → pixel range. A deployment that
//! skips a step (resizing the camera frame straight to the model's size, say) feeds the policy
//! images it was never trained on.

use serde::{Deserialize, Serialize};

/// How the dataset's frames were made from camera frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoredImages {
    /// Stored width (px).
    pub width: u32,
    /// Stored height (px).
    pub height: u32,
    /// How a camera frame became a stored frame: `scaledp-convert` (the converter's path:
    /// Lanczos3 to the stored size, then JPEG at `jpeg_quality`), or `unknown` (a dataset
    /// written by another tool: a controller approximates it with the converter's path).
    pub made_by: String,
    /// JPEG quality of the stored frames, when known.
    pub jpeg_quality: Option<u8>,
}

/// The loader's resize from the stored size to the model's input size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainResize {
    /// Model input width (px, before the crop).
    pub width: u32,
    /// Model input height (px, before the crop).
    pub height: u32,
    /// `bilinear` (fast_image_resize's convolution filter, as `scaledp_datasets` decodes).
    pub filter: String,
}

/// Camera frame → encoder input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageChain {
    /// What the dataset holds.
    pub stored: StoredImages,
    /// The loader's resize, when the model's size differs from the stored one.
    pub train_resize: Option<TrainResize>,
    /// Crop side / image side: random windows in training, the centred one at inference.
    pub crop: f64,
    /// The pixel range the encoders see (`symmetric` [−1, 1] or `unit` [0, 1]).
    pub range: crate::config::ImageRange,
}

/// The JPEG quality the converter writes by default (what a checkpoint without a recorded
/// chain is assumed to have seen).
pub const DEFAULT_JPEG_QUALITY: u8 = 90;

impl ImageChain {
    /// The chain of a checkpoint written before chains were recorded: stored at the model's
    /// size by the converter at its default quality, no loader resize.
    pub fn legacy(model: &crate::ModelConfig) -> Self {
        ImageChain {
            stored: StoredImages {
                width: model.image_width,
                height: model.image_height,
                made_by: "scaledp-convert".into(),
                jpeg_quality: Some(DEFAULT_JPEG_QUALITY),
            },
            train_resize: None,
            crop: model.crop,
            range: model.image_range,
        }
    }

    /// The stored size (width, height) a camera frame must be brought to first.
    pub fn stored_size(&self) -> (u32, u32) {
        (self.stored.width, self.stored.height)
    }

    /// The JPEG quality to encode stored frames with.
    pub fn jpeg_quality(&self) -> u8 {
        self.stored.jpeg_quality.unwrap_or(DEFAULT_JPEG_QUALITY)
    }

    /// Whether the controller reproduces the chain exactly (the dataset came from our
    /// converter).
    pub fn exact(&self) -> bool {
        self.stored.made_by == "scaledp-convert" && self.stored.jpeg_quality.is_some()
    }

    /// One line for logs: `320x180 jpeg q90 (scaledp-convert) → bilinear 84x84 → crop 0.9`.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "{}x{} jpeg q{} ({})",
            self.stored.width,
            self.stored.height,
            self.jpeg_quality(),
            self.stored.made_by
        );
        if let Some(r) = &self.train_resize {
            s.push_str(&format!(" → {} {}x{}", r.filter, r.width, r.height));
        }
        s.push_str(&format!(" → crop {}", self.crop));
        s
    }
}
