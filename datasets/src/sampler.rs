//! Which samples an epoch yields and in what order: the train/val split by episode, the
//! (episode, current frame) samples, diffusion_policy's windows with edge padding, the seeded
//! per-epoch permutation, DDP sharding, and the streaming order (a shuffle buffer over episodes).
//!
//! Everything here is a pure function of the options, the episode lengths, the seed and the
//! epoch: the thread count never changes an order.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Which part of the episodes to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Split {
    /// The training episodes (all but the validation ones).
    Train,
    /// The validation episodes.
    Val,
    /// Every episode.
    #[default]
    All,
}

/// One sample: an episode (position in the loader's episode list) and its current frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Sample {
    /// Position of the episode in the loader's episode list.
    pub episode: u32,
    /// The current frame t.
    pub t: u32,
}

/// An RNG for (seed, stream): ChaCha8 is the same on every platform.
fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// Positions of the episodes in `split`: a permutation seeded by `seed` puts the first
/// `round(n · val_ratio)` episodes in validation; `max_episodes` keeps the first ones of the
/// split in that permutation, so smaller caps are subsets of larger ones. Sorted.
pub fn split_episodes(
    n: usize,
    split: Split,
    val_ratio: f64,
    seed: u64,
    max_episodes: Option<usize>,
) -> Vec<usize> {
    let mut perm: Vec<usize> = (0..n).collect();
    perm.shuffle(&mut rng(seed, 0));
    let n_val = ((n as f64) * val_ratio.clamp(0.0, 1.0)).round() as usize;
    let mut chosen: Vec<usize> = match split {
        Split::All => (0..n).collect(),
        Split::Val => perm[..n_val].to_vec(),
        Split::Train => perm[n_val..].to_vec(),
    };
    if let Some(cap) = max_episodes {
        if split == Split::All {
            chosen = perm.clone();
        }
        chosen.truncate(cap);
    }
    chosen.sort_unstable();
    chosen
}

/// Every sample of episodes with `lens`: current frames `drop_first .. len − drop_last`.
pub fn samples(lens: &[usize], drop_first: usize, drop_last: usize) -> Vec<Sample> {
    let mut out = Vec::new();
    for (e, &len) in lens.iter().enumerate() {
        for t in drop_first..len.saturating_sub(drop_last) {
            out.push(Sample {
                episode: e as u32,
                t: t as u32,
            });
        }
    }
    out
}

/// The frames a sample reads and where they are padding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Window {
    /// Observation frames t−To+1 ..= t, clamped into the episode.
    pub obs: Vec<usize>,
    /// Whether each observation frame lies before the episode.
    pub obs_is_pad: Vec<bool>,
    /// Action frames t+offset .. t+offset+C, clamped into the episode.
    pub action: Vec<usize>,
    /// Whether each action frame lies after the episode.
    pub action_is_pad: Vec<bool>,
}

/// diffusion_policy's window for current frame `t` of an episode of `len` frames: out-of-episode
/// steps repeat the first or last frame.
pub fn window(
    len: usize,
    t: usize,
    obs_horizon: usize,
    action_chunk: usize,
    offset: usize,
) -> Window {
    let last = len.saturating_sub(1) as i64;
    let clamp = |i: i64| i.clamp(0, last) as usize;
    let first_obs = t as i64 - obs_horizon as i64 + 1;
    let obs_idx: Vec<i64> = (0..obs_horizon as i64).map(|k| first_obs + k).collect();
    let act_idx: Vec<i64> = (0..action_chunk as i64)
        .map(|k| (t + offset) as i64 + k)
        .collect();
    Window {
        obs: obs_idx.iter().map(|&i| clamp(i)).collect(),
        obs_is_pad: obs_idx.iter().map(|&i| i < 0 || i > last).collect(),
        action: act_idx.iter().map(|&i| clamp(i)).collect(),
        action_is_pad: act_idx.iter().map(|&i| i < 0 || i > last).collect(),
    }
}

/// This rank's positions in the epoch's order of `n` samples: a seeded permutation per epoch
/// (or 0..n), padded to a multiple of `world_size` by repeating its head, then every
/// `world_size`-th starting at `rank` (torch's DistributedSampler rule).
pub fn random_order(
    n: usize,
    shuffle: bool,
    seed: u64,
    epoch: u64,
    rank: usize,
    world: usize,
) -> Vec<usize> {
    let mut order: Vec<usize> = (0..n).collect();
    if shuffle {
        order.shuffle(&mut rng(seed, epoch.wrapping_add(1)));
    }
    shard(order, rank, world)
}

fn shard<T: Clone>(mut order: Vec<T>, rank: usize, world: usize) -> Vec<T> {
    let world = world.max(1);
    let n = order.len();
    if n == 0 {
        return order;
    }
    let total = n.div_ceil(world) * world;
    for i in n..total {
        let v = order[i % n].clone();
        order.push(v);
    }
    order.into_iter().skip(rank).step_by(world).collect()
}

/// What a streaming order depends on besides the episodes, epoch and rank.
#[derive(Clone, Copy, Debug)]
pub struct StreamSpec {
    /// Frames skipped at each episode's start.
    pub drop_first: usize,
    /// Frames skipped at each episode's end.
    pub drop_last: usize,
    /// Episodes open at once.
    pub buffer_episodes: usize,
    /// Draw at random (else in order).
    pub shuffle: bool,
    /// Seed.
    pub seed: u64,
}

/// The streaming order of this rank, and the length of its unpadded part: episodes in a seeded order dealt round-robin to ranks; a
/// buffer of `buffer_episodes` episodes is open at a time and each next sample is drawn at random
/// among the open episodes' remaining ones; an episode is replaced by the next when it runs out.
/// Ranks with fewer samples repeat their head so that every rank yields the same count.
pub fn streaming_order(
    lens: &[usize],
    spec: &StreamSpec,
    epoch: u64,
    rank: usize,
    world: usize,
) -> (Vec<Sample>, usize) {
    let StreamSpec {
        drop_first,
        drop_last,
        buffer_episodes,
        shuffle,
        seed,
    } = *spec;
    let world = world.max(1);
    let mut eps: Vec<usize> = (0..lens.len()).collect();
    let mut r = rng(seed, epoch.wrapping_add(1));
    if shuffle {
        eps.shuffle(&mut r);
    }
    let count = |e: &usize| lens[*e].saturating_sub(drop_first.saturating_add(drop_last));
    // Only episodes with samples are dealt, so that empty ones do not leave a rank short.
    eps.retain(|e| count(e) > 0);
    let per_rank: Vec<usize> = (0..world)
        .map(|k| eps.iter().skip(k).step_by(world).map(count).sum())
        .collect();
    let target = per_rank.iter().copied().max().unwrap_or(0);
    let mut mine: Vec<usize> = eps.iter().copied().skip(rank).step_by(world).collect();
    if mine.is_empty() && target > 0 {
        // Fewer episodes than ranks: this rank repeats one of the others' (every rank must
        // yield the same count, or a DDP collective waits forever).
        mine.push(eps[rank % eps.len()]);
    }
    let mut r = rng(
        seed ^ 0x5eed_5eed,
        epoch
            .wrapping_add(1)
            .wrapping_mul(world as u64)
            .wrapping_add(rank as u64),
    );
    let mut out = Vec::with_capacity(target);
    let mut open: Vec<(usize, Vec<u32>)> = Vec::new();
    let mut next = mine.iter();
    loop {
        while open.len() < buffer_episodes.max(1) {
            match next.next() {
                Some(&e) => {
                    let frames: Vec<u32> = (drop_first..lens[e].saturating_sub(drop_last))
                        .map(|t| t as u32)
                        .rev()
                        .collect();
                    if !frames.is_empty() {
                        open.push((e, frames));
                    }
                }
                None => break,
            }
        }
        if open.is_empty() {
            break;
        }
        // Draw uniformly among the open samples: pick an episode weighted by what it has left,
        // then one of its frames at random.
        let total: usize = open.iter().map(|(_, f)| f.len()).sum();
        let mut k = if shuffle { r.random_range(0..total) } else { 0 };
        let mut slot = 0;
        while k >= open[slot].1.len() {
            k -= open[slot].1.len();
            slot += 1;
        }
        let frames = &mut open[slot].1;
        let t = if shuffle {
            frames.swap_remove(k)
        } else {
            frames.pop().unwrap_or_default()
        };
        out.push(Sample {
            episode: open[slot].0 as u32,
            t,
        });
        if open[slot].1.is_empty() {
            open.remove(slot);
        }
    }
    let n = out.len();
    for i in n..target {
        if n == 0 {
            break;
        }
        out.push(out[i % n]);
    }
    (out, n)
}
