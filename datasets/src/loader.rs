//! [`Loader`]: opens a dataset, keeps this epoch's order, and hands out batches that a
//! background thread prepares `prefetch` ahead on a rayon pool.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use crossbeam_channel::{bounded, Receiver};

use crate::batch::{self, Batch};
use crate::error::{Error, Result};
use crate::meta::Meta;
use crate::normalize::{Affine, Normalizer};
use crate::options::LoaderOptions;
use crate::reader::{Data, EpisodeRows};
use crate::sampler::{self, Sample};
use crate::store::Store;
use crate::stream::Cache;

/// Most frames in an observation window or action chunk, and the largest action offset.
const MAX_WINDOW: usize = 100_000;
/// Largest image side.
const MAX_SIDE: u32 = 16_384;
/// Largest image buffer of one batch (bytes).
const MAX_BATCH_IMAGE_BYTES: u128 = 16 << 30;

/// Image size and batch options that give a buffer we can allocate.
fn check_batch_size(
    opts: &LoaderOptions,
    cameras: usize,
    width: u32,
    height: u32,
) -> std::result::Result<(), String> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(format!(
            "image size {width}×{height}: each side must be 1 ..= {MAX_SIDE}"
        ));
    }
    let bytes = [opts.batch_size, opts.obs_horizon, cameras, 3]
        .iter()
        .fold(u128::from(width) * u128::from(height), |a, &n| {
            a * n as u128
        });
    if bytes > MAX_BATCH_IMAGE_BYTES {
        return Err(format!(
            "a batch of {} samples × {} frames × {cameras} cameras of {width}×{height} needs {:.1} GiB of images: use a smaller batch or image size",
            opts.batch_size,
            opts.obs_horizon,
            bytes as f64 / f64::from(1u32 << 30)
        ));
    }
    Ok(())
}

/// Options that make no loader, whatever the dataset.
fn check_options(opts: &LoaderOptions) -> std::result::Result<(), String> {
    if opts.obs_horizon == 0 || opts.action_chunk == 0 || opts.batch_size == 0 {
        return Err("obs_horizon, action_chunk and batch_size must be at least 1".into());
    }
    if opts.world_size == 0 || opts.rank >= opts.world_size {
        return Err(format!(
            "rank {} of world size {}",
            opts.rank, opts.world_size
        ));
    }
    if opts.obs_horizon > MAX_WINDOW
        || opts.action_chunk > MAX_WINDOW
        || opts.action_offset > MAX_WINDOW
        || opts.drop_first > u32::MAX as usize
        || opts.drop_last > u32::MAX as usize
    {
        return Err(format!(
            "obs_horizon, action_chunk and action_offset must be at most {MAX_WINDOW}, drop_first and drop_last at most {}",
            u32::MAX
        ));
    }
    if !(0.0..=1.0).contains(&opts.val_ratio) {
        return Err(format!("val_ratio {} outside [0, 1]", opts.val_ratio));
    }
    Ok(())
}

/// The image features to load (keys), in order: all of them, or those the options name (by
/// short name or key). Video features are refused.
fn pick_cameras(meta: &Meta, opts: &LoaderOptions, info_file: &str) -> Result<Vec<String>> {
    for key in [&opts.state_key, &opts.action_key] {
        if !meta.features.contains_key(key) {
            return Err(Error::format(info_file, format!("no feature {key}")));
        }
    }
    let all_cams = meta.image_keys();
    let cameras: Vec<String> = match &opts.cameras {
        None => all_cams.clone(),
        Some(names) => names
            .iter()
            .map(|n| {
                [n.clone(), format!("observation.images.{n}")]
                    .into_iter()
                    .find(|k| all_cams.contains(k))
                    .ok_or_else(|| {
                        Error::format(info_file, format!("no camera {n} (cameras: {all_cams:?})"))
                    })
            })
            .collect::<Result<_>>()?,
    };
    for c in &cameras {
        if meta.features[c].dtype == "video" {
            return Err(Error::format(
                info_file,
                format!("{c} is stored as video; this loader reads image features (convert with images)"),
            ));
        }
    }
    Ok(cameras)
}

/// The batch's image size: the options', else the cameras' common stored size; checked to make
/// a batch buffer that can be allocated.
fn image_size(
    meta: &Meta,
    opts: &LoaderOptions,
    cameras: &[String],
) -> std::result::Result<(u32, u32), String> {
    let (width, height) = match opts.image_size {
        Some(s) => s,
        None => {
            let sizes: Vec<Option<(u32, u32)>> = cameras
                .iter()
                .map(|c| meta.features[c].image_size())
                .collect();
            match sizes.first() {
                None => (0, 0),
                Some(Some(s)) if sizes.iter().all(|x| *x == Some(*s)) => *s,
                _ => {
                    let shapes: Vec<&Vec<usize>> =
                        cameras.iter().map(|c| &meta.features[c].shape).collect();
                    return Err(format!(
                        "cameras of different or unknown shapes {shapes:?}: choose an image_size"
                    ));
                }
            }
        }
    };
    if !cameras.is_empty() {
        check_batch_size(opts, cameras.len(), width, height)?;
    }
    Ok((width, height))
}

/// The data files must hold what `info.json` announces: its state and action widths, and (when
/// it gives them) its episode and frame totals — a data file missing or cut short otherwise
/// loses episodes without a word.
fn check_data(meta: &Meta, data: &Data, opts: &LoaderOptions, info_file: &str) -> Result<()> {
    for (key, dim) in [
        (&opts.state_key, data.state_dim),
        (&opts.action_key, data.action_dim),
    ] {
        let shape = &meta.features[key].shape;
        let want: usize = shape.iter().product();
        if want != dim {
            return Err(Error::format(
                info_file,
                format!(
                    "{key} has shape {shape:?}, but the data files hold {dim} values per frame"
                ),
            ));
        }
    }
    if let Some((episodes, frames)) = meta.totals {
        let found = data.episodes.len();
        let rows: usize = data.episodes.iter().map(|e| e.len).sum();
        if (found, rows) != (episodes, frames) {
            return Err(Error::format(
                info_file,
                format!(
                    "total_episodes {episodes} and total_frames {frames}, but the data files hold \
                     {found} episodes of {rows} frames: a data file is missing or cut short"
                ),
            ));
        }
    }
    Ok(())
}

/// The decoding pool: `threads` threads, or one per available core for 0.
fn decode_pool(threads: usize) -> Result<rayon::ThreadPool> {
    let threads = if threads == 0 {
        std::thread::available_parallelism().map_or(1, usize::from)
    } else {
        threads
    };
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("scaledp-decode-{i}"))
        .build()
        .map_err(|e| Error::Options(format!("cannot start {threads} decoding threads: {e}")))
}

/// Where a loader stands: the epoch and the samples already yielded in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LoaderState {
    /// The epoch.
    pub epoch: u64,
    /// Samples of this rank already yielded in the epoch.
    pub position: u64,
}

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
}

/// Everything the prefetch thread shares with the loader.
pub(crate) struct Shared {
    pub data: Data,
    pub episodes: Vec<EpisodeRows>,
    pub opts: LoaderOptions,
    pub info: DatasetInfo,
    pub norm: Normalizer,
    pub pool: rayon::ThreadPool,
    samples: Vec<Sample>,
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
    fn new(keep: usize) -> Self {
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

/// What the prefetch thread hands over: a batch (None when every sample of its range was
/// skipped) and how many samples of the order it used.
type Prepared = Result<(Option<Batch>, usize)>;

struct Producer {
    rx: Receiver<Prepared>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Drop for Producer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        // Unblock a send waiting on a full channel, then wait for the thread.
        while self.rx.try_recv().is_ok() {}
        if let Some(h) = self.handle.take() {
            while !h.is_finished() {
                while self.rx.try_recv().is_ok() {}
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            let _ = h.join();
        }
    }
}

/// Streams batches of action-chunk samples; see [`LoaderOptions`].
pub struct Loader {
    shared: Arc<Shared>,
    bytes_read: Arc<AtomicU64>,
    peak_resident: Arc<AtomicUsize>,
    epoch: u64,
    position: u64,
    order: Arc<Vec<Sample>>,
    /// End of the unpadded part of a streaming order.
    main_len: usize,
    producer: Option<Producer>,
}

impl std::fmt::Debug for Loader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Loader")
            .field("location", &self.shared.info.location)
            .field("episodes", &self.shared.info.episodes.len())
            .field("samples", &self.len())
            .field("epoch", &self.epoch)
            .field("position", &self.position)
            .finish_non_exhaustive()
    }
}

impl Loader {
    pub(crate) fn open(location: &str, opts: LoaderOptions) -> Result<Self> {
        check_options(&opts).map_err(|m| Error::Options(format!("{location}: {m}")))?;
        let store = Store::open(location)?;
        let meta = Meta::read(&store)?;
        let info_file = store.describe("meta/info.json");
        let cameras = pick_cameras(&meta, &opts, &info_file)?;
        let (width, height) = image_size(&meta, &opts, &cameras)
            .map_err(|m| Error::Options(format!("{location}: {m}")))?;
        let bytes_read = Arc::new(AtomicU64::new(0));
        let data = Data::open(
            &store,
            &opts.state_key,
            &opts.action_key,
            bytes_read.clone(),
        )?;
        check_data(&meta, &data, &opts, &info_file)?;
        let stats_file = store.describe("meta/stats.json");
        let norm = Normalizer {
            state: Affine::new(
                opts.state_norm,
                &opts.state_key,
                data.state_dim,
                &meta.stats,
                &stats_file,
            )?,
            action: Affine::new(
                opts.action_norm,
                &opts.action_key,
                data.action_dim,
                &meta.stats,
                &stats_file,
            )?,
        };
        let chosen = sampler::split_episodes(
            data.episodes.len(),
            opts.split,
            opts.val_ratio,
            opts.split_seed,
            opts.max_episodes,
        );
        let episodes: Vec<EpisodeRows> = chosen.iter().map(|&i| data.episodes[i].clone()).collect();
        let lens: Vec<usize> = episodes.iter().map(|e| e.len).collect();
        let samples = sampler::samples(&lens, opts.drop_first, opts.drop_last);
        if samples.is_empty() {
            return Err(Error::Options(format!(
                "{location}: no samples: {} of {} episodes chosen ({:?} split, val_ratio {}, max_episodes {:?}), {} frames, drop_first {} / drop_last {}",
                episodes.len(),
                data.episodes.len(),
                opts.split,
                opts.val_ratio,
                opts.max_episodes,
                lens.iter().sum::<usize>(),
                opts.drop_first,
                opts.drop_last
            )));
        }
        let (state_f, action_f) = (
            &meta.features[&opts.state_key],
            &meta.features[&opts.action_key],
        );
        let info = DatasetInfo {
            location: location.to_string(),
            fps: meta.fps,
            cameras,
            width,
            height,
            state_names: state_f.dim_names(),
            action_names: action_f.dim_names(),
            episodes: episodes.iter().map(|e| e.episode_index).collect(),
            episode_lengths: lens.clone(),
            frames: lens.iter().sum(),
            total_episodes: data.episodes.len(),
        };
        let pool = decode_pool(opts.threads)?;
        tracing::debug!(
            "{location}: {} of {} episodes, {} samples, {} cameras {}×{}, {} threads",
            info.episodes.len(),
            info.total_episodes,
            samples.len(),
            info.cameras.len(),
            width,
            height,
            pool.current_num_threads()
        );
        let opts_prefetch = opts.prefetch.max(1);
        let shared = Arc::new(Shared {
            data,
            episodes,
            opts,
            info,
            norm,
            pool,
            samples,
            spare: ImagePool::new(opts_prefetch + 2),
            skipped: AtomicU64::new(0),
        });
        let mut loader = Loader {
            shared,
            bytes_read,
            peak_resident: Arc::new(AtomicUsize::new(0)),
            epoch: 0,
            position: 0,
            order: Arc::new(Vec::new()),
            main_len: 0,
            producer: None,
        };
        loader.set_epoch(0);
        Ok(loader)
    }

    /// Samples this rank yields in the current epoch.
    pub fn len(&self) -> usize {
        let (n, b) = (self.order.len(), self.shared.opts.batch_size);
        if self.shared.opts.drop_incomplete_batch {
            n / b * b
        } else {
            n
        }
    }

    /// Whether the epoch has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Batches in the current epoch.
    pub fn batches_per_epoch(&self) -> usize {
        self.len().div_ceil(self.shared.opts.batch_size)
    }

    /// Starts epoch `epoch`: its own permutation, from the first sample.
    pub fn set_epoch(&mut self, epoch: u64) {
        self.producer = None;
        let o = &self.shared.opts;
        let (order, main_len) = match o.streaming {
            None => {
                let idx = sampler::random_order(
                    self.shared.samples.len(),
                    o.shuffle,
                    o.seed,
                    epoch,
                    o.rank,
                    o.world_size,
                );
                let n = idx.len();
                (idx.into_iter().map(|i| self.shared.samples[i]).collect(), n)
            }
            Some(buffer) => {
                let lens: Vec<usize> = self.shared.episodes.iter().map(|e| e.len).collect();
                let spec = sampler::StreamSpec {
                    drop_first: o.drop_first,
                    drop_last: o.drop_last,
                    buffer_episodes: buffer,
                    shuffle: o.shuffle,
                    seed: o.seed,
                };
                sampler::streaming_order(&lens, &spec, epoch, o.rank, o.world_size)
            }
        };
        self.order = Arc::new(order);
        self.main_len = main_len;
        self.epoch = epoch;
        self.position = 0;
    }

    /// Where the next batch starts.
    pub fn state(&self) -> LoaderState {
        LoaderState {
            epoch: self.epoch,
            position: self.position,
        }
    }

    /// Continues from `state` (as returned by [`Loader::state`] of a loader with the same
    /// options). On an error the loader stays where it was.
    pub fn resume(&mut self, state: LoaderState) -> Result<()> {
        let before = (self.epoch, self.position);
        self.set_epoch(state.epoch);
        if state.position > self.len() as u64 {
            let len = self.len();
            self.set_epoch(before.0);
            self.position = before.1;
            return Err(Error::Options(format!(
                "cannot resume at sample {} of an epoch of {len} samples",
                state.position,
            )));
        }
        self.position = state.position;
        Ok(())
    }

    /// Hands a batch's image buffer back for the batches still to come (see [`ImagePool`]).
    /// Optional: call it once a batch has been copied out (to the GPU, say).
    pub fn recycle(&self, batch: Batch) {
        self.shared.spare.put(batch.images);
    }

    /// The pool [`Loader::recycle`] puts buffers in, for buffers that outlive their batch.
    pub fn image_pool(&self) -> ImagePool {
        self.shared.spare.clone()
    }

    /// The state and action normalization applied to batches.
    pub fn normalizer(&self) -> &Normalizer {
        &self.shared.norm
    }

    /// What the loader reads.
    pub fn info(&self) -> &DatasetInfo {
        &self.shared.info
    }

    /// Bytes read from data files so far (footers, small columns and image pages).
    pub fn bytes_read(&self) -> u64 {
        self.bytes_read.load(Ordering::Relaxed)
    }

    /// Streaming mode: the most frames whose encoded images were held at once so far (the open
    /// episodes of the shuffle buffer); 0 in random-access mode, which holds none between samples.
    pub fn peak_resident_rows(&self) -> usize {
        self.peak_resident.load(Ordering::Relaxed)
    }

    /// The next batch of the epoch; `None` at its end.
    pub fn next_batch(&mut self) -> Option<Result<Batch>> {
        if self.position >= self.len() as u64 {
            return None;
        }
        if self.producer.is_none() {
            self.producer = Some(self.spawn());
        }
        loop {
            let got = self.producer.as_ref().map(|p| p.rx.recv());
            match got {
                Some(Ok(Ok((batch, used)))) => {
                    self.position += used as u64;
                    match batch {
                        Some(batch) => return Some(Ok(batch)),
                        // Every sample of that range was skipped: on to the next.
                        None if self.position < self.len() as u64 => continue,
                        None => return None,
                    }
                }
                Some(Ok(Err(e))) => {
                    self.producer = None;
                    return Some(Err(e));
                }
                _ => {
                    self.producer = None;
                    return Some(Err(Error::Stopped("no batch came".into())));
                }
            }
        }
    }

    /// Samples left out of batches so far because their images could not be read or decoded
    /// (see [`LoaderOptions::skip_bad_samples`]).
    pub fn skipped_samples(&self) -> u64 {
        self.shared.skipped.load(Ordering::Relaxed)
    }

    /// The rest of this epoch's batches.
    pub fn iter(&mut self) -> impl Iterator<Item = Result<Batch>> + '_ {
        std::iter::from_fn(move || self.next_batch())
    }

    fn spawn(&self) -> Producer {
        let (tx, rx) = bounded(self.shared.opts.prefetch.max(1));
        let stop = Arc::new(AtomicBool::new(false));
        let (shared, order, stop2) = (self.shared.clone(), self.order.clone(), stop.clone());
        let peak = self.peak_resident.clone();
        let (start, end, main_len) = (self.position as usize, self.len(), self.main_len);
        let handle = std::thread::Builder::new()
            .name("scaledp-prefetch".into())
            .spawn(move || {
                let mut cache = shared
                    .opts
                    .streaming
                    .map(|_| Cache::new(&order, main_len, peak));
                let b = shared.opts.batch_size;
                let mut p = start;
                while p < end && !stop2.load(Ordering::Relaxed) {
                    let q = (p + b).min(end);
                    let got = batch::assemble(&shared, &order, p..q, cache.as_mut())
                        .map(|b| ((b.len > 0).then_some(b), q - p));
                    let failed = got.is_err();
                    if tx.send(got).is_err() || failed {
                        break;
                    }
                    p = q;
                }
            });
        match handle {
            Ok(h) => Producer {
                rx,
                stop,
                handle: Some(h),
            },
            Err(e) => {
                let (tx, rx) = bounded(1);
                let _ = tx.send(Err(Error::Stopped(format!(
                    "cannot start the prefetch thread: {e}"
                ))));
                Producer {
                    rx,
                    stop,
                    handle: None,
                }
            }
        }
    }
}
