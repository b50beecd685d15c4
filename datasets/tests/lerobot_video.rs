//! Conformance with LeRobot 0.4.4 itself (the LeRobot venv of scripts/setup-bench-python.sh):
//! a video dataset written by LeRobot's own writer (`LeRobotDataset.create` … `finalize`, its
//! `encode_video_frames`: libsvtav1, yuv420p, g=2, crf=30) is read by our loader, and every
//! frame of every camera equals what `LeRobotDataset[i]` returns for the same episode and
//! frame (pyav backend, scaled back to 0-255): tolerance 0, bit for bit.
#![allow(clippy::unwrap_used)]

use scaledp_datasets::LoaderOptions;
use scaledp_testkit::lerobot_video as lerobot;

#[test]
fn frames_equal_lerobot_datasets_own_for_a_dataset_lerobot_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let ds = dir.path().join("ds");
    let bin = dir.path().join("frames.bin");
    let (ds_s, bin_s) = (ds.to_str().unwrap(), bin.to_str().unwrap());
    lerobot(&["write", ds_s], dir.path());
    let theirs = lerobot(&["read", ds_s, bin_s], dir.path());
    let frames = std::fs::read(&bin).unwrap();
    let (h, w) = (48usize, 64usize);
    let keys: Vec<&str> = theirs["keys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap())
        .collect();
    let n = theirs["frames"].as_u64().unwrap() as usize;
    assert_eq!(frames.len(), n * keys.len() * h * w * 3);
    let index: Vec<(i64, i64)> = (0..n)
        .map(|i| {
            (
                theirs["episode_index"][i].as_i64().unwrap(),
                theirs["frame_index"][i].as_i64().unwrap(),
            )
        })
        .collect();
    let mut l = LoaderOptions::default()
        .obs_horizon(1)
        .action_chunk(1)
        .shuffle(false)
        .batch_size(n)
        .cameras(keys.iter().map(|k| k.to_string()).collect())
        .open(ds_s)
        .unwrap();
    let b = l.next_batch().unwrap().unwrap();
    assert_eq!(b.len, n);
    let plane = h * w;
    let mut compared = 0;
    for i in 0..n {
        let at = index
            .iter()
            .position(|&x| x == (b.episode_index[i], b.frame_index[i]))
            .unwrap();
        for (c, key) in keys.iter().enumerate() {
            let ours = &b.images[(i * keys.len() + c) * 3 * plane..][..3 * plane];
            let theirs = &frames[(at * keys.len() + c) * 3 * plane..][..3 * plane];
            let max = (0..plane * 3)
                .map(|j| {
                    let (p, ch) = (j / 3, j % 3);
                    (i32::from(ours[ch * plane + p]) - i32::from(theirs[j])).abs()
                })
                .max()
                .unwrap();
            assert_eq!(
                max, 0,
                "episode {} frame {} {key}: ours differ from LeRobot's by up to {max}",
                b.episode_index[i], b.frame_index[i]
            );
            compared += 1;
        }
    }
    assert_eq!(compared, n * 2);
}
