//! [`Loader`]: the sampling — this epoch's order (shuffled, sharded by rank, or the streaming
//! order), where the epoch stands and how to resume it, and batches prepared `prefetch` ahead
//! by a background thread (built by [`crate::batch`] on the decoding pool).

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

use crossbeam_channel::{bounded, Receiver};

use crate::batch::{self, Batch, DepthBatch};
use crate::error::{Error, Result};
use crate::normalize::Normalizer;
use crate::sampler::{self, Sample};
use crate::shared::{DatasetInfo, ImagePool, Shared};
use crate::stream::Cache;

/// Where a loader stands: the epoch and the samples already yielded in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LoaderState {
    /// The epoch.
    pub epoch: u64,
    /// Samples of this rank already yielded in the epoch.
    pub position: u64,
}

/// What the prefetch thread hands over: a batch (None when every sample of its range was
/// skipped) and how many samples of the order it used.
type Prepared = Result<(Option<(Batch, Option<DepthBatch>)>, usize)>;

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

/// Streams batches of action-chunk samples; see [`crate::LoaderOptions`].
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
    /// A loader over what [`crate::open::open`] opened, at the start of epoch 0.
    pub(crate) fn new(shared: Shared, bytes_read: Arc<AtomicU64>) -> Self {
        let mut loader = Loader {
            shared: Arc::new(shared),
            bytes_read,
            peak_resident: Arc::new(AtomicUsize::new(0)),
            epoch: 0,
            position: 0,
            order: Arc::new(Vec::new()),
            main_len: 0,
            producer: None,
        };
        loader.set_epoch(0);
        loader
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
        self.next_with_depth().map(|r| r.map(|(b, _)| b))
    }

    /// The next batch of the epoch and, with [`crate::LoaderOptions::depth`], its samples'
    /// depth; `None` at the epoch's end.
    pub fn next_with_depth(&mut self) -> Option<Result<(Batch, Option<DepthBatch>)>> {
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
    /// (see [`crate::LoaderOptions::skip_bad_samples`]).
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
                        .map(|b| ((b.0.len > 0).then_some(b), q - p));
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
