//! Video datasets for the loader's tests: a [`super::Fixture`] written with images, then its
//! cameras turned into LeRobot video features by `tests/py/make_video_dataset.py` (PyAV with
//! LeRobot's encoder settings), with what LeRobot's pyav backend decodes from each file.

use std::collections::BTreeMap;
use std::path::Path;

use super::{write, Fixture, Written};

/// One video file as PyAV decodes it.
pub struct RefFile {
    pub times: Vec<f64>,
    pub width: usize,
    pub height: usize,
    /// frames × H × W × 3, interleaved RGB.
    pub rgb: Vec<u8>,
}

impl RefFile {
    /// Frame shown nearest to `t_s` as channel-first RGB.
    pub fn chw_at(&self, t_s: f64) -> Vec<u8> {
        let i = (0..self.times.len())
            .min_by(|&a, &b| {
                (self.times[a] - t_s)
                    .abs()
                    .total_cmp(&(self.times[b] - t_s).abs())
            })
            .unwrap();
        assert!((self.times[i] - t_s).abs() < 1e-4, "no frame at {t_s}");
        let plane = self.width * self.height;
        let frame = &self.rgb[i * plane * 3..(i + 1) * plane * 3];
        let mut out = vec![0u8; plane * 3];
        for p in 0..plane {
            for c in 0..3 {
                out[c * plane + p] = frame[p * 3 + c];
            }
        }
        out
    }
}

/// A video dataset and PyAV's decoding of its files.
pub struct VideoWritten {
    pub ds: Written,
    /// Keeps the reference directory alive.
    pub _refs: tempfile::TempDir,
    /// By file path relative to the dataset root.
    pub files: BTreeMap<String, RefFile>,
}

/// Writes `fx` and turns the cameras `keys` (short names) into video features of `codec`,
/// `per_file` episodes per video file, `gop` frames per group of pictures.
pub fn write_video(
    fx: &Fixture,
    keys: &[&str],
    codec: &str,
    per_file: usize,
    gop: usize,
) -> VideoWritten {
    let ds = write(fx);
    let refs = tempfile::tempdir().unwrap();
    let keys = keys.join(",");
    let per_file = per_file.to_string();
    let gop = gop.to_string();
    let out = scaledp_testkit::run_python(
        "make_video_dataset.py",
        &[
            &ds.root,
            refs.path(),
            Path::new("--keys"),
            Path::new(&keys),
            Path::new("--codec"),
            Path::new(codec),
            Path::new("--episodes-per-file"),
            Path::new(&per_file),
            Path::new("--gop"),
            Path::new(&gop),
        ],
    );
    let mut files = BTreeMap::new();
    for (rel, f) in out["files"].as_object().unwrap() {
        files.insert(
            rel.clone(),
            RefFile {
                times: f["times"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|t| t.as_f64().unwrap())
                    .collect(),
                width: f["width"].as_u64().unwrap() as usize,
                height: f["height"].as_u64().unwrap() as usize,
                rgb: std::fs::read(f["rgb"].as_str().unwrap()).unwrap(),
            },
        );
    }
    VideoWritten {
        ds,
        _refs: refs,
        files,
    }
}

/// The file and time of frame `f` of episode `e` of camera `key` (short name): episodes
/// are `per_file` to a file, each frame 1/fps after the last (fixture timestamps are f/10).
pub fn where_is(fx: &Fixture, key: &str, per_file: usize, e: usize, f: usize) -> (String, f64) {
    let file = e / per_file;
    let before: usize = fx.lens[file * per_file..e].iter().sum();
    (
        format!("videos/observation.images.{key}/chunk-000/file-{file:03}.mp4"),
        before as f64 / 10.0 + f64::from(f as f32 / 10.0),
    )
}
