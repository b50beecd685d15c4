//! `scaledp_data.Loader`: options as keyword arguments, iteration over numpy batches, epochs,
//! resumable state.

use std::path::PathBuf;

use pyo3::exceptions::{PyKeyError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use scaledp_datasets::{LoaderOptions, LoaderState};

use crate::convert::{batch_dict, info_dict, norm};
use crate::normalizer::Normalizer;
use crate::to_py;

/// Shuffled action-chunk batches of a LeRobot v3.0 dataset (a directory or `s3://bucket/prefix`).
///
/// Iterating yields the rest of the current epoch as dicts of numpy arrays:
/// `observation.images` uint8 `[B, To, cams, 3, H, W]`, `observation.state` float32
/// `[B, To, S]`, `action` float32 `[B, C, A]`, `obs_is_pad` bool `[B, To]`, `action_is_pad`
/// bool `[B, C]`, `episode_index` and `frame_index` int64 `[B]`; with `depth=True` also
/// `observation.depth` float32 `[B, To, depth cameras, H, W]` in each camera's stored unit
/// (`info["depth_cameras"]`, `info["depth_units"]`: `mm`, 0 where unknown, or `m`, NaN where
/// unknown). When an epoch ends the loader
/// moves on to the next one, so `for batch in loader:` once per epoch gives a new order each
/// time; `set_epoch(e)` picks the epoch explicitly (as with DDP's `DistributedSampler`).
#[pyclass(module = "scaledp_data")]
pub struct Loader {
    inner: scaledp_datasets::Loader,
}

#[pymethods]
impl Loader {
    #[new]
    #[pyo3(signature = (
        location, *, obs_horizon=2, action_chunk=16, action_offset=0, cameras=None,
        image_size=None, drop_first=0, drop_last=0, split="all", val_ratio=0.0, split_seed=0,
        max_episodes=None, state_norm="mean_std", action_norm="min_max", batch_size=64,
        drop_incomplete_batch=false, shuffle=true, seed=0, rank=0, world_size=1, threads=0,
        prefetch=2, streaming=None, skip_bad_samples=0, video_tolerance_s=1e-4, video_decoders=0,
        depth=false,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        location: PathBuf,
        obs_horizon: usize,
        action_chunk: usize,
        action_offset: usize,
        cameras: Option<Vec<String>>,
        image_size: Option<(u32, u32)>,
        drop_first: usize,
        drop_last: usize,
        split: &str,
        val_ratio: f64,
        split_seed: u64,
        max_episodes: Option<usize>,
        state_norm: &str,
        action_norm: &str,
        batch_size: usize,
        drop_incomplete_batch: bool,
        shuffle: bool,
        seed: u64,
        rank: usize,
        world_size: usize,
        threads: usize,
        prefetch: usize,
        streaming: Option<usize>,
        skip_bad_samples: usize,
        video_tolerance_s: f64,
        video_decoders: usize,
        depth: bool,
    ) -> PyResult<Self> {
        let location = location
            .to_str()
            .ok_or_else(|| PyValueError::new_err(format!("{location:?}: not UTF-8")))?
            .to_string();
        let mut o = LoaderOptions::default()
            .obs_horizon(obs_horizon)
            .action_chunk(action_chunk)
            .action_offset(action_offset)
            .drop_first(drop_first)
            .drop_last(drop_last)
            .split(crate::convert::split(split)?)
            .val_ratio(val_ratio)
            .split_seed(split_seed)
            .state_norm(norm("state_norm", state_norm)?)
            .action_norm(norm("action_norm", action_norm)?)
            .batch_size(batch_size)
            .drop_incomplete_batch(drop_incomplete_batch)
            .shuffle(shuffle)
            .seed(seed)
            .rank(rank, world_size)
            .threads(threads)
            .prefetch(prefetch)
            .skip_bad_samples(skip_bad_samples)
            .video_tolerance_s(video_tolerance_s)
            .video_decoders(video_decoders)
            .depth(depth);
        if let Some(c) = cameras {
            o = o.cameras(c);
        }
        if let Some((w, h)) = image_size {
            o = o.image_size(w, h);
        }
        if let Some(n) = max_episodes {
            o = o.max_episodes(n);
        }
        if let Some(n) = streaming {
            o = o.streaming(n);
        }
        let inner = py.detach(|| o.open(&location)).map_err(to_py)?;
        Ok(Loader { inner })
    }

    /// Batches per epoch (of this rank).
    fn __len__(&self) -> usize {
        self.inner.batches_per_epoch()
    }

    /// Samples per epoch (of this rank).
    #[getter]
    fn num_samples(&self) -> usize {
        self.inner.len()
    }

    /// The current epoch.
    #[getter]
    fn epoch(&self) -> u64 {
        self.inner.state().epoch
    }

    /// Starts epoch `epoch` from its first sample (its own seeded order).
    fn set_epoch(&mut self, py: Python<'_>, epoch: u64) {
        // Stopping the batch in preparation can take a while (a slow S3 read): without the GIL.
        let inner = &mut self.inner;
        py.detach(|| inner.set_epoch(epoch));
    }

    /// Where the next batch starts: `{"epoch": e, "position": samples already yielded}`.
    fn state_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.inner.state();
        let d = PyDict::new(py);
        d.set_item("epoch", s.epoch)?;
        d.set_item("position", s.position)?;
        Ok(d)
    }

    /// Continues from a `state_dict()` of a loader with the same options.
    fn load_state_dict(&mut self, py: Python<'_>, state: &Bound<'_, PyDict>) -> PyResult<()> {
        let get = |k: &str| -> PyResult<u64> {
            state
                .get_item(k)?
                .ok_or_else(|| PyKeyError::new_err(format!("state_dict has no {k:?}")))?
                .extract()
        };
        let s = LoaderState {
            epoch: get("epoch")?,
            position: get("position")?,
        };
        let inner = &mut self.inner;
        py.detach(|| inner.resume(s)).map_err(to_py)
    }

    /// The state / action normalization applied to batches.
    #[getter]
    fn normalizer(&self) -> Normalizer {
        Normalizer {
            inner: self.inner.normalizer().clone(),
        }
    }

    /// What the loader reads: fps, cameras, image_size (w, h), state/action names, episodes
    /// (their `episode_index`), frames, total_episodes, location, depth_cameras and
    /// depth_units, and `intrinsics` (per camera name, `scaledp.cameras` of `info.json`: K, D,
    /// P for the stored images, and the depth's unit and intrinsics).
    #[getter]
    fn info<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        info_dict(py, self.inner.info())
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&mut self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let inner = &mut self.inner;
        match py.detach(|| inner.next_with_depth()) {
            Some(Ok((b, depth))) => Ok(Some(batch_dict(py, b, depth, self.inner.image_pool())?)),
            Some(Err(e)) => Err(to_py(e)),
            None => {
                let next = self.inner.state().epoch.wrapping_add(1);
                self.inner.set_epoch(next);
                Ok(None)
            }
        }
    }

    fn __repr__(&self) -> String {
        let i = self.inner.info();
        let s = self.inner.state();
        format!(
            "Loader({:?}: {} episodes, {} samples in {} batches per epoch, cameras {:?}, epoch {}, position {})",
            i.location,
            i.episodes.len(),
            self.inner.len(),
            self.inner.batches_per_epoch(),
            i.cameras,
            s.epoch,
            s.position
        )
    }
}
