//! Video features, written as LeRobot 0.4.4 writes them (PyAV, libsvtav1 yuv420p g=2 crf=30,
//! episodes concatenated per file): every frame of every window equals what LeRobot's pyav
//! backend decodes for that row (same nearest-frame rule), in random access and streaming;
//! H.264 with longer groups of pictures; the order, sharding and resuming are those of the
//! same dataset stored as images; a dataset mixing image and video cameras.
#![allow(clippy::unwrap_used)]

use crate::common;

use common::video::{where_is, write_video, VideoWritten};
use common::{decode_pixel, Fixture};
use scaledp_datasets::{window, Batch, LoaderOptions};

fn fixture() -> Fixture {
    Fixture {
        lens: vec![5, 1, 3, 12, 2, 7],
        cameras: vec![("top".into(), 64, 48), ("wrist".into(), 64, 48)],
        ..Fixture::default()
    }
}

/// Checks every image of `b` (cameras `video` of `keys` by position) against PyAV's decoding;
/// returns how many were compared.
fn check_batch(v: &VideoWritten, per_file: usize, b: &Batch, keys: &[&str]) -> usize {
    let fx = &v.ds.fixture;
    let plane = 3 * b.width as usize * b.height as usize;
    let cams = b.cameras.len();
    let mut checked = 0;
    for i in 0..b.len {
        let (e, t) = (b.episode_index[i] as usize, b.frame_index[i] as usize);
        let w = window(fx.lens[e], t, b.obs_horizon, b.action_chunk, 0);
        for (k, &f) in w.obs.iter().enumerate() {
            for (c, key) in keys.iter().enumerate() {
                let slot = ((i * b.obs_horizon + k) * cams + c) * plane;
                let got = &b.images[slot..slot + plane];
                let (file, t_s) = where_is(fx, key, per_file, e, f);
                let want = v.files[&file].chw_at(t_s);
                // First that it is the right frame of the right episode (colours survive the
                // codec), then that it is exactly PyAV's decoding.
                let hw = plane / 3;
                let px = [got[hw / 2], got[hw + hw / 2], got[2 * hw + hw / 2]];
                assert_eq!(decode_pixel(px), (e % 32, f % 32), "{key} e {e} f {f}");
                let diff = got.iter().zip(&want).filter(|(a, b)| a != b).count();
                assert_eq!(
                    diff, 0,
                    "episode {e} frame {f} {key}: {diff} values differ from PyAV"
                );
                checked += 1;
            }
        }
    }
    checked
}

#[test]
fn av1_frames_equal_lerobots_pyav_decoding_in_random_access_and_streaming() {
    let per_file = 2;
    let v = write_video(&fixture(), &["top", "wrist"], "av1", per_file, 2);
    let total: usize = v.ds.fixture.lens.iter().sum();
    for streaming in [None, Some(2)] {
        let mut o = LoaderOptions::default()
            .batch_size(5)
            .obs_horizon(3)
            .threads(2);
        if let Some(n) = streaming {
            o = o.streaming(n);
        }
        let mut l = o.open(&v.ds.location()).unwrap();
        let mut checked = 0;
        let mut samples = 0;
        for b in l.iter() {
            let b = b.unwrap();
            samples += b.len;
            checked += check_batch(&v, per_file, &b, &["top", "wrist"]);
        }
        assert_eq!(samples, total, "streaming {streaming:?}");
        assert_eq!(checked, total * 3 * 2);
    }
}

#[test]
fn h264_with_longer_groups_decodes_every_frame_and_resizes() {
    let per_file = 3;
    let v = write_video(&fixture(), &["top", "wrist"], "h264", per_file, 12);
    let mut l = LoaderOptions::default()
        .batch_size(4)
        .video_decoders(1)
        .open(&v.ds.location())
        .unwrap();
    let mut checked = 0;
    for b in l.iter() {
        checked += check_batch(&v, per_file, &b.unwrap(), &["top", "wrist"]);
    }
    assert_eq!(checked, 30 * 2 * 2);
    // Another output size: resized like image features (the colour code still reads).
    let mut small = LoaderOptions::default()
        .image_size(32, 24)
        .shuffle(false)
        .open(&v.ds.location())
        .unwrap();
    let b = small.next_batch().unwrap().unwrap();
    assert_eq!(b.images.len(), b.len * 2 * 2 * 3 * 32 * 24);
    let hw = 32 * 24;
    let last = ((b.len - 1) * 2 + 1) * 2 * 3 * hw;
    let px = [
        b.images[last + 12 * 32 + 16],
        b.images[last + hw + 12 * 32 + 16],
        b.images[last + 2 * hw + 12 * 32 + 16],
    ];
    assert_eq!(
        decode_pixel(px),
        (
            b.episode_index[b.len - 1] as usize,
            b.frame_index[b.len - 1] as usize
        )
    );
}

#[test]
fn order_sharding_and_resume_are_those_of_the_image_dataset() {
    let images = common::write(&fixture());
    let v = write_video(&fixture(), &["top", "wrist"], "av1", 3, 2);
    let opts = || LoaderOptions::default().batch_size(3).seed(7).rank(1, 2);
    let want = common::samples_of(&mut opts().open(&images.location()).unwrap());
    let mut video = opts().open(&v.ds.location()).unwrap();
    assert_eq!(common::samples_of(&mut video), want);
    // Resume in the middle of epoch 1.
    video.set_epoch(1);
    let first = video.next_batch().unwrap().unwrap();
    let state = video.state();
    let rest = common::samples_of(&mut video);
    let mut again = opts().open(&v.ds.location()).unwrap();
    again.resume(state).unwrap();
    assert_eq!(common::samples_of(&mut again), rest);
    assert_eq!(first.len, 3);
}

#[test]
fn image_and_video_cameras_mix() {
    let images = common::write(&fixture());
    let v = write_video(&fixture(), &["top"], "av1", 10, 2);
    let opts = || LoaderOptions::default().batch_size(6).shuffle(false);
    let mut mixed = opts().open(&v.ds.location()).unwrap();
    let mut plain = opts().open(&images.location()).unwrap();
    assert_eq!(
        mixed.info().cameras,
        ["observation.images.top", "observation.images.wrist"]
    );
    let (mut batches, plane) = (0, 3 * 64 * 48);
    while let Some(b) = mixed.next_batch() {
        let (b, p) = (b.unwrap(), plain.next_batch().unwrap().unwrap());
        // The image camera (slot 1) is byte for byte the image dataset's.
        for s in 0..b.len * 2 {
            let at = (s * 2 + 1) * plane;
            assert_eq!(b.images[at..at + plane], p.images[at..at + plane]);
        }
        // The video camera (slot 0) is PyAV's decoding.
        for i in 0..b.len {
            let (e, t) = (b.episode_index[i] as usize, b.frame_index[i] as usize);
            let f = window(v.ds.fixture.lens[e], t, 2, 16, 0).obs[1];
            let (file, t_s) = where_is(&v.ds.fixture, "top", 10, e, f);
            let at = (i * 2 + 1) * 2 * plane;
            assert_eq!(b.images[at..at + plane], v.files[&file].chw_at(t_s)[..]);
        }
        assert_eq!((b.state, b.action), (p.state, p.action));
        batches += 1;
    }
    assert_eq!(batches, 5);
}
