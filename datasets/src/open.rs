//! Opening a dataset for the loader: the options checked on their own and against the
//! dataset (features, shapes, totals, a batch buffer that can be allocated), the split's
//! episodes and samples, the normalizer, and one frame source per kind of camera feature —
//! images in the data files, video files — with the batch slots each fills.

use std::sync::atomic::AtomicU64;
use std::sync::Arc;

use crate::depth::DepthSource;
use crate::episodes::{read_segments, DEFAULT_VIDEO_PATH};
use crate::error::{Error, Result};
use crate::frames::{ImageSource, Sourced};
use crate::meta::Meta;
use crate::normalize::{Affine, Normalizer};
use crate::options::LoaderOptions;
use crate::reader::{Data, EpisodeRows};
use crate::sampler;
use crate::shared::{DatasetInfo, ImagePool, Shared};
use crate::store::Store;
use crate::video::VideoSource;

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
    if !(opts.video_tolerance_s.is_finite() && opts.video_tolerance_s >= 0.0) {
        return Err(format!(
            "video_tolerance_s {} is not a time of 0 s or more",
            opts.video_tolerance_s
        ));
    }
    if !(0.0..=1.0).contains(&opts.val_ratio) {
        return Err(format!("val_ratio {} outside [0, 1]", opts.val_ratio));
    }
    Ok(())
}

/// The camera features (image or video) to load (keys), in order: all of them, or those the
/// options name (by short name or key).
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

/// Opens `location` with `opts`: everything the loader shares with its prefetch thread, and
/// the counter of bytes read.
pub(crate) fn open(location: &str, opts: LoaderOptions) -> Result<(Shared, Arc<AtomicU64>)> {
    check_options(&opts).map_err(|m| Error::Options(format!("{location}: {m}")))?;
    let store = Store::open(location)?;
    let meta = Meta::read(&store)?;
    let info_file = store.describe("meta/info.json");
    let cameras = pick_cameras(&meta, &opts, &info_file)?;
    let (width, height) = image_size(&meta, &opts, &cameras)
        .map_err(|m| Error::Options(format!("{location}: {m}")))?;
    let bytes_read = Arc::new(AtomicU64::new(0));
    let data = Arc::new(Data::open(
        &store,
        &opts.state_key,
        &opts.action_key,
        bytes_read.clone(),
    )?);
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
    let crate::depth::Picked {
        keys: depth_cameras,
        units: depth_units,
        size: depth_size,
    } = match opts.depth {
        true => crate::depth::pick(&meta, &cameras, &info_file)?,
        false => crate::depth::Picked {
            keys: Vec::new(),
            units: Vec::new(),
            size: (0, 0),
        },
    };
    let depth_out = if cameras.is_empty() {
        depth_size
    } else {
        (width, height)
    };
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
        depth_cameras: depth_cameras.clone(),
        depth_units,
        sensors: meta.cameras.clone(),
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
    let sources = sources(
        &store,
        &meta,
        &opts,
        &data,
        &info.cameras,
        &bytes_read,
        &pool,
    )?;
    let depth = opts.depth.then(|| DepthSource {
        data: data.clone(),
        keys: depth_cameras,
        stored: depth_size,
        out: depth_out,
    });
    let opts_prefetch = opts.prefetch.max(1);
    let shared = Shared {
        data,
        sources,
        depth,
        episodes,
        opts,
        info,
        norm,
        pool,
        samples,
        spare: ImagePool::new(opts_prefetch + 2),
        skipped: AtomicU64::new(0),
    };
    Ok((shared, bytes_read))
}

/// The frame sources of `cameras`: one for the image features, one for the video features
/// (each only when some camera is of its kind).
fn sources(
    store: &Store,
    meta: &Meta,
    opts: &LoaderOptions,
    data: &Arc<Data>,
    cameras: &[String],
    bytes_read: &Arc<AtomicU64>,
    pool: &rayon::ThreadPool,
) -> Result<Vec<Sourced>> {
    let (mut images, mut videos) = (Vec::new(), Vec::new());
    for (slot, key) in cameras.iter().enumerate() {
        if meta.features[key].dtype == "video" {
            videos.push((slot, key.clone()));
        } else {
            images.push((slot, key.clone()));
        }
    }
    let mut out = Vec::new();
    if !images.is_empty() {
        out.push(Sourced {
            source: Box::new(ImageSource {
                data: data.clone(),
                cameras: images.iter().map(|c| c.1.clone()).collect(),
            }),
            slots: images.iter().map(|c| c.0).collect(),
        });
    }
    if !videos.is_empty() {
        let keys: Vec<String> = videos.iter().map(|c| c.1.clone()).collect();
        let template = meta.video_path.as_deref().unwrap_or(DEFAULT_VIDEO_PATH);
        let segments = read_segments(store, &keys, template)?;
        let decoders = match opts.video_decoders {
            0 => (2 * pool.current_num_threads() * keys.len()).clamp(4, 256),
            n => n,
        };
        out.push(Sourced {
            source: Box::new(VideoSource::new(
                store.clone(),
                bytes_read.clone(),
                data.clone(),
                keys,
                segments,
                opts.video_tolerance_s,
                decoders,
            )),
            slots: videos.iter().map(|c| c.0).collect(),
        });
    }
    Ok(out)
}
