//! Windows and padding equal diffusion_policy's `SequenceSampler`: a faithful re-implementation
//! of its `create_indices` and `sample_sequence` (diffusion_policy/common/sampler.py) is the
//! reference, on hand-built episodes shorter than To and than C, across episode and file
//! boundaries — both for `window` alone and for the batches the loader builds from Parquet.
#![allow(clippy::unwrap_used)]

use crate::common;

use common::{action_value, decode_pixel, state_value, Fixture};
use scaledp_datasets::{window, LoaderOptions, Norm};

/// diffusion_policy's `create_indices`: per sample `[buffer_start, buffer_end, sample_start,
/// sample_end]` over the concatenated episodes (all episodes kept: episode_mask all true).
fn create_indices(
    episode_ends: &[i64],
    sequence_length: i64,
    pad_before: i64,
    pad_after: i64,
) -> Vec<[i64; 4]> {
    let pad_before = pad_before.max(0).min(sequence_length - 1);
    let pad_after = pad_after.max(0).min(sequence_length - 1);
    let mut indices = Vec::new();
    for i in 0..episode_ends.len() {
        let start_idx = if i > 0 { episode_ends[i - 1] } else { 0 };
        let end_idx = episode_ends[i];
        let episode_length = end_idx - start_idx;
        let min_start = -pad_before;
        let max_start = episode_length - sequence_length + pad_after;
        for idx in min_start..=max_start {
            let buffer_start_idx = idx.max(0) + start_idx;
            let buffer_end_idx = (idx + sequence_length).min(episode_length) + start_idx;
            let start_offset = buffer_start_idx - (idx + start_idx);
            let end_offset = (idx + sequence_length + start_idx) - buffer_end_idx;
            let sample_start_idx = start_offset;
            let sample_end_idx = sequence_length - end_offset;
            indices.push([
                buffer_start_idx,
                buffer_end_idx,
                sample_start_idx,
                sample_end_idx,
            ]);
        }
    }
    indices
}

/// diffusion_policy's `sample_sequence` on a buffer of row numbers: the rows of the window, the
/// first one repeated before `sample_start`, the last one after `sample_end`.
fn sample_sequence(ix: [i64; 4], sequence_length: i64) -> Vec<i64> {
    let [buffer_start, buffer_end, sample_start, sample_end] = ix;
    let sample: Vec<i64> = (buffer_start..buffer_end).collect();
    let mut data = vec![0; sequence_length as usize];
    for (j, slot) in data.iter_mut().enumerate() {
        let j = j as i64;
        *slot = if j < sample_start {
            sample[0]
        } else if j >= sample_end {
            sample[sample.len() - 1]
        } else {
            sample[(j - sample_start) as usize]
        };
    }
    data
}

/// One reference sample in the loader's terms: global rows and pad flags of the To observation
/// and C action steps. The window's horizon is H = To + offset + C − 1 with pad_before = To − 1
/// and pad_after = offset + C − 1; observations are its first To steps, actions its last C.
struct Reference {
    obs: Vec<i64>,
    obs_is_pad: Vec<bool>,
    action: Vec<i64>,
    action_is_pad: Vec<bool>,
}

fn reference(lens: &[usize], to: usize, c: usize, offset: usize) -> Vec<Reference> {
    let ends: Vec<i64> = lens
        .iter()
        .scan(0i64, |s, &l| {
            *s += l as i64;
            Some(*s)
        })
        .collect();
    let h = (to + offset + c - 1) as i64;
    create_indices(&ends, h, to as i64 - 1, (offset + c) as i64 - 1)
        .into_iter()
        .map(|ix| {
            let rows = sample_sequence(ix, h);
            let pad: Vec<bool> = (0..h).map(|j| j < ix[2] || j >= ix[3]).collect();
            let a0 = to - 1 + offset;
            Reference {
                obs: rows[..to].to_vec(),
                obs_is_pad: pad[..to].to_vec(),
                action: rows[a0..].to_vec(),
                action_is_pad: pad[a0..].to_vec(),
            }
        })
        .collect()
}

/// (episode, frame) of each global row.
fn frames(lens: &[usize]) -> Vec<(usize, usize)> {
    lens.iter()
        .enumerate()
        .flat_map(|(e, &l)| (0..l).map(move |f| (e, f)))
        .collect()
}

#[test]
fn window_equals_create_indices_and_sample_sequence() {
    let lens = [1usize, 2, 3, 4, 5, 8, 16, 17, 40];
    let rows = frames(&lens);
    let starts: Vec<usize> = lens
        .iter()
        .scan(0, |s, &l| {
            *s += l;
            Some(*s - l)
        })
        .collect();
    let mut checked = 0;
    for to in 1..=5 {
        for c in [1, 2, 3, 8, 16, 20] {
            for offset in 0..=2 {
                let want = reference(&lens, to, c, offset);
                // create_indices yields one sample per frame: the current frame t = idx + To − 1.
                assert_eq!(
                    want.len(),
                    lens.iter().sum::<usize>(),
                    "To {to} C {c} offset {offset}"
                );
                for (r, &(e, t)) in want.iter().zip(&rows) {
                    let w = window(lens[e], t, to, c, offset);
                    let global = |v: &[usize]| {
                        v.iter()
                            .map(|&f| (starts[e] + f) as i64)
                            .collect::<Vec<_>>()
                    };
                    let ctx = format!(
                        "episode of {} frames, t {t}, To {to}, C {c}, offset {offset}",
                        lens[e]
                    );
                    assert_eq!(global(&w.obs), r.obs, "obs: {ctx}");
                    assert_eq!(w.obs_is_pad, r.obs_is_pad, "obs_is_pad: {ctx}");
                    assert_eq!(global(&w.action), r.action, "action: {ctx}");
                    assert_eq!(w.action_is_pad, r.action_is_pad, "action_is_pad: {ctx}");
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 5 * 6 * 3 * lens.iter().sum::<usize>());
}

/// Every batch of an unshuffled epoch against the reference: state and action values, masks and
/// the images of each observation step (solid colours naming episode and frame).
fn check_loader(fx: &Fixture, to: usize, c: usize, offset: usize, batch: usize) {
    let ds = common::write(fx);
    let mut loader = LoaderOptions::default()
        .obs_horizon(to)
        .action_chunk(c)
        .action_offset(offset)
        .state_norm(Norm::None)
        .action_norm(Norm::None)
        .shuffle(false)
        .batch_size(batch)
        .threads(2)
        .open(&ds.location())
        .unwrap();
    let want = reference(&fx.lens, to, c, offset);
    let rows = frames(&fx.lens);
    let (sd, ad) = (fx.state_dim, fx.action_dim);
    let ctx = format!("lens {:?} To {to} C {c} offset {offset}", fx.lens);
    let mut i = 0;
    for b in loader.iter() {
        let b = b.unwrap();
        assert_eq!(
            (b.obs_horizon, b.action_chunk, b.state_dim, b.action_dim),
            (to, c, sd, ad)
        );
        let (w, h) = (b.width as usize, b.height as usize);
        let cams = b.cameras.len();
        for s in 0..b.len {
            let r = &want[i];
            let (e, t) = rows[i];
            assert_eq!(
                (b.episode_index[s], b.frame_index[s]),
                (e as i64, t as i64),
                "{ctx}: sample {i}"
            );
            for k in 0..to {
                let (re, rf) = rows[r.obs[k] as usize];
                let st = &b.state[(s * to + k) * sd..(s * to + k + 1) * sd];
                assert_eq!(
                    st,
                    (0..sd).map(|d| state_value(re, rf, d)).collect::<Vec<_>>(),
                    "{ctx}: state {i}/{k}"
                );
                assert_eq!(
                    b.obs_is_pad[s * to + k],
                    r.obs_is_pad[k],
                    "{ctx}: obs_is_pad {i}/{k}"
                );
                for cam in 0..cams {
                    let plane = w * h;
                    let base = ((s * to + k) * cams + cam) * 3 * plane;
                    for px in [0, plane / 2 + w / 2, plane - 1] {
                        let rgb = [
                            b.images[base + px],
                            b.images[base + plane + px],
                            b.images[base + 2 * plane + px],
                        ];
                        assert_eq!(
                            decode_pixel(rgb),
                            (re % 32, rf % 32),
                            "{ctx}: image {i}/{k}/{cam} {rgb:?}"
                        );
                        assert!(
                            (i32::from(rgb[2]) - (cam as i32 * 64 + 32)).abs() <= 4,
                            "{ctx}: camera order"
                        );
                    }
                }
            }
            for k in 0..c {
                let (re, rf) = rows[r.action[k] as usize];
                let ac = &b.action[(s * c + k) * ad..(s * c + k + 1) * ad];
                assert_eq!(
                    ac,
                    (0..ad).map(|d| action_value(re, rf, d)).collect::<Vec<_>>(),
                    "{ctx}: action {i}/{k}"
                );
                assert_eq!(
                    b.action_is_pad[s * c + k],
                    r.action_is_pad[k],
                    "{ctx}: action_is_pad {i}/{k}"
                );
            }
            i += 1;
        }
    }
    assert_eq!(i, want.len(), "{ctx}: sample count");
}

#[test]
fn loader_batches_equal_the_reference_across_episode_and_file_boundaries() {
    // Episodes shorter than To (1, 2) and than C (1..7), in three data files.
    let fx = Fixture {
        lens: vec![1, 2, 3, 5, 9, 20, 4, 1],
        episodes_per_file: 3,
        ..Fixture::default()
    };
    check_loader(&fx, 2, 16, 0, 7);
    check_loader(&fx, 3, 4, 0, 5);
    check_loader(&fx, 4, 8, 1, 64);
    check_loader(&fx, 1, 1, 0, 3);
}

#[test]
fn other_writers_layouts_give_the_same_windows() {
    // Row groups of 8 rows crossing episodes, List<f32> vectors, no page index, JPEG images.
    let fx = Fixture {
        lens: vec![3, 11, 1, 6, 17],
        episodes_per_file: 5,
        row_group_rows: Some(8),
        list_vectors: true,
        page_index: false,
        png: false,
        ..Fixture::default()
    };
    check_loader(&fx, 2, 5, 0, 4);
    check_loader(&fx, 3, 2, 2, 9);
}

#[test]
fn dropped_frames_are_never_current_frames() {
    let fx = Fixture {
        lens: vec![1, 2, 3, 6, 10],
        ..Fixture::default()
    };
    let ds = common::write(&fx);
    let mut loader = LoaderOptions::default()
        .drop_first(1)
        .drop_last(2)
        .shuffle(false)
        .batch_size(4)
        .open(&ds.location())
        .unwrap();
    let got = common::samples_of(&mut loader);
    let want: Vec<(i64, i64)> = fx
        .lens
        .iter()
        .enumerate()
        .flat_map(|(e, &l)| (1..l.saturating_sub(2)).map(move |t| (e as i64, t as i64)))
        .collect();
    assert_eq!(got, want);
    assert_eq!(loader.len(), want.len());
}
