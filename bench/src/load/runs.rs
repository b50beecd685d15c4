//! What one `bench load` run measured, route by route, and the goals it is read against;
//! the loader's shape (To, C) that every route samples.

use std::path::PathBuf;

use scaledp_testkit::Measured;

use super::decode::PureDecode;
use super::worker::EpochReport;
use crate::python::{LeRobotRun, ModuleRun, NotRun};

/// Loader images/s over pure-decode images/s.
pub(super) const TARGET_DECODE_RATIO: f64 = 0.8;
/// Loader samples/s over LeRobot's.
pub(super) const TARGET_LEROBOT_RATIO: f64 = 5.0;
/// Peak resident memory of the streaming run (bytes).
pub(super) const TARGET_STREAMING_RSS: u64 = 2_000_000_000;
/// Loader samples/s on video over the same loader on JPEG: "within 2×".
pub(super) const TARGET_VIDEO_JPEG_RATIO: f64 = 0.5;

/// The video routes: our loader and LeRobot's on the video dataset, and a streaming epoch over
/// the larger dataset as video.
pub(super) struct VideoRuns {
    pub(super) codec: &'static str,
    pub(super) how: String,
    pub(super) dataset: PathBuf,
    pub(super) video_bytes: u64,
    pub(super) ours: (Measured, EpochReport),
    pub(super) lerobot: Result<LeRobotRun, NotRun>,
    /// The epoch, the video bytes of its dataset, how it was made, its frames uncompressed.
    pub(super) streaming: Option<((Measured, EpochReport), u64, String, u64)>,
}

/// Everything one run measured.
pub(super) struct Runs {
    pub(super) threads: usize,
    pub(super) cores: usize,
    pub(super) how: String,
    pub(super) dataset: PathBuf,
    pub(super) data_bytes: u64,
    pub(super) load_before: Option<f64>,
    pub(super) ours: (Measured, EpochReport),
    pub(super) pure: PureDecode,
    pub(super) module: Result<ModuleRun, NotRun>,
    pub(super) lerobot: Result<LeRobotRun, NotRun>,
    /// The streaming epoch, the bytes of its dataset and how that was made.
    pub(super) streaming: Option<((Measured, EpochReport), u64, String)>,
    /// The video routes, or why they did not run.
    pub(super) video: Option<Result<VideoRuns, String>>,
}
