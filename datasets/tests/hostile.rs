//! Hostile datasets: a data file missing or damaged, `info.json` paths that leave the dataset, a
//! feature whose shape the data contradicts, a corrupt JPEG, statistics missing a key or not
//! finite. Each is one clear line naming the file and what is wrong, or — when the user allows
//! it with `skip_bad_samples` — a sample left out and counted; never a panic or a hang.
#![allow(clippy::unwrap_used)]

use crate::common;

use common::Fixture;
use scaledp_datasets::LoaderOptions;

fn open_err(o: LoaderOptions, location: &str) -> String {
    let e = o.open(location).expect_err("an error").to_string();
    assert!(!e.contains('\n'), "one line: {e}");
    e
}

fn edit_json(path: &std::path::Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(path, serde_json::to_vec(&v).unwrap()).unwrap();
}

/// JPEG frames of one camera, noisy (a realistic few KB each, so a damaged one is noticed).
fn jpeg_fixture(lens: Vec<usize>) -> common::Written {
    common::write(&Fixture {
        lens,
        cameras: vec![("top".into(), 32, 24)],
        png: false,
        noise: true,
        ..Fixture::default()
    })
}

/// Byte offsets of the JPEGs (start-of-image markers) in a data file, in row order.
fn jpeg_starts(bytes: &[u8]) -> Vec<usize> {
    bytes
        .windows(4)
        .enumerate()
        .filter(|(_, w)| w[..3] == [0xFF, 0xD8, 0xFF])
        .map(|(i, _)| i)
        .collect()
}

/// Breaks the JPEG of row `row` of the dataset's first data file: its frame header claims a
/// height of 0 (zune-jpeg refuses it; garbage in the entropy-coded data would only make noise).
fn break_jpeg(ds: &common::Written, row: usize) {
    let path = ds.root.join(&ds.files[0]);
    let mut bytes = std::fs::read(&path).unwrap();
    let start = jpeg_starts(&bytes)[row];
    let sof = start
        + bytes[start..]
            .windows(2)
            .position(|w| w == [0xFF, 0xC0])
            .unwrap();
    // SOF0: marker, length (2), precision (1), height (2), width (2).
    bytes[sof + 5] = 0;
    bytes[sof + 6] = 0;
    std::fs::write(&path, bytes).unwrap();
}

#[test]
fn a_missing_data_file_is_an_error_not_fewer_episodes() {
    let ds = common::write(&Fixture::default());
    std::fs::remove_file(ds.root.join(&ds.files[1])).unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(
        e.contains("meta/info.json")
            && e.contains("total_episodes 6")
            && e.contains("hold 4 episodes")
            && e.contains("missing"),
        "{e}"
    );
}

#[test]
fn paths_leaving_the_dataset_are_refused() {
    for (key, value) in [
        ("data_path", "../../elsewhere/file-{file_index:03d}.parquet"),
        ("data_path", "/etc/{chunk_index}.parquet"),
        ("video_path", "videos/../../../{video_key}.mp4"),
        ("data_path", "s3://other-bucket/{file_index}.parquet"),
    ] {
        let ds = common::write(&Fixture::default());
        edit_json(&ds.root.join("meta/info.json"), |v| {
            v[key] = serde_json::json!(value);
        });
        let e = open_err(LoaderOptions::default(), &ds.location());
        assert!(
            e.contains("meta/info.json") && e.contains(key) && e.contains("outside the dataset"),
            "{e}"
        );
    }
}

#[test]
fn a_feature_whose_shape_the_data_contradicts_is_named() {
    let ds = common::write(&Fixture::default());
    let info = ds.root.join("meta/info.json");
    let text = std::fs::read(&info).unwrap();
    edit_json(&info, |v| {
        v["features"]["observation.state"]["shape"] = serde_json::json!([7]);
    });
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(
        e.contains("observation.state") && e.contains("[7]") && e.contains("3 values"),
        "{e}"
    );

    // An image shape no batch can hold, and one with no channel axis.
    for shape in [
        serde_json::json!([100_000, 100_000, 3]),
        serde_json::json!([12, 16, 5]),
    ] {
        std::fs::write(&info, &text).unwrap();
        edit_json(&info, |v| {
            v["features"]["observation.images.top"]["shape"] = shape.clone();
            v["features"]["observation.images.top"]["names"] = serde_json::Value::Null;
        });
        let e = open_err(LoaderOptions::default(), &ds.location());
        assert!(e.contains(&ds.location()), "{e}");
    }
}

#[test]
fn statistics_missing_a_key_or_not_finite_are_named() {
    let ds = common::write(&Fixture::default());
    let stats = ds.root.join("meta/stats.json");
    let text = std::fs::read(&stats).unwrap();
    edit_json(&stats, |v| {
        v["observation.state"]
            .as_object_mut()
            .unwrap()
            .remove("std");
    });
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(
        e.contains("meta/stats.json") && e.contains("observation.state/std"),
        "{e}"
    );
    // Unused statistics may be missing: min-max state needs no std.
    LoaderOptions::default()
        .state_norm(scaledp_datasets::Norm::MinMax)
        .open(&ds.location())
        .unwrap();

    std::fs::write(&stats, &text).unwrap();
    let t = String::from_utf8(text).unwrap();
    // A `null` where a number belongs (what NaN becomes in JSON).
    let broken = t.replacen("\"max\": [", "\"max\": [null, ", 1);
    std::fs::write(&stats, broken).unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(e.contains("meta/stats.json"), "{e}");
}

#[test]
fn a_corrupt_jpeg_fails_its_batch_or_is_skipped_and_counted() {
    let ds = jpeg_fixture(vec![3, 4]);
    // Row 4 of the file: episode 1, frame 1.
    break_jpeg(&ds, 4);
    let o = || LoaderOptions::default().shuffle(false).batch_size(2);
    let mut l = o().open(&ds.location()).unwrap();
    let e = l
        .iter()
        .find_map(Result::err)
        .expect("an error")
        .to_string();
    assert!(
        e.contains(&ds.files[0])
            && e.contains("episode 1 frame 1")
            && e.contains("observation.images.top"),
        "{e}"
    );

    // Skipped: the samples whose observation window holds that frame (t = 1 and t = 2 with
    // To = 2) are left out, the rest are all there, each once.
    for streaming in [false, true] {
        let mut o = o().skip_bad_samples(2);
        if streaming {
            o = o.streaming(1);
        }
        let mut l = o.open(&ds.location()).unwrap();
        let mut seen = common::samples_of(&mut l);
        seen.sort_unstable();
        let want: Vec<(i64, i64)> = [(0, 0), (0, 1), (0, 2), (1, 0), (1, 3)].into();
        assert_eq!(seen, want, "streaming {streaming}");
        assert_eq!(l.skipped_samples(), 2);
        assert_eq!(l.state().position, 7, "the skipped samples count as used");
    }
    // A budget too small: the next bad sample is the error.
    let mut l = o().skip_bad_samples(1).open(&ds.location()).unwrap();
    let e = l
        .iter()
        .find_map(Result::err)
        .expect("an error")
        .to_string();
    assert!(e.contains("episode 1 frame 1"), "{e}");
}

#[test]
fn a_data_file_damaged_inside_fails_reads_of_it_only() {
    let ds = jpeg_fixture(vec![4, 4, 4, 4, 4, 4]);
    // The second file (episodes 4, 5, a row group each): zero the image pages of episode 4
    // (its first four JPEGs, page headers between them included); its small columns, episode
    // 5 and the footer stay intact.
    let path = ds.root.join(&ds.files[1]);
    let mut bytes = std::fs::read(&path).unwrap();
    let starts = jpeg_starts(&bytes);
    assert_eq!(starts.len(), 8);
    let (a, b) = (starts[0], starts[3] + 16);
    bytes[a..b].fill(0);
    std::fs::write(&path, bytes).unwrap();
    let o = || LoaderOptions::default().batch_size(4).threads(2);
    let mut l = o().open(&ds.location()).unwrap();
    let e = l
        .iter()
        .find_map(Result::err)
        .expect("an error")
        .to_string();
    assert!(e.contains(&ds.files[1]), "{e}");
    let mut l = o().skip_bad_samples(100).open(&ds.location()).unwrap();
    let seen = common::samples_of(&mut l);
    assert_eq!(seen.len(), 20, "every episode but 4 is read");
    assert!(seen.iter().all(|&(e, _)| e != 4));
    assert_eq!(l.skipped_samples(), 4);
}
