//! Streaming mode's frame memory: the encoded images or compressed video of the episodes open
//! in the shuffle buffer
//! (see [`crate::sampler::streaming_order`]). An episode's frames are read whole, in
//! parallel with the other episodes a batch opens, when its first sample comes, and dropped
//! after its last one, so what is resident is bounded by the buffer (plus the episodes a single
//! batch opens), never by the dataset. The most rows resident at once is counted for tests and
//! benchmarks ([`crate::Loader::peak_resident_rows`]).

use std::collections::{HashMap, HashSet};
use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::frames::Fetched;
use crate::sampler::Sample;
use crate::shared::Shared;

/// What each frame source read of one open episode (its whole length).
pub(crate) type Open = HashMap<u32, Arc<Vec<Arc<dyn Fetched>>>>;

/// What the sources read of one episode, or why they could not.
type Read = Result<Vec<Arc<dyn Fetched>>>;

/// Encoded images of the open episodes.
pub(crate) struct Cache {
    open: Open,
    /// Whether position i of the order is its episode's last use (before the episode would be
    /// read again in the padded tail of a rank's order).
    last_use: Vec<bool>,
    /// Rows (frames) of the open episodes.
    resident: usize,
    /// Most rows resident at once, shared with the loader.
    peak: Arc<AtomicUsize>,
}

impl Cache {
    /// A cache for `order`, whose first `main_len` samples cover each episode once and whose
    /// rest repeats some (the padding that equalizes ranks).
    pub fn new(order: &[Sample], main_len: usize, peak: Arc<AtomicUsize>) -> Self {
        let mut last_use = vec![false; order.len()];
        // The padded tail repeats the main part from its start, possibly more than once: each
        // repetition is a segment of its own, so an episode is released at its last use in
        // each, and what is open stays bounded by the buffer.
        let cut = main_len.min(order.len()).max(1);
        let segments = (0..order.len())
            .step_by(cut)
            .map(|a| a..(a + cut).min(order.len()));
        for seg in segments {
            let mut seen = HashSet::new();
            for i in seg.rev() {
                last_use[i] = seen.insert(order[i].episode);
            }
        }
        Cache {
            open: HashMap::new(),
            last_use,
            resident: 0,
            peak,
        }
    }

    /// Reads (in parallel on the pool) the episodes of `samples` that are not open yet;
    /// returns those that could not be read, with why (the first error instead, unless bad
    /// samples may be skipped).
    pub fn load(&mut self, shared: &Shared, samples: &[Sample]) -> Result<Vec<(u32, Error)>> {
        if shared.info.cameras.is_empty() {
            return Ok(Vec::new());
        }
        let mut missing: Vec<u32> = samples
            .iter()
            .map(|s| s.episode)
            .filter(|e| !self.open.contains_key(e))
            .collect();
        missing.sort_unstable();
        missing.dedup();
        let loaded: Vec<(u32, Read)> = shared.pool.install(|| {
            missing
                .par_iter()
                .map(|&e| {
                    let ep = &shared.episodes[e as usize];
                    let got = shared
                        .sources
                        .iter()
                        .map(|src| src.source.fetch(ep, 0..ep.len))
                        .collect();
                    (e, got)
                })
                .collect()
        });
        let mut unread = Vec::new();
        for (e, cols) in loaded {
            match cols {
                Ok(cols) => {
                    self.open.insert(e, Arc::new(cols));
                    self.resident += shared.episodes[e as usize].len;
                }
                Err(err) if shared.opts.skip_bad_samples == 0 => return Err(err),
                Err(err) => unread.push((e, err)),
            }
        }
        self.peak.fetch_max(self.resident, Ordering::Relaxed);
        Ok(unread)
    }

    /// The open episodes' images.
    pub fn open(&self) -> &Open {
        &self.open
    }

    /// Drops the episodes whose last sample is in `order[range]`.
    pub fn release(&mut self, shared: &Shared, range: Range<usize>, samples: &[Sample]) {
        for (i, s) in range.zip(samples) {
            if self.last_use[i] && self.open.remove(&s.episode).is_some() {
                self.resident -= shared.episodes[s.episode as usize].len;
            }
        }
    }
}
