//! Cameras stored as LeRobot v3 video features: one MP4 per camera and file index
//! (`videos/observation.images.<camera>/chunk-XXX/file-YYY.mp4`), episodes concatenated in
//! it at the dataset's frame rate, each episode's span in the episodes metadata
//! (`from_timestamp`, `to_timestamp`). Like the open data file, the open video file is
//! rewritten whole (from the encoded episodes kept in memory, a few MB each) and renamed into
//! place with each commit, so it is always a complete, valid MP4 that lists only committed
//! episodes; a file is closed once one camera's MP4 passes the size target.

use std::path::{Path, PathBuf};

use scaledp_codec::{mp4_file, Codec, EncodedVideo, VideoSettings};
use serde::{Deserialize, Serialize};

use super::columns::{derr, stage, Staged, CHUNKS_SIZE};
use crate::error::Result;

/// LeRobot's default size target of a video file (`video_files_size_in_mb`).
pub const VIDEO_FILE_SIZE_MB: u64 = 200;

/// How a dataset's cameras are encoded (recorded in `meta/scaledp.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoFormat {
    /// `av1` or `h264` (what ffprobe and LeRobot's `video.codec` call them).
    pub codec: String,
    /// Always `yuv420p`.
    pub pix_fmt: String,
    /// Frames from one keyframe to the next.
    pub gop: u32,
    /// Constant rate factor (AV1: 0–63; H.264: the QP it maps to).
    pub crf: u8,
}

impl VideoFormat {
    /// The record of `settings`.
    pub fn of(settings: &VideoSettings) -> Self {
        Self {
            codec: codec_name(settings.codec).into(),
            pix_fmt: "yuv420p".into(),
            gop: settings.gop,
            crf: settings.crf,
        }
    }
}

/// The name LeRobot's `video.codec` gives `codec`.
pub fn codec_name(codec: Codec) -> &'static str {
    match codec {
        Codec::Av1 => "av1",
        Codec::H264 => "h264",
    }
}

/// Where one episode's frames are in its cameras' videos (the same for every camera).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VideoSpan {
    /// Video file (global number; chunk = n / 1000, file = n % 1000).
    pub file: u64,
    /// Time of the episode's first frame in the file (s).
    pub from_timestamp: f64,
    /// Time just past its last frame (s): `from_timestamp + length / fps`.
    pub to_timestamp: f64,
}

/// `videos/<key>/chunk-XXX/file-YYY.mp4` of a global file number.
pub fn video_path(root: &Path, key: &str, file: u64) -> PathBuf {
    root.join(format!(
        "videos/{key}/chunk-{:03}/file-{:03}.mp4",
        file / CHUNKS_SIZE,
        file % CHUNKS_SIZE
    ))
}

/// The video file still open for more episodes: each camera's encoded episodes in it.
pub(super) struct VideoTail {
    pub file: u64,
    /// Frames already in the file.
    pub frames: u64,
    /// Per camera (dataset order), its episodes' streams.
    pub pieces: Vec<Vec<EncodedVideo>>,
}

impl VideoTail {
    /// A new file `file` for `cameras` cameras.
    pub fn new(file: u64, cameras: usize) -> Self {
        Self {
            file,
            frames: 0,
            pieces: vec![Vec::new(); cameras],
        }
    }

    /// True when this episode's streams can be appended to the file: a stream whose
    /// configuration differs (another encoder build, another size) starts a new file, since
    /// one MP4 track has one sample description.
    pub fn accepts(&self, streams: &[&EncodedVideo]) -> bool {
        self.pieces.iter().zip(streams).all(|(have, new)| {
            have.first().is_none_or(|h| {
                h.config == new.config
                    && (h.codec, h.width, h.height) == (new.codec, new.width, new.height)
            })
        })
    }

    /// Adds an episode of `frames` frames (one stream per camera), stages every camera's MP4
    /// under `root`, and returns the episode's span and the largest MP4's size in bytes.
    pub fn add_and_stage(
        &mut self,
        root: &Path,
        keys: &[String],
        streams: Vec<EncodedVideo>,
        frames: u64,
        fps: f64,
        staged: &mut Staged,
    ) -> Result<(VideoSpan, u64)> {
        for (have, s) in self.pieces.iter_mut().zip(streams) {
            if s.samples.len() as u64 != frames {
                return Err(derr(
                    root,
                    format!("a video of {} frames for {frames} rows", s.samples.len()),
                ));
            }
            have.push(s);
        }
        let span = VideoSpan {
            file: self.file,
            from_timestamp: self.frames as f64 / fps,
            to_timestamp: (self.frames + frames) as f64 / fps,
        };
        self.frames += frames;
        let mut largest = 0;
        for (key, pieces) in keys.iter().zip(&self.pieces) {
            let path = video_path(root, key, self.file);
            let parts: Vec<&EncodedVideo> = pieces.iter().collect();
            let bytes = mp4_file(&parts, fps).map_err(|e| derr(&path, e))?;
            largest = largest.max(bytes.len() as u64);
            stage(&path, &bytes, staged)?;
        }
        Ok((span, largest))
    }
}
