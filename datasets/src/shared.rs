//! What the loader and its prefetch thread share: the dataset as opened (data, frame sources,
//! episodes of the split, normalizer, options), the decoding pool, the image buffers handed
//! back for reuse, and the count of skipped samples. Built once by [`crate::open`]; read by
//! the sampling ([`crate::loader`]), the batch builder and the streaming cache.

use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex};

use crate::depth::DepthSource;
use crate::frames::Sourced;
use crate::normalize::Normalizer;
use crate::options::LoaderOptions;
use crate::reader::{Data, EpisodeRows};
use crate::sampler::Sample;

/// What a loader reads.
#[derive(Clone, Debug)]
pub struct DatasetInfo {
    /// The dataset location.
    pub location: String,
    /// Frames per second.
    pub fps: f64,
    /// Camera keys in image order.
    pub cameras: Vec<String>,
    /// Output image size.
    pub width: u32,
    /// Output image size.
    pub height: u32,
    /// Names of the state dimensions.
    pub state_names: Vec<String>,
    /// Names of the action dimensions.
    pub action_names: Vec<String>,
    /// `episode_index` of every episode used (the split, capped), ascending.
    pub episodes: Vec<i64>,
    /// Frames of each of those episodes, in the same order.
    pub episode_lengths: Vec<usize>,
    /// Frames of those episodes.
    pub frames: usize,
    /// Episodes in the whole dataset.
    pub total_episodes: usize,
    /// Depth feature keys in [`crate::Batch::depth`] order (empty unless depth was asked for).
    pub depth_cameras: Vec<String>,
    /// Their units, `mm` or `m`, in the same order.
    pub depth_units: Vec<String>,
    /// `scaledp.cameras` of `info.json`, per camera name: `intrinsics` (K, D, P for the stored
    /// image size) and `depth` (unit, the depth image's intrinsics), when the dataset has them.
    pub sensors: serde_json::Map<String, serde_json::Value>,
}

/// Everything the prefetch thread shares with the loader.
pub(crate) struct Shared {
    pub data: Arc<Data>,
    /// Where the cameras' frames come from (images, video), each with its batch slots.
    pub sources: Vec<Sourced>,
    /// Where depth comes from, when asked for.
    pub depth: Option<DepthSource>,
    pub episodes: Vec<EpisodeRows>,
    pub opts: LoaderOptions,
    pub info: DatasetInfo,
    pub norm: Normalizer,
    pub pool: rayon::ThreadPool,
    /// Every sample of the split, in order (the epochs' orders are drawn from these).
    pub samples: Vec<Sample>,
    /// Image buffers handed back for the next batches.
    pub spare: ImagePool,
    /// Samples left out because their images could not be read (see
    /// [`LoaderOptions::skip_bad_samples`]).
    pub skipped: AtomicU64,
}

/// Where consumers hand batches' image buffers back ([`Loader::recycle`], or
/// [`Loader::image_pool`] for a buffer that outlives its batch, as a numpy array does), so
/// that later batches are written into memory already mapped instead of fresh pages: a batch of
/// 64 × 2 × 3 × 320×240 holds 88 MB of images, and faulting in new pages for every batch cost
/// ~12 % of the loader's CPU time. A cheap handle: clones share one pool, which keeps at most
/// a few buffers (`prefetch` + 2); the rest are freed.
#[derive(Clone, Debug)]
pub struct ImagePool {
    spare: Arc<Mutex<Vec<Vec<u8>>>>,
    keep: usize,
}

impl ImagePool {
    pub(crate) fn new(keep: usize) -> Self {
        ImagePool {
            spare: Arc::new(Mutex::new(Vec::new())),
            keep,
        }
    }

    /// Gives a batch's `images` buffer back for reuse.
    pub fn put(&self, images: Vec<u8>) {
        if images.capacity() == 0 {
            return;
        }
        if let Ok(mut spare) = self.spare.lock() {
            if spare.len() < self.keep {
                spare.push(images);
            }
        }
    }

    /// A buffer of `len` image bytes: a recycled one when there is one (its old contents are
    /// left in place: every byte of a batch's images is written), else a new one.
    pub(crate) fn take(&self, len: usize) -> Vec<u8> {
        let spare = self.spare.lock().ok().and_then(|mut s| s.pop());
        match spare {
            Some(mut v) => {
                v.resize(len, 0);
                v
            }
            None => vec![0; len],
        }
    }
}
