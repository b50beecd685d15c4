//! Edge cases a trainer hits sooner or later: state-only batches (no cameras), more DDP ranks
//! than episodes in streaming mode, a rank whose padded tail wraps many times, a split with no
//! samples, options too large to allocate, and a resume that fails.
#![allow(clippy::unwrap_used)]

use crate::common;

use common::{action_value, state_value, Fixture};
use scaledp_datasets::{LoaderOptions, LoaderState, Norm, Split};

#[test]
fn without_cameras_state_and_action_are_still_filled() {
    let ds = common::write(&Fixture::default());
    let mut l = LoaderOptions::default()
        .cameras(vec![])
        .state_norm(Norm::None)
        .action_norm(Norm::None)
        .obs_horizon(2)
        .action_chunk(3)
        .batch_size(4)
        .open(&ds.location())
        .unwrap();
    let lens = &ds.fixture.lens;
    let (sd, ad) = (ds.fixture.state_dim, ds.fixture.action_dim);
    let mut seen = 0;
    for b in l.iter() {
        let b = b.unwrap();
        assert!(b.images.is_empty() && b.cameras.is_empty());
        for k in 0..b.len {
            let (e, t) = (b.episode_index[k] as usize, b.frame_index[k] as usize);
            let w = scaledp_datasets::window(lens[e], t, 2, 3, 0);
            for (j, &f) in w.obs.iter().enumerate() {
                for d in 0..sd {
                    assert_eq!(b.state[(k * 2 + j) * sd + d], state_value(e, f, d));
                }
            }
            for (j, &f) in w.action.iter().enumerate() {
                for d in 0..ad {
                    assert_eq!(b.action[(k * 3 + j) * ad + d], action_value(e, f, d));
                }
            }
            assert_eq!(&b.obs_is_pad[k * 2..k * 2 + 2], &w.obs_is_pad[..]);
            assert_eq!(&b.action_is_pad[k * 3..k * 3 + 3], &w.action_is_pad[..]);
            seen += 1;
        }
    }
    assert_eq!(seen, lens.iter().sum::<usize>());
}

#[test]
fn streaming_with_more_ranks_than_episodes_gives_every_rank_the_same_count() {
    let ds = common::write(&Fixture {
        lens: vec![6, 3],
        cameras: vec![("top".into(), 8, 6)],
        ..Fixture::default()
    });
    let world = 5;
    let mut counts = Vec::new();
    let mut union = std::collections::BTreeSet::new();
    for rank in 0..world {
        let mut l = LoaderOptions::default()
            .streaming(2)
            .batch_size(2)
            .rank(rank, world)
            .open(&ds.location())
            .unwrap();
        let s = common::samples_of(&mut l);
        counts.push(s.len());
        union.extend(s);
    }
    assert!(counts.iter().all(|&c| c == 6), "{counts:?}");
    assert_eq!(union.len(), 9, "ranks together cover every sample");
}

#[test]
fn a_padded_tail_that_wraps_keeps_the_buffer_bound() {
    // Unshuffled, rank 1 of 2 gets ten 2-frame episodes (20 samples) and pads to rank 0's
    // 220: its tail repeats its order ten times. One episode open, one sample per batch: at
    // most 2 episodes (4 frames) are resident at once.
    let mut lens = vec![200];
    lens.extend(std::iter::repeat_n(2, 20));
    let ds = common::write(&Fixture {
        lens,
        episodes_per_file: 25,
        cameras: vec![("top".into(), 8, 6)],
        ..Fixture::default()
    });
    let mut l = LoaderOptions::default()
        .streaming(1)
        .shuffle(false)
        .batch_size(1)
        .rank(1, 2)
        .open(&ds.location())
        .unwrap();
    let s = common::samples_of(&mut l);
    assert_eq!(s.len(), 220);
    let peak = l.peak_resident_rows();
    assert!(peak > 0 && peak <= 4, "{peak} frames resident");
}

#[test]
fn a_selection_without_samples_is_refused_when_opened() {
    let ds = common::write(&Fixture::default());
    let e = LoaderOptions::default()
        .split(Split::Train)
        .val_ratio(1.0)
        .open(&ds.location())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no samples") && e.contains(&ds.location()),
        "{e}"
    );
    let e = LoaderOptions::default()
        .drop_first(10)
        .drop_last(10)
        .open(&ds.location())
        .unwrap_err()
        .to_string();
    assert!(e.contains("no samples"), "{e}");
}

#[test]
fn sizes_that_cannot_be_allocated_are_refused_when_opened() {
    let ds = common::write(&Fixture::default());
    let open = |o: LoaderOptions| o.open(&ds.location()).unwrap_err().to_string();
    assert!(open(LoaderOptions::default().image_size(0, 240)).contains("image size 0×240"));
    let e = open(
        LoaderOptions::default()
            .image_size(16_000, 16_000)
            .batch_size(4096),
    );
    assert!(e.contains("GiB"), "{e}");
    let e = open(LoaderOptions::default().action_offset(usize::MAX));
    assert!(e.contains("at most"), "{e}");
}

#[test]
fn a_failed_resume_leaves_the_loader_where_it_was() {
    let ds = common::write(&Fixture::default());
    let mut l = LoaderOptions::default()
        .batch_size(3)
        .open(&ds.location())
        .unwrap();
    l.set_epoch(2);
    l.next_batch().unwrap().unwrap();
    let before = l.state();
    let e = l.resume(LoaderState {
        epoch: 5,
        position: 10_000,
    });
    assert!(e.is_err());
    assert_eq!(l.state(), before);
    // And it goes on with the same batches as a loader that never tried.
    let mut twin = LoaderOptions::default()
        .batch_size(3)
        .open(&ds.location())
        .unwrap();
    twin.resume(before).unwrap();
    assert_eq!(
        l.next_batch().unwrap().unwrap(),
        twin.next_batch().unwrap().unwrap()
    );
}
