//! The shuffled action-chunk loader for ScaleDP training: opens a LeRobot v3.0 dataset (what
//! `scaledp convert` writes, or any v3.0 dataset with image or video features — AV1 and H.264
//! in MP4, as LeRobot writes them — or both) from a directory or
//! S3-compatible storage, and yields contiguous batches — observation windows of To frames
//! (images `[B, To, cams, 3, H, W]`, normalized state), the next C actions, and
//! diffusion_policy-style edge padding with `obs_is_pad` / `action_is_pad` masks.
//!
//! Only the columns and rows a sample needs are read (for video, from the keyframe before a
//! window to its last frame); frames are decoded on a thread pool straight into the batch; batches are prepared ahead on a background thread. Orders are
//! seeded per epoch, identical for any thread count, shardable for DDP, and resumable. A
//! streaming mode reads whole episodes through a bounded buffer for datasets larger than memory.

mod batch;
mod decode;
mod depth;
mod episodes;
mod error;
mod files;
mod frames;
mod loader;
mod meta;
mod normalize;
mod open;
mod options;
mod reader;
mod sampler;
mod shared;
mod store;
mod stream;
mod video;

pub use batch::{Batch, DepthBatch};
pub use error::{Error, Result};
pub use files::DatasetFiles;
pub use loader::{Loader, LoaderState};
pub use meta::Feature;
pub use normalize::{Affine, Norm, Normalizer};
pub use options::LoaderOptions;
pub use sampler::{
    samples, split_episodes, streaming_order, window, Sample, Split, StreamSpec, Window,
};
pub use shared::{DatasetInfo, ImagePool};

/// An encoded image [`decode_image`] could not decode (corrupt, not JPEG or PNG, claiming
/// absurd dimensions), or a destination of the wrong size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct ImageError {
    /// What is wrong.
    pub reason: String,
}

/// Kept for callers that report errors as text.
impl From<ImageError> for String {
    fn from(e: ImageError) -> Self {
        e.reason
    }
}

/// LeRobot's `video_path` when `info.json` gives none.
pub const DEFAULT_VIDEO_PATH: &str = episodes::DEFAULT_VIDEO_PATH;

/// A LeRobot path template (`info.json`'s `video_path`) that cannot be filled: an unknown or
/// unclosed field, or a negative chunk or file index.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct TemplateError {
    /// What is wrong.
    pub reason: String,
}

/// Fills LeRobot's path template (Python format fields `{video_key}`, `{chunk_index:03d}`,
/// `{file_index:03d}`) for one video key, chunk and file: the loader's own, for tools that find
/// a dataset's video files as it does.
pub fn video_path(
    template: &str,
    key: &str,
    chunk: i64,
    file: i64,
) -> std::result::Result<String, TemplateError> {
    episodes::format_path(template, key, chunk, file).map_err(|reason| TemplateError { reason })
}

/// Decodes an encoded image (JPEG or PNG) into `dst`, channel-first RGB of `width` × `height`
/// (`3 × height × width` bytes; resized bilinearly when the image is another size) — the
/// loader's own decoder, for benchmarks that measure the decoding limit and for a deployment
/// node that must see frames as training did.
pub fn decode_image(
    encoded: &[u8],
    width: u32,
    height: u32,
    dst: &mut [u8],
) -> std::result::Result<(), ImageError> {
    let want = 3 * width as usize * height as usize;
    if dst.len() != want {
        return Err(ImageError {
            reason: format!(
                "destination of {} bytes for {width}×{height} RGB ({want} bytes)",
                dst.len()
            ),
        });
    }
    decode::decode_into(encoded, width, height, dst).map_err(|reason| ImageError { reason })
}
