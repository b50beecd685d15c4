//! Streaming mode: every sample exactly once per epoch, a seeded order that is the same on every
//! run, the same sample contents as random access, and bounded memory — the frames whose images
//! are held at once never exceed what the buffer allows (computed from the options, not timed).
#![allow(clippy::unwrap_used)]

use crate::common;

use std::collections::{BTreeSet, HashMap};

use common::Fixture;
use scaledp_datasets::{Batch, LoaderOptions};

fn fixture() -> common::Written {
    // 30 episodes of 3..=21 frames in 4 files.
    common::write(&Fixture {
        lens: (0..30).map(|i| 3 + (i * 7) % 19).collect(),
        episodes_per_file: 8,
        cameras: vec![("top".into(), 8, 6)],
        ..Fixture::default()
    })
}

/// Each sample's (state, action, images), keyed by (episode, frame).
type Contents = HashMap<(i64, i64), (Vec<f32>, Vec<f32>, Vec<u8>)>;

fn contents(batches: &[Batch]) -> Contents {
    let mut out = HashMap::new();
    for b in batches {
        let (s, a, i) = (
            b.state.len() / b.len,
            b.action.len() / b.len,
            b.images.len() / b.len,
        );
        for k in 0..b.len {
            let key = (b.episode_index[k], b.frame_index[k]);
            let v = (
                b.state[k * s..(k + 1) * s].to_vec(),
                b.action[k * a..(k + 1) * a].to_vec(),
                b.images[k * i..(k + 1) * i].to_vec(),
            );
            assert!(out.insert(key, v).is_none(), "{key:?} twice");
        }
    }
    out
}

#[test]
fn streaming_covers_every_sample_once_with_random_access_contents() {
    let ds = fixture();
    let total: usize = ds.fixture.lens.iter().sum();
    let opts = LoaderOptions::default()
        .obs_horizon(3)
        .action_chunk(5)
        .batch_size(7)
        .seed(9);
    let mut random = opts.clone().open(&ds.location()).unwrap();
    let reference = contents(&random.iter().map(Result::unwrap).collect::<Vec<_>>());
    assert_eq!(reference.len(), total);
    let mut orders = Vec::new();
    for epoch in 0..3 {
        let mut l = opts.clone().streaming(3).open(&ds.location()).unwrap();
        assert_eq!(l.len(), total);
        l.set_epoch(epoch);
        let batches: Vec<Batch> = l.iter().map(Result::unwrap).collect();
        let got = contents(&batches);
        assert_eq!(got.len(), total, "every sample once");
        assert!(
            got == reference,
            "epoch {epoch}: streaming and random access disagree on a sample"
        );
        orders.push(
            batches
                .iter()
                .flat_map(|b| b.episode_index.clone())
                .collect::<Vec<_>>(),
        );
        // Deterministic: the same epoch again, from a new loader.
        let mut again = opts.clone().streaming(3).open(&ds.location()).unwrap();
        again.set_epoch(epoch);
        assert_eq!(
            again.iter().map(Result::unwrap).collect::<Vec<_>>(),
            batches
        );
    }
    assert_ne!(orders[0], orders[1]);
    assert_ne!(orders[1], orders[2]);
}

#[test]
fn streaming_holds_a_bounded_number_of_frames() {
    let ds = fixture();
    let lens = &ds.fixture.lens;
    let total: usize = lens.iter().sum();
    let longest = *lens.iter().max().unwrap();
    for (buffer, batch) in [(1usize, 1usize), (2, 4), (4, 8)] {
        let mut l = LoaderOptions::default()
            .streaming(buffer)
            .batch_size(batch)
            .prefetch(2)
            .threads(3)
            .open(&ds.location())
            .unwrap();
        let mut seen_eps = BTreeSet::new();
        for b in l.iter() {
            seen_eps.extend(b.unwrap().episode_index);
        }
        assert_eq!(seen_eps.len(), lens.len());
        // At a batch's start at most `buffer` episodes are open; each of its samples can finish
        // one episode and let one more open.
        let bound = (buffer + batch) * longest;
        let peak = l.peak_resident_rows();
        eprintln!("buffer {buffer} batch {batch}: peak {peak} frames resident (bound {bound}, dataset {total})");
        assert!(
            peak > 0 && peak <= bound,
            "buffer {buffer} batch {batch}: {peak} > {bound}"
        );
        assert!(
            peak * 2 < total,
            "buffer {buffer}: {peak} of {total} frames"
        );
    }
    let mut random = LoaderOptions::default().open(&ds.location()).unwrap();
    random.iter().for_each(|b| drop(b.unwrap()));
    assert_eq!(
        random.peak_resident_rows(),
        0,
        "random access keeps no images between samples"
    );
}
