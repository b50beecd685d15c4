//! Building one batch: the samples' windows, state and action rows (normalized), padding
//! masks, and images decoded in parallel straight into the batch's contiguous buffer (in
//! streaming mode from the [`Cache`] of open episodes).

use std::ops::Range;
use std::sync::atomic::Ordering;
use std::sync::Arc;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::frames::Fetched;
use crate::sampler::{window, Sample};
use crate::shared::Shared;
use crate::stream::{Cache, Open};

/// One batch, contiguous and row-major.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// Samples in the batch, B (the last batch of an epoch may be shorter).
    pub len: usize,
    /// Observation frames per sample, To.
    pub obs_horizon: usize,
    /// Actions per sample, C.
    pub action_chunk: usize,
    /// Camera keys, in image order.
    pub cameras: Vec<String>,
    /// Image height.
    pub height: u32,
    /// Image width.
    pub width: u32,
    /// State width, S.
    pub state_dim: usize,
    /// Action width, A.
    pub action_dim: usize,
    /// `[B, To, cams, 3, H, W]`, RGB, channel-first.
    pub images: Vec<u8>,
    /// `[B, To, S]`, normalized.
    pub state: Vec<f32>,
    /// `[B, C, A]`, normalized.
    pub action: Vec<f32>,
    /// `[B, To]`: observation frames before the episode (copies of frame 0).
    pub obs_is_pad: Vec<bool>,
    /// `[B, C]`: action frames after the episode (copies of its last frame).
    pub action_is_pad: Vec<bool>,
    /// `[B]`: each sample's `episode_index`.
    pub episode_index: Vec<i64>,
    /// `[B]`: each sample's current frame t.
    pub frame_index: Vec<i64>,
}

/// The depth of a batch's samples ([`crate::LoaderOptions::depth`],
/// [`crate::Loader::next_with_depth`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DepthBatch {
    /// Depth feature keys in `values` order (`observation.depth.<camera>`).
    pub cameras: Vec<String>,
    /// Their units, `mm` or `m`.
    pub units: Vec<String>,
    /// Frame height (the batch's image height when it has images).
    pub height: u32,
    /// Frame width.
    pub width: u32,
    /// `[B, To, cameras, H, W]`, `f32` in each camera's stored unit: millimetres (0 where
    /// unknown) or metres (NaN or ±inf where unknown).
    pub values: Vec<f32>,
}

/// Builds the batch of `order[range]`. A sample whose images cannot be read or decoded fails
/// the batch, or with [`crate::LoaderOptions::skip_bad_samples`] is left out of it (counted,
/// logged) while the loader's budget lasts: the batch is then shorter than the range.
pub(crate) fn assemble(
    shared: &Shared,
    order: &[Sample],
    range: Range<usize>,
    cache: Option<&mut Cache>,
) -> Result<(Batch, Option<DepthBatch>)> {
    let o = &shared.opts;
    let info = &shared.info;
    let samples = &order[range.clone()];
    let (to, c, cams) = (o.obs_horizon, o.action_chunk, info.cameras.len());
    let (s_dim, a_dim) = (shared.data.state_dim, shared.data.action_dim);
    let plane = 3 * info.width as usize * info.height as usize;
    let per_sample = to * cams * plane;
    let b = samples.len();
    let (depth_width, depth_height) = shared.depth.as_ref().map_or((0, 0), |d| d.out);
    let depth_plane = depth_width as usize * depth_height as usize;
    let depth_per_sample = to * info.depth_cameras.len() * depth_plane;
    let mut batch = Batch {
        len: b,
        obs_horizon: to,
        action_chunk: c,
        cameras: info.cameras.clone(),
        height: info.height,
        width: info.width,
        state_dim: s_dim,
        action_dim: a_dim,
        images: shared.spare.take(b * per_sample),
        state: vec![0.0; b * to * s_dim],
        action: vec![0.0; b * c * a_dim],
        obs_is_pad: vec![false; b * to],
        action_is_pad: vec![false; b * c],
        episode_index: samples
            .iter()
            .map(|s| shared.episodes[s.episode as usize].episode_index)
            .collect(),
        frame_index: samples.iter().map(|s| i64::from(s.t)).collect(),
    };
    let mut depth = shared.depth.as_ref().map(|_| DepthBatch {
        cameras: info.depth_cameras.clone(),
        units: info.depth_units.clone(),
        height: depth_height,
        width: depth_width,
        values: vec![0.0; b * depth_per_sample],
    });
    // Streaming: read the episodes this batch needs that are not open yet.
    let mut cache = cache;
    let unread = match cache.as_deref_mut() {
        Some(cache) => cache.load(shared, samples)?,
        None => Vec::new(),
    };
    let mut unread_eps = std::collections::HashSet::new();
    let mut budget = Budget(shared);
    for (episode, e) in unread {
        budget.spend(e)?;
        unread_eps.insert(episode);
    }
    let open = cache.as_deref().map(Cache::open);
    // One slice per sample of each buffer, empty ones too (no cameras, a 0-wide state): a
    // zip of `par_chunks_mut` would stop at the shortest and leave the batch unfilled.
    let images = rows(&mut batch.images, per_sample, b);
    let state = rows(&mut batch.state, to * s_dim, b);
    let action = rows(&mut batch.action, c * a_dim, b);
    let obs_pad = rows(&mut batch.obs_is_pad, to, b);
    let act_pad = rows(&mut batch.action_is_pad, c, b);
    let mut no_depth = Vec::new();
    let depth_values = depth.as_mut().map_or(&mut no_depth, |d| &mut d.values);
    let depth_rows = rows(depth_values, depth_per_sample, b);
    let filled: Vec<Result<bool>> = shared.pool.install(|| {
        images
            .into_par_iter()
            .zip(state)
            .zip(action)
            .zip(obs_pad)
            .zip(act_pad)
            .zip(depth_rows)
            .zip(samples.par_iter())
            .map(|((((((img, st), ac), op), ap), dp), s)| {
                if unread_eps.contains(&s.episode) {
                    return Ok(false);
                }
                let out = Row {
                    img,
                    st,
                    ac,
                    op,
                    ap,
                    dp,
                };
                fill(shared, s, open, out, plane).map(|()| true)
            })
            .collect()
    });
    if let Some(cache) = cache {
        cache.release(shared, range, samples);
    }
    let mut keep = Vec::with_capacity(b);
    for r in filled {
        match r {
            Ok(k) => keep.push(k),
            Err(e) => {
                budget.spend(e)?;
                keep.push(false);
            }
        }
    }
    if keep.iter().any(|k| !k) {
        batch.retain(&keep, per_sample);
        if let Some(d) = depth.as_mut() {
            compact(&mut d.values, depth_per_sample, &keep);
        }
    }
    Ok((batch, depth))
}

/// The loader's budget of bad samples (see [`crate::LoaderOptions::skip_bad_samples`]).
struct Budget<'a>(&'a Shared);

impl Budget<'_> {
    /// Counts one bad sample, or one episode that could not be read (its samples in the batch
    /// are left out together); the error itself once the budget is spent.
    fn spend(&mut self, e: Error) -> Result<()> {
        let budget = self.0.opts.skip_bad_samples as u64;
        if budget == 0 {
            return Err(e);
        }
        let skipped = self.0.skipped.fetch_add(1, Ordering::Relaxed) + 1;
        if skipped > budget {
            tracing::error!("{budget} bad samples skipped already: giving up");
            return Err(e);
        }
        tracing::warn!("bad sample skipped ({skipped} of at most {budget}): {e}");
        Ok(())
    }
}

impl Batch {
    /// Keeps the samples whose `keep` is true (in order); `per_sample` image bytes each.
    fn retain(&mut self, keep: &[bool], per_sample: usize) {
        let (to, c) = (self.obs_horizon, self.action_chunk);
        compact(&mut self.images, per_sample, keep);
        compact(&mut self.state, to * self.state_dim, keep);
        compact(&mut self.action, c * self.action_dim, keep);
        compact(&mut self.obs_is_pad, to, keep);
        compact(&mut self.action_is_pad, c, keep);
        compact(&mut self.episode_index, 1, keep);
        compact(&mut self.frame_index, 1, keep);
        self.len = keep.iter().filter(|&&k| k).count();
    }
}

/// Keeps the `stride`-long rows of `v` whose `keep` is true, in order.
fn compact<T: Copy>(v: &mut Vec<T>, stride: usize, keep: &[bool]) {
    let mut to = 0;
    for (i, &k) in keep.iter().enumerate() {
        if k {
            if to != i {
                v.copy_within(i * stride..(i + 1) * stride, to * stride);
            }
            to += 1;
        }
    }
    v.truncate(to * stride);
}

/// `buf` as `n` consecutive slices of `stride` elements (all empty when `stride` is 0).
fn rows<T>(buf: &mut [T], stride: usize, n: usize) -> Vec<&mut [T]> {
    if stride == 0 {
        return (0..n).map(|_| <&mut [T]>::default()).collect();
    }
    buf.chunks_mut(stride).collect()
}

/// One sample's slices of the batch's buffers.
struct Row<'a> {
    img: &'a mut [u8],
    st: &'a mut [f32],
    ac: &'a mut [f32],
    op: &'a mut [bool],
    ap: &'a mut [bool],
    dp: &'a mut [f32],
}

fn fill(
    shared: &Shared,
    s: &Sample,
    open: Option<&Open>,
    out: Row<'_>,
    plane: usize,
) -> Result<()> {
    let Row {
        img,
        st,
        ac,
        op,
        ap,
        dp,
    } = out;
    let o = &shared.opts;
    let ep = &shared.episodes[s.episode as usize];
    let w = window(
        ep.len,
        s.t as usize,
        o.obs_horizon,
        o.action_chunk,
        o.action_offset,
    );
    let (sd, ad) = (shared.data.state_dim, shared.data.action_dim);
    for (k, &f) in w.obs.iter().enumerate() {
        let row = ep.offset + f;
        st[k * sd..(k + 1) * sd].copy_from_slice(&shared.data.state[row * sd..(row + 1) * sd]);
    }
    for (k, &f) in w.action.iter().enumerate() {
        let row = ep.offset + f;
        ac[k * ad..(k + 1) * ad].copy_from_slice(&shared.data.action[row * ad..(row + 1) * ad]);
    }
    shared.norm.normalize_state(st);
    shared.norm.normalize_action(ac);
    op.copy_from_slice(&w.obs_is_pad);
    ap.copy_from_slice(&w.action_is_pad);
    // Obs frames are ascending: one read covers them all.
    let (lo, hi) = (w.obs[0], w.obs[w.obs.len() - 1]);
    if let Some(depth) = &shared.depth {
        let got = depth.read(ep, lo..hi + 1)?;
        let n = got.len();
        let per = dp.len() / (w.obs.len() * n).max(1);
        for (k, &f) in w.obs.iter().enumerate() {
            for (d, frames) in got.iter().enumerate() {
                dp[(k * n + d) * per..][..per].copy_from_slice(&frames[f - lo]);
            }
        }
    }
    let cams = &shared.info.cameras;
    if cams.is_empty() {
        return Ok(());
    }
    let fetched: Arc<Vec<Arc<dyn Fetched>>> = match open {
        Some(open) => open
            .get(&s.episode)
            .cloned()
            .ok_or_else(|| Error::Stopped(format!("episode {} was not read", ep.episode_index)))?,
        None => Arc::new(
            shared
                .sources
                .iter()
                .map(|src| src.source.fetch(ep, lo..hi + 1))
                .collect::<Result<_>>()?,
        ),
    };
    let (width, height) = (shared.info.width, shared.info.height);
    // Camera by camera, frames in order: a video decoder goes on from one frame to the next.
    for (src, got) in shared.sources.iter().zip(fetched.iter()) {
        for (local, &ci) in src.slots.iter().enumerate() {
            for (k, &f) in w.obs.iter().enumerate() {
                let slot = (k * cams.len() + ci) * plane;
                if k > 0 && w.obs[k - 1] == f {
                    let prev = ((k - 1) * cams.len() + ci) * plane;
                    img.copy_within(prev..prev + plane, slot);
                    continue;
                }
                got.decode(local, f, width, height, &mut img[slot..slot + plane])?;
            }
        }
    }
    Ok(())
}
