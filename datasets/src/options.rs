//! [`LoaderOptions`]: what a sample is, which episodes, how batches are ordered and built.

use crate::normalize::Norm;
use crate::sampler::Split;

/// Options of a [`crate::Loader`], set with chained setters; `open` makes the loader.
///
/// ```no_run
/// use scaledp_datasets::{LoaderOptions, Split};
/// let mut loader = LoaderOptions::default()
///     .obs_horizon(2)
///     .action_chunk(16)
///     .split(Split::Train)
///     .val_ratio(0.1)
///     .open("datasets/cups")?;
/// while let Some(batch) = loader.next_batch() {
///     let batch = batch?;
///     // batch.images: [B, To, cams, 3, H, W] u8; batch.action: [B, C, A] f32 in [-1, 1]
/// }
/// # Ok::<(), scaledp_datasets::Error>(())
/// ```
#[derive(Clone, Debug)]
pub struct LoaderOptions {
    pub(crate) obs_horizon: usize,
    pub(crate) action_chunk: usize,
    pub(crate) action_offset: usize,
    pub(crate) cameras: Option<Vec<String>>,
    pub(crate) image_size: Option<(u32, u32)>,
    pub(crate) drop_first: usize,
    pub(crate) drop_last: usize,
    pub(crate) split: Split,
    pub(crate) val_ratio: f64,
    pub(crate) split_seed: u64,
    pub(crate) max_episodes: Option<usize>,
    pub(crate) state_norm: Norm,
    pub(crate) action_norm: Norm,
    pub(crate) state_key: String,
    pub(crate) action_key: String,
    pub(crate) batch_size: usize,
    pub(crate) drop_incomplete_batch: bool,
    pub(crate) shuffle: bool,
    pub(crate) seed: u64,
    pub(crate) rank: usize,
    pub(crate) world_size: usize,
    pub(crate) threads: usize,
    pub(crate) prefetch: usize,
    pub(crate) streaming: Option<usize>,
    pub(crate) skip_bad_samples: usize,
    pub(crate) video_tolerance_s: f64,
    pub(crate) video_decoders: usize,
    pub(crate) depth: bool,
}

impl Default for LoaderOptions {
    fn default() -> Self {
        LoaderOptions {
            obs_horizon: 2,
            action_chunk: 16,
            action_offset: 0,
            cameras: None,
            image_size: None,
            drop_first: 0,
            drop_last: 0,
            split: Split::All,
            val_ratio: 0.0,
            split_seed: 0,
            max_episodes: None,
            state_norm: Norm::MeanStd,
            action_norm: Norm::MinMax,
            state_key: "observation.state".into(),
            action_key: "action".into(),
            batch_size: 64,
            drop_incomplete_batch: false,
            shuffle: true,
            seed: 0,
            rank: 0,
            world_size: 1,
            threads: 0,
            prefetch: 2,
            streaming: None,
            skip_bad_samples: 0,
            video_tolerance_s: 1e-4,
            video_decoders: 0,
            depth: false,
        }
    }
}

impl LoaderOptions {
    /// Observation frames per sample, To (default 2): frames t−To+1 ..= t.
    pub fn obs_horizon(mut self, n: usize) -> Self {
        self.obs_horizon = n;
        self
    }
    /// Actions per sample, C (default 16).
    pub fn action_chunk(mut self, n: usize) -> Self {
        self.action_chunk = n;
        self
    }
    /// First action frame relative to the current frame t (default 0: our converter's action at
    /// t is already the next tick's pose).
    pub fn action_offset(mut self, n: usize) -> Self {
        self.action_offset = n;
        self
    }
    /// Cameras to load, by short name (`wrist`) or key (`observation.images.wrist`); default all.
    pub fn cameras(mut self, names: Vec<String>) -> Self {
        self.cameras = Some(names);
        self
    }
    /// Output image size (default: as stored); other sizes are resized bilinearly.
    pub fn image_size(mut self, width: u32, height: u32) -> Self {
        self.image_size = Some((width, height));
        self
    }
    /// Frames at each episode's start never used as the current frame (default 0).
    pub fn drop_first(mut self, n: usize) -> Self {
        self.drop_first = n;
        self
    }
    /// Frames at each episode's end never used as the current frame (default 0).
    pub fn drop_last(mut self, n: usize) -> Self {
        self.drop_last = n;
        self
    }
    /// Which episodes (default [`Split::All`]).
    pub fn split(mut self, s: Split) -> Self {
        self.split = s;
        self
    }
    /// Fraction of episodes in the validation split (default 0).
    pub fn val_ratio(mut self, r: f64) -> Self {
        self.val_ratio = r;
        self
    }
    /// Seed of the split (default 0).
    pub fn split_seed(mut self, seed: u64) -> Self {
        self.split_seed = seed;
        self
    }
    /// Use at most this many episodes of the split (data-scaling studies; smaller caps are subsets).
    pub fn max_episodes(mut self, n: usize) -> Self {
        self.max_episodes = Some(n);
        self
    }
    /// State normalization (default [`Norm::MeanStd`]).
    pub fn state_norm(mut self, n: Norm) -> Self {
        self.state_norm = n;
        self
    }
    /// Action normalization (default [`Norm::MinMax`]).
    pub fn action_norm(mut self, n: Norm) -> Self {
        self.action_norm = n;
        self
    }
    /// The state feature (default `observation.state`).
    pub fn state_key(mut self, key: &str) -> Self {
        self.state_key = key.into();
        self
    }
    /// The action feature (default `action`).
    pub fn action_key(mut self, key: &str) -> Self {
        self.action_key = key.into();
        self
    }
    /// Samples per batch (default 64).
    pub fn batch_size(mut self, n: usize) -> Self {
        self.batch_size = n;
        self
    }
    /// Leave out the epoch's last batch when it is short (default false).
    pub fn drop_incomplete_batch(mut self, yes: bool) -> Self {
        self.drop_incomplete_batch = yes;
        self
    }
    /// Shuffle samples (default true).
    pub fn shuffle(mut self, yes: bool) -> Self {
        self.shuffle = yes;
        self
    }
    /// Seed of the per-epoch permutation (default 0).
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }
    /// This process's rank and the world size of a DDP job (default 0 of 1).
    pub fn rank(mut self, rank: usize, world_size: usize) -> Self {
        self.rank = rank;
        self.world_size = world_size;
        self
    }
    /// Decoding threads (default 0: one per available core).
    pub fn threads(mut self, n: usize) -> Self {
        self.threads = n;
        self
    }
    /// Batches prepared ahead of the consumer (default 2).
    pub fn prefetch(mut self, batches: usize) -> Self {
        self.prefetch = batches;
        self
    }
    /// Streaming mode: read whole episodes in a seeded order, `buffer_episodes` open at a time,
    /// samples drawn at random among them (default: random access over the whole split).
    pub fn streaming(mut self, buffer_episodes: usize) -> Self {
        self.streaming = Some(buffer_episodes);
        self
    }
    /// Leave out of their batch (logged, counted by [`crate::Loader::skipped_samples`]) up to
    /// `max` samples whose images cannot be read or decoded (a corrupt JPEG, a data file cut
    /// short, an object store that keeps dropping the connection) instead of failing the batch;
    /// the next one fails it. A batch with skipped samples is that much shorter. Default 0:
    /// the first bad sample is an error.
    pub fn skip_bad_samples(mut self, max: usize) -> Self {
        self.skip_bad_samples = max;
        self
    }
    /// Video features: how far (seconds) the frame shown nearest to a row's time may be from it
    /// (default 1e-4, LeRobot's `tolerance_s`); farther is an error naming the file and frame.
    pub fn video_tolerance_s(mut self, seconds: f64) -> Self {
        self.video_tolerance_s = seconds;
        self
    }
    /// Video features: decoders kept between samples, with where they stand in their file, so
    /// a later frame of the same group of pictures goes on instead of starting again at the
    /// keyframe (default 0: twice the decoding threads × video cameras, 4 to 256).
    pub fn video_decoders(mut self, n: usize) -> Self {
        self.video_decoders = n;
        self
    }
    /// Also yield the depth of the cameras loaded that have an `observation.depth.<camera>`
    /// feature, in [`crate::Batch::depth`] (`f32` in the stored unit, which
    /// [`crate::DatasetInfo::depth_units`] names; default false: depth is not read). Opening
    /// fails when none of the cameras has depth.
    pub fn depth(mut self, yes: bool) -> Self {
        self.depth = yes;
        self
    }
    /// Opens the dataset at `location` (a directory or `s3://bucket/prefix`).
    pub fn open(self, location: &str) -> crate::Result<crate::Loader> {
        let (shared, bytes_read) = crate::open::open(location, self)?;
        Ok(crate::Loader::new(shared, bytes_read))
    }
}
