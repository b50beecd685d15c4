//! Orders: the same samples in the same order (and the same bytes) for 1 and 4 threads; DDP ranks
//! disjoint, covering and of equal counts; resuming mid-epoch reproduces the rest of the epoch;
//! epochs and seeds change the permutation; splits are disjoint by episode and caps nest.
#![allow(clippy::unwrap_used)]

use crate::common;

use std::collections::{BTreeMap, BTreeSet};

use common::Fixture;
use scaledp_datasets::{Batch, LoaderOptions, LoaderState, Split};

fn fixture() -> common::Written {
    common::write(&Fixture {
        lens: vec![5, 1, 3, 12, 2, 7, 9, 4, 6],
        episodes_per_file: 4,
        ..Fixture::default()
    })
}

fn opts() -> LoaderOptions {
    LoaderOptions::default()
        .obs_horizon(2)
        .action_chunk(4)
        .batch_size(5)
        .seed(11)
}

fn all_batches(o: LoaderOptions, location: &str, epoch: u64) -> Vec<Batch> {
    let mut l = o.open(location).unwrap();
    l.set_epoch(epoch);
    l.iter().map(Result::unwrap).collect()
}

fn keys(batches: &[Batch]) -> Vec<(i64, i64)> {
    batches
        .iter()
        .flat_map(|b| {
            b.episode_index
                .iter()
                .copied()
                .zip(b.frame_index.iter().copied())
        })
        .collect()
}

#[test]
fn one_and_four_threads_give_identical_batches() {
    let ds = fixture();
    for streaming in [None, Some(2)] {
        for epoch in [0, 3] {
            let with = |threads: usize, prefetch: usize| {
                let o = opts().threads(threads).prefetch(prefetch);
                let o = match streaming {
                    Some(n) => o.streaming(n),
                    None => o,
                };
                all_batches(o, &ds.location(), epoch)
            };
            let one = with(1, 1);
            let four = with(4, 3);
            assert!(!one.is_empty());
            assert_eq!(one, four, "streaming {streaming:?} epoch {epoch}");
        }
    }
}

#[test]
fn an_epoch_is_a_seeded_permutation_of_every_sample() {
    let ds = fixture();
    let total: usize = ds.fixture.lens.iter().sum();
    let e0 = keys(&all_batches(opts(), &ds.location(), 0));
    let e1 = keys(&all_batches(opts(), &ds.location(), 1));
    assert_eq!(e0.len(), total);
    assert_eq!(
        e0.iter().collect::<BTreeSet<_>>().len(),
        total,
        "no sample twice"
    );
    assert_ne!(e0, e1, "each epoch has its own permutation");
    assert_eq!(
        e1.iter().collect::<BTreeSet<_>>(),
        e0.iter().collect::<BTreeSet<_>>()
    );
    assert_eq!(
        e0,
        keys(&all_batches(opts(), &ds.location(), 0)),
        "reproducible"
    );
    assert_ne!(
        e0,
        keys(&all_batches(opts().seed(12), &ds.location(), 0)),
        "seeded"
    );
    let plain = keys(&all_batches(opts().shuffle(false), &ds.location(), 0));
    let mut sorted = plain.clone();
    sorted.sort();
    assert_eq!(plain, sorted, "without shuffle: episode then frame order");
}

#[test]
fn ranks_are_disjoint_covering_and_equal_in_count() {
    let ds = fixture();
    let total: usize = ds.fixture.lens.iter().sum(); // 49: not a multiple of 2 or 3
    for streaming in [None, Some(2)] {
        for world in [2usize, 3] {
            let mut per_rank = Vec::new();
            for rank in 0..world {
                let o = opts().rank(rank, world);
                let o = match streaming {
                    Some(n) => o.streaming(n),
                    None => o,
                };
                let mut l = o.open(&ds.location()).unwrap();
                l.set_epoch(2);
                let got = common::samples_of(&mut l);
                assert_eq!(got.len(), l.len());
                per_rank.push(got);
            }
            let ctx = format!("streaming {streaming:?} world {world}");
            let n = per_rank[0].len();
            assert!(per_rank.iter().all(|r| r.len() == n), "{ctx}: equal counts");
            let mut count: BTreeMap<(i64, i64), usize> = BTreeMap::new();
            for r in &per_rank {
                for k in r {
                    *count.entry(*k).or_default() += 1;
                }
            }
            assert_eq!(count.len(), total, "{ctx}: every sample on some rank");
            // Padding to equal counts repeats the fewest samples possible.
            let repeats: usize = count.values().map(|c| c - 1).sum();
            assert_eq!(
                repeats,
                n * world - total,
                "{ctx}: only the padding repeats"
            );
            if streaming.is_none() {
                assert_eq!(
                    n,
                    total.div_ceil(world),
                    "{ctx}: DistributedSampler's count"
                );
            }
        }
    }
    // A world size that divides the sample count: strictly disjoint.
    let ds = common::write(&Fixture {
        lens: vec![4, 6, 2],
        ..Fixture::default()
    });
    let sets: Vec<BTreeSet<(i64, i64)>> = (0..3)
        .map(|r| {
            let mut l = opts().rank(r, 3).open(&ds.location()).unwrap();
            common::samples_of(&mut l).into_iter().collect()
        })
        .collect();
    assert!(sets.iter().all(|s| s.len() == 4));
    assert_eq!(sets.iter().flatten().collect::<BTreeSet<_>>().len(), 12);
}

#[test]
fn resume_mid_epoch_reproduces_the_rest_exactly() {
    let ds = fixture();
    for streaming in [None, Some(3)] {
        let o = match streaming {
            Some(n) => opts().streaming(n),
            None => opts(),
        };
        let mut full = o.clone().open(&ds.location()).unwrap();
        full.set_epoch(4);
        let whole: Vec<Batch> = full.iter().map(Result::unwrap).collect();
        for cut in [0, 1, 4, whole.len()] {
            let mut first = o.clone().open(&ds.location()).unwrap();
            first.set_epoch(4);
            for _ in 0..cut {
                first.next_batch().unwrap().unwrap();
            }
            let state = first.state();
            assert_eq!(state.epoch, 4);
            assert_eq!(
                state.position as usize,
                whole[..cut].iter().map(|b| b.len).sum::<usize>()
            );
            // Through serde, as a trainer's checkpoint would carry it.
            let json = serde_json::to_string(&state).unwrap();
            let state: LoaderState = serde_json::from_str(&json).unwrap();
            drop(first);
            let mut again = o.clone().threads(3).open(&ds.location()).unwrap();
            again.resume(state).unwrap();
            let rest: Vec<Batch> = again.iter().map(Result::unwrap).collect();
            assert_eq!(rest, whole[cut..], "streaming {streaming:?} cut {cut}");
            assert!(again.next_batch().is_none());
        }
        let mut l = o.open(&ds.location()).unwrap();
        let bad = LoaderState {
            epoch: 0,
            position: 10_000,
        };
        let e = l.resume(bad).unwrap_err().to_string();
        assert!(e.contains("10000"), "{e}");
    }
}

#[test]
fn batch_counts_follow_drop_incomplete_batch() {
    let ds = fixture();
    let mut l = opts().open(&ds.location()).unwrap();
    assert_eq!((l.len(), l.batches_per_epoch()), (49, 10));
    let sizes: Vec<usize> = l.iter().map(|b| b.unwrap().len).collect();
    assert_eq!(sizes, [5, 5, 5, 5, 5, 5, 5, 5, 5, 4]);
    assert!(l.next_batch().is_none(), "an epoch ends");
    l.set_epoch(1);
    assert_eq!(
        l.state(),
        LoaderState {
            epoch: 1,
            position: 0
        }
    );
    let mut l = opts()
        .drop_incomplete_batch(true)
        .open(&ds.location())
        .unwrap();
    assert_eq!((l.len(), l.batches_per_epoch()), (45, 9));
    assert!(l.iter().all(|b| b.unwrap().len == 5));
}

#[test]
fn splits_are_disjoint_by_episode_and_caps_nest() {
    let ds = common::write(&Fixture {
        lens: vec![3; 20],
        cameras: vec![("top".into(), 8, 8)],
        episodes_per_file: 7,
        ..Fixture::default()
    });
    let eps = |o: LoaderOptions| -> BTreeSet<i64> {
        let mut l = o.batch_size(16).open(&ds.location()).unwrap();
        let from_batches: BTreeSet<i64> = common::samples_of(&mut l)
            .into_iter()
            .map(|k| k.0)
            .collect();
        assert_eq!(from_batches, l.info().episodes.iter().copied().collect());
        from_batches
    };
    let split = |s: Split| {
        LoaderOptions::default()
            .split(s)
            .val_ratio(0.2)
            .split_seed(5)
    };
    let (train, val) = (eps(split(Split::Train)), eps(split(Split::Val)));
    assert_eq!((train.len(), val.len()), (16, 4));
    assert!(train.is_disjoint(&val));
    assert_eq!(train.union(&val).count(), 20);
    assert_ne!(
        val,
        eps(split(Split::Val).split_seed(6)),
        "the split seed matters"
    );
    let five = eps(split(Split::Train).max_episodes(5));
    let ten = eps(split(Split::Train).max_episodes(10));
    assert_eq!((five.len(), ten.len()), (5, 10));
    assert!(
        five.is_subset(&ten) && ten.is_subset(&train),
        "smaller caps are subsets"
    );
    assert_eq!(eps(split(Split::All)).len(), 20);
}
