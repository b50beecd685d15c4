//! Images: a camera subset (short or full names, in the order given), a resized output size,
//! cameras of different sizes, and random access that reads only the pages holding a sample's
//! rows of the cameras it uses (bytes read per sample measured against the files' own page index).
#![allow(clippy::unwrap_used)]

use crate::common;

use common::{decode_pixel, Fixture};
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::file::serialized_reader::ReadOptionsBuilder;
use scaledp_datasets::LoaderOptions;

fn three_cameras() -> common::Written {
    common::write(&Fixture {
        lens: vec![4, 9, 2],
        cameras: vec![
            ("left".into(), 24, 16),
            ("top".into(), 24, 16),
            ("wrist".into(), 24, 16),
        ],
        ..Fixture::default()
    })
}

#[test]
fn camera_subset_keeps_the_given_order() {
    let ds = three_cameras();
    let mut l = LoaderOptions::default()
        .cameras(vec!["wrist".into(), "observation.images.left".into()])
        .shuffle(false)
        .batch_size(3)
        .open(&ds.location())
        .unwrap();
    assert_eq!(
        l.info().cameras,
        ["observation.images.wrist", "observation.images.left"]
    );
    let b = l.next_batch().unwrap().unwrap();
    assert_eq!(
        b.cameras,
        ["observation.images.wrist", "observation.images.left"]
    );
    let plane = 24 * 16;
    assert_eq!(b.images.len(), 3 * 2 * 2 * 3 * plane);
    // Blue names the camera (index 2 = wrist, 0 = left in the fixture).
    for (slot, cam) in [(0usize, 2i32), (1, 0)] {
        let blue = i32::from(b.images[slot * 3 * plane + 2 * plane]);
        assert!(
            (blue - (cam * 64 + 32)).abs() <= 4,
            "slot {slot}: blue {blue}"
        );
    }
    let none = LoaderOptions::default()
        .cameras(vec![])
        .open(&ds.location())
        .unwrap();
    assert!(none.info().cameras.is_empty());
}

#[test]
fn resized_images_have_the_requested_size() {
    let ds = three_cameras();
    let mut l = LoaderOptions::default()
        .image_size(10, 6)
        .obs_horizon(3)
        .shuffle(false)
        .batch_size(4)
        .open(&ds.location())
        .unwrap();
    let b = l.next_batch().unwrap().unwrap();
    assert_eq!((b.width, b.height), (10, 6));
    assert_eq!(b.images.len(), 4 * 3 * 3 * 3 * 10 * 6);
    // Solid colours stay solid through the bilinear resize: every pixel names its frame.
    let plane = 60;
    for s in 0..4usize {
        for k in 0..3 {
            let base = (s * 3 + k) * 3 * 3 * plane;
            let frame = (s + k).saturating_sub(2usize);
            for px in 0..plane {
                let rgb = [
                    b.images[base + px],
                    b.images[base + plane + px],
                    b.images[base + 2 * plane + px],
                ];
                assert_eq!(
                    decode_pixel(rgb),
                    (0, frame),
                    "sample {s} step {k} pixel {px}"
                );
            }
        }
    }
}

#[test]
fn cameras_of_different_sizes_need_an_image_size() {
    let ds = common::write(&Fixture {
        cameras: vec![("big".into(), 32, 24), ("small".into(), 16, 12)],
        ..Fixture::default()
    });
    let e = LoaderOptions::default()
        .open(&ds.location())
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("image_size") && e.contains(&ds.location()),
        "{e}"
    );
    let mut l = LoaderOptions::default()
        .image_size(16, 12)
        .batch_size(2)
        .open(&ds.location())
        .unwrap();
    assert_eq!(
        l.next_batch().unwrap().unwrap().images.len(),
        2 * 2 * 2 * 3 * 16 * 12
    );
    // One camera alone needs none.
    let l = LoaderOptions::default()
        .cameras(vec!["big".into()])
        .open(&ds.location())
        .unwrap();
    assert_eq!((l.info().width, l.info().height), (32, 24));
}

/// Largest compressed page of the image `bytes` columns, from the file's offset index.
fn largest_image_page(path: &std::path::Path) -> u64 {
    let options = ReadOptionsBuilder::new().with_page_index().build();
    let r = SerializedFileReader::new_with_options(std::fs::File::open(path).unwrap(), options)
        .unwrap();
    let md = r.metadata();
    let offsets = md.offset_index().unwrap();
    let mut largest = 0u64;
    for (rg, cols) in offsets.iter().enumerate() {
        for (c, idx) in cols.iter().enumerate() {
            if md
                .row_group(rg)
                .column(c)
                .column_path()
                .string()
                .ends_with(".bytes")
            {
                for p in idx.page_locations() {
                    largest = largest.max(p.compressed_page_size as u64);
                }
            }
        }
    }
    largest
}

/// Bytes read at open and per sample over one epoch (To 2, one camera of two).
fn bytes_read(ds: &common::Written) -> (u64, u64) {
    let mut l = LoaderOptions::default()
        .cameras(vec!["top".into()])
        .obs_horizon(2)
        .batch_size(8)
        .prefetch(1)
        .open(&ds.location())
        .unwrap();
    let at_open = l.bytes_read();
    let n = common::samples_of(&mut l).len() as u64;
    (at_open, (l.bytes_read() - at_open) / n)
}

#[test]
fn random_access_reads_only_the_pages_of_a_sample() {
    // Noisy 64×48 JPEGs (several KB each), in the converter's layout (a page per frame) and in
    // one with 64 KiB pages holding a few frames each (other writers).
    for big_pages in [false, true] {
        let fx = Fixture {
            lens: vec![150, 150],
            episodes_per_file: 2,
            cameras: vec![("top".into(), 64, 48), ("wrist".into(), 64, 48)],
            png: false,
            noise: true,
            big_pages,
            ..Fixture::default()
        };
        let ds = common::write(&fx);
        let path = ds.root.join(&ds.files[0]);
        let file_size = std::fs::metadata(&path).unwrap().len();
        let page = largest_image_page(&path);
        let (at_open, per_sample) = bytes_read(&ds);
        eprintln!(
            "big pages {big_pages}: file {file_size} B, largest image page {page} B: opening read \
             {at_open} B, random access {per_sample} B per sample (To 2, 1 of 2 cameras)"
        );
        // A window of 2 frames lies in at most 2 pages of the one camera read.
        assert!(
            per_sample <= 2 * page,
            "{per_sample} B per sample, pages of {page} B"
        );
        assert!(
            per_sample * 20 < file_size,
            "{per_sample} B per sample of a {file_size} B file"
        );
        // Opening reads the footer and small columns, not the images.
        assert!(
            at_open * 5 < file_size,
            "opening read {at_open} of {file_size} B"
        );
        if !big_pages {
            // A page per frame: about the 2 images the sample uses (frames of 64×48 noise are
            // 2–3 KB; 2 KB of slack for page headers and the odd larger frame).
            let images = file_size / 600; // 2 cameras × 300 frames
            assert!(
                per_sample <= 2 * images + 2048,
                "{per_sample} B per sample, images of ~{images} B"
            );
        }

        // Without an offset index (pyarrow's default) page headers are read to find the rows,
        // but not the pages in between.
        let ds = common::write(&Fixture {
            page_index: false,
            ..fx
        });
        let (at_open, per_sample) = bytes_read(&ds);
        eprintln!(
            "without page index: opening read {at_open} B, random access {per_sample} B per sample"
        );
        assert!(
            per_sample * 10 < file_size,
            "{per_sample} B per sample of a {file_size} B file"
        );
        assert!(
            at_open * 5 < file_size,
            "opening read {at_open} of {file_size} B"
        );
    }
}

#[test]
fn recycled_buffers_give_the_same_batches() {
    let ds = three_cameras();
    // 15 samples in batches of 4: the last one is shorter than the buffer handed back.
    let opts = LoaderOptions::default().batch_size(4).seed(4).threads(2);
    let mut fresh = opts.clone().open(&ds.location()).unwrap();
    let want: Vec<_> = fresh.iter().map(Result::unwrap).collect();
    let mut reused = opts.open(&ds.location()).unwrap();
    for epoch in 0..2 {
        reused.set_epoch(0);
        let mut got = Vec::new();
        while let Some(b) = reused.next_batch() {
            let b = b.unwrap();
            got.push(b.clone());
            reused.recycle(b);
        }
        assert_eq!(got, want, "pass {epoch}");
    }
}
