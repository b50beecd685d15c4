//! Bad input gives one clear line naming the file (or option) and what is wrong, never a panic.
#![allow(clippy::unwrap_used)]

use crate::common;

use common::Fixture;
use scaledp_datasets::LoaderOptions;

fn open_err(o: LoaderOptions, location: &str) -> String {
    let e = o.open(location).expect_err("an error").to_string();
    assert!(!e.contains('\n'), "one line: {e}");
    e
}

/// The first error of an epoch, read through to the end.
fn epoch_err(o: LoaderOptions, location: &str) -> String {
    let mut l = o.open(location).unwrap();
    let e = l
        .iter()
        .find_map(Result::err)
        .expect("an error")
        .to_string();
    assert!(!e.contains('\n'), "one line: {e}");
    e
}

#[test]
fn missing_or_bad_meta_files_are_named() {
    let ds = common::write(&Fixture::default());
    let info = ds.root.join("meta/info.json");
    let text = std::fs::read(&info).unwrap();

    std::fs::write(&info, b"{ not json").unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(e.contains("meta/info.json"), "{e}");

    std::fs::write(
        &info,
        String::from_utf8(text.clone())
            .unwrap()
            .replace("v3.0", "v2.1"),
    )
    .unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(e.contains("meta/info.json") && e.contains("v2.1"), "{e}");

    std::fs::remove_file(&info).unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(e.contains("meta/info.json"), "{e}");
    std::fs::write(&info, &text).unwrap();

    std::fs::write(ds.root.join("meta/stats.json"), b"{}").unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(
        e.contains("meta/stats.json") && e.contains("observation.state"),
        "{e}"
    );

    let e = open_err(LoaderOptions::default(), "/nonexistent/dataset");
    assert!(e.contains("/nonexistent/dataset"), "{e}");
}

#[test]
fn a_missing_camera_is_named_with_the_ones_there_are() {
    let ds = common::write(&Fixture::default());
    let e = open_err(
        LoaderOptions::default().cameras(vec!["front".into()]),
        &ds.location(),
    );
    assert!(
        e.contains("front") && e.contains("observation.images.top") && e.contains("info.json"),
        "{e}"
    );
}

#[test]
fn bad_options_are_refused() {
    let ds = common::write(&Fixture::default());
    let e = open_err(LoaderOptions::default().rank(2, 2), &ds.location());
    assert!(e.contains("rank 2"), "{e}");
    let e = open_err(LoaderOptions::default().obs_horizon(0), &ds.location());
    assert!(e.contains("obs_horizon"), "{e}");
    let e = open_err(LoaderOptions::default().val_ratio(1.5), &ds.location());
    assert!(e.contains("1.5"), "{e}");
}

#[test]
fn a_truncated_data_file_is_named() {
    let ds = common::write(&Fixture::default());
    let path = ds.root.join(&ds.files[1]);
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(e.contains(&ds.files[1]), "{e}");

    std::fs::write(&path, b"PAR1 not parquet at all").unwrap();
    let e = open_err(LoaderOptions::default(), &ds.location());
    assert!(e.contains(&ds.files[1]), "{e}");
}

#[test]
fn a_corrupt_image_names_file_episode_frame_and_camera() {
    let ds = common::write(&Fixture {
        lens: vec![3, 4],
        cameras: vec![("top".into(), 16, 12)],
        ..Fixture::default()
    });
    // Garble the pixel data of the 5th PNG in the file (episode 1, frame 1): image bytes are
    // stored uncompressed, so the PNG's zlib stream (after "IDAT") is there to overwrite.
    let path = ds.root.join(&ds.files[0]);
    let mut bytes = std::fs::read(&path).unwrap();
    let idat: Vec<usize> = bytes
        .windows(4)
        .enumerate()
        .filter(|(_, w)| w == b"IDAT")
        .map(|(i, _)| i)
        .collect();
    assert_eq!(idat.len(), 7, "one PNG per frame");
    for b in &mut bytes[idat[4] + 4..idat[4] + 14] {
        *b = 0xA5;
    }
    std::fs::write(&path, &bytes).unwrap();
    let e = epoch_err(
        LoaderOptions::default().shuffle(false).batch_size(2),
        &ds.location(),
    );
    assert!(
        e.contains(&ds.files[0]) && e.contains("episode 1") && e.contains("frame 1"),
        "{e}"
    );
    assert!(e.contains("observation.images.top"), "{e}");
    // Without the camera, the broken image is never decoded.
    let mut l = LoaderOptions::default()
        .cameras(vec![])
        .open(&ds.location())
        .unwrap();
    assert!(l.iter().all(|b| b.is_ok()));
}
