//! Hostile video features: a truncated MP4 (mdat cut, and cut before its index), a missing video
//! file, a codec we do not decode (HEVC), an episode whose timestamps lie outside its video.
//! Each is one line naming the file and the problem; with `skip_bad_samples` the samples that
//! need the bad file are left out and every other sample of the epoch is there.
#![allow(clippy::unwrap_used)]

use crate::common;

use std::collections::BTreeSet;
use std::sync::Arc;

use arrow_array::{Array, ArrayRef, Float64Array, RecordBatch};
use common::video::write_video;
use common::Fixture;
use scaledp_datasets::LoaderOptions;

fn fixture() -> Fixture {
    Fixture {
        lens: vec![5, 1, 3, 12, 2, 7],
        cameras: vec![("top".into(), 64, 48)],
        ..Fixture::default()
    }
}

fn video_file(e: usize) -> String {
    format!("videos/observation.images.top/chunk-000/file-{e:03}.mp4")
}

/// The first error of an epoch without skipping (one line), and the (episode, frame) samples
/// of an epoch that skips bad ones, with how many were skipped.
fn epoch(location: &str) -> (String, BTreeSet<(i64, i64)>, u64) {
    let mut strict = LoaderOptions::default()
        .batch_size(4)
        .open(location)
        .unwrap();
    let err = strict
        .iter()
        .find_map(|b| b.err())
        .expect("an error")
        .to_string();
    assert!(!err.contains('\n'), "one line: {err}");
    let mut lenient = LoaderOptions::default()
        .batch_size(4)
        .skip_bad_samples(1000)
        .open(location)
        .unwrap();
    let got = common::samples_of(&mut lenient).into_iter().collect();
    (err, got, lenient.skipped_samples())
}

/// Every sample of the episodes not in `bad`.
fn all_but(fx: &Fixture, bad: &[usize]) -> BTreeSet<(i64, i64)> {
    fx.lens
        .iter()
        .enumerate()
        .filter(|(e, _)| !bad.contains(e))
        .flat_map(|(e, &n)| (0..n).map(move |f| (e as i64, f as i64)))
        .collect()
}

/// A one-episode-per-file AV1 dataset with episode `e`'s file changed by `edit`.
fn broken(e: usize, edit: impl FnOnce(&std::path::Path)) -> (String, BTreeSet<(i64, i64)>, u64) {
    let v = write_video(&fixture(), &["top"], "av1", 1, 2);
    edit(&v.ds.root.join(video_file(e)));
    let (err, got, skipped) = epoch(&v.ds.location());
    assert!(err.contains(&video_file(e)), "{err}");
    // Every sample of the other episodes is there.
    let want = all_but(&v.ds.fixture, &[e]);
    assert!(
        got.is_superset(&want),
        "missing: {:?}",
        want.difference(&got)
    );
    assert_eq!(skipped, 30 - got.len() as u64);
    (err, got, skipped)
}

#[test]
fn a_video_file_cut_in_its_media_data_fails_the_frames_past_the_cut() {
    // Episode 3 (12 frames): the index is written first and survives; the second half of
    // the media data does not.
    let (err, got, skipped) = broken(3, |p| {
        let bytes = std::fs::read(p).unwrap();
        let mdat = bytes.windows(4).position(|w| w == b"mdat").unwrap();
        std::fs::write(p, &bytes[..mdat + (bytes.len() - mdat) / 2]).unwrap();
    });
    assert!(err.contains("cut short"), "{err}");
    assert!(got.contains(&(3, 0)), "the first frames still load");
    assert!(skipped >= 3, "{skipped}");
}

#[test]
fn a_video_file_cut_before_its_index_fails_its_episode() {
    let (err, got, _) = broken(5, |p| {
        std::fs::write(p, &std::fs::read(p).unwrap()[..100]).unwrap();
    });
    assert!(
        err.contains("cut short") || err.contains("not a readable MP4"),
        "{err}"
    );
    assert!(got.iter().all(|&(e, _)| e != 5));
}

#[test]
fn a_missing_video_file_fails_its_episode() {
    let (err, got, skipped) = broken(0, |p| std::fs::remove_file(p).unwrap());
    assert!(err.contains("video file missing"), "{err}");
    assert_eq!(skipped, 5);
    assert!(got.iter().all(|&(e, _)| e != 0));
}

#[test]
fn an_undecodable_codec_is_named() {
    let v = write_video(&fixture(), &["top"], "hevc", 10, 2);
    let (err, got, skipped) = epoch(&v.ds.location());
    assert!(
        err.contains(&video_file(0)) && err.contains("not decoded here") && err.contains("hvc1")
            || err.contains("hev1"),
        "{err}"
    );
    assert!(got.is_empty());
    assert_eq!(skipped, 30);
}

#[test]
fn timestamps_outside_the_video_fail_that_episode_only() {
    let v = write_video(&fixture(), &["top"], "av1", 10, 2);
    // Episode 2 claims to start 100 s into the file.
    let path = v.ds.root.join("meta/episodes/chunk-000/file-000.parquet");
    let file = std::fs::File::open(&path).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
        .unwrap()
        .build()
        .unwrap();
    let batch: RecordBatch = reader.map(|b| b.unwrap()).next().unwrap();
    let key = "videos/observation.images.top/from_timestamp";
    let col = batch.column_by_name(key).unwrap();
    let from = col.as_any().downcast_ref::<Float64Array>().unwrap();
    let moved: Float64Array = (0..from.len())
        .map(|i| Some(from.value(i) + if i == 2 { 100.0 } else { 0.0 }))
        .collect();
    let at = batch.schema().index_of(key).unwrap();
    let mut cols: Vec<ArrayRef> = batch.columns().to_vec();
    cols[at] = Arc::new(moved);
    let batch = RecordBatch::try_new(batch.schema(), cols).unwrap();
    let mut w = parquet::arrow::ArrowWriter::try_new(
        std::fs::File::create(&path).unwrap(),
        batch.schema(),
        None,
    )
    .unwrap();
    w.write(&batch).unwrap();
    w.close().unwrap();
    let (err, got, skipped) = epoch(&v.ds.location());
    assert!(
        err.contains(&video_file(0)) && err.contains("episode 2") && err.contains("no frame at"),
        "{err}"
    );
    assert_eq!(got, all_but(&v.ds.fixture, &[2]));
    assert_eq!(skipped, 3);
}
