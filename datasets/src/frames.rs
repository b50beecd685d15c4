//! Where the cameras' frames come from, behind one small trait: encoded images in the data
//! files' Parquet columns ([`ImageSource`]) or video files ([`crate::video::VideoSource`]). A
//! source serves some of the batch's cameras; the batch code asks it for the frames a window
//! (or, streaming, a whole episode) needs, then for each frame decoded into its slot.

use std::ops::Range;
use std::sync::Arc;

use crate::decode::decode_into;
use crate::error::{Error, Result};
use crate::reader::{Data, EpisodeRows, ImageColumn};

/// A source of camera frames.
pub(crate) trait FrameSource: Send + Sync {
    /// Reads what frames `frames` (episode frame indices) of `ep` need, for every camera the
    /// source serves.
    fn fetch(&self, ep: &EpisodeRows, frames: Range<usize>) -> Result<Arc<dyn Fetched>>;
}

/// Frames read by a [`FrameSource`], decoded on demand (from any thread).
pub(crate) trait Fetched: Send + Sync {
    /// Decodes frame `frame` (an episode frame index among those fetched) of the source's
    /// camera `cam` into `dst`: channel-first RGB, `width × height`.
    fn decode(
        &self,
        cam: usize,
        frame: usize,
        width: u32,
        height: u32,
        dst: &mut [u8],
    ) -> Result<()>;
}

/// A source and the batch's camera slots its cameras fill, in the source's camera order.
pub(crate) struct Sourced {
    pub source: Box<dyn FrameSource>,
    pub slots: Vec<usize>,
}

/// Image features: encoded JPEG/PNG bytes in the data files, read one Parquet page per frame.
pub(crate) struct ImageSource {
    pub data: Arc<Data>,
    /// Camera keys (columns), in the source's order.
    pub cameras: Vec<String>,
}

struct FetchedImages {
    cols: Vec<ImageColumn>,
    /// Episode frame index of the first row read.
    base: usize,
    file: String,
    episode: i64,
    cameras: Vec<String>,
}

impl FrameSource for ImageSource {
    fn fetch(&self, ep: &EpisodeRows, frames: Range<usize>) -> Result<Arc<dyn Fetched>> {
        let rows = ep.first_row + frames.start..ep.first_row + frames.end;
        let cols = self.data.read_images(ep.file, rows, &self.cameras)?;
        Ok(Arc::new(FetchedImages {
            cols,
            base: frames.start,
            file: self.data.files[ep.file].file.name.clone(),
            episode: ep.episode_index,
            cameras: self.cameras.clone(),
        }))
    }
}

impl Fetched for FetchedImages {
    fn decode(
        &self,
        cam: usize,
        frame: usize,
        width: u32,
        height: u32,
        dst: &mut [u8],
    ) -> Result<()> {
        let err = |reason: String| Error::Image {
            path: self.file.clone(),
            episode: self.episode,
            frame,
            camera: self.cameras[cam].clone(),
            reason,
        };
        let encoded = frame
            .checked_sub(self.base)
            .and_then(|i| self.cols[cam].get(i))
            .ok_or_else(|| err("no image (null)".into()))?;
        decode_into(encoded, width, height, dst).map_err(err)
    }
}
