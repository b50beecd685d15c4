//! Tiny LeRobot v3.0 datasets written at test time (the layout `scaledp convert` writes, after
//! datasets/tests/common/mod.rs), and tiny training options.
#![allow(dead_code, clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{FixedSizeListBuilder, Float32Builder};
use arrow_array::{
    ArrayRef, BinaryArray, Float32Array, Int64Array, RecordBatch, StringArray, StructArray,
};
use arrow_schema::{DataType, Field, Fields};
use parquet::arrow::ArrowWriter;
use scaledp_policy::TrainOptions;

/// What to write.
#[derive(Clone, Debug)]
pub struct Fixture {
    /// Frames of each episode.
    pub lens: Vec<usize>,
    /// Camera short names.
    pub cameras: Vec<String>,
    /// Image width and height.
    pub size: (u32, u32),
    /// State and action widths.
    pub state_dim: usize,
    pub action_dim: usize,
    /// Put a NaN in this (episode, frame)'s state.
    pub nan_at: Option<(usize, usize)>,
}

impl Default for Fixture {
    fn default() -> Self {
        Fixture {
            lens: vec![12, 10, 9],
            cameras: vec!["front".into(), "wrist".into()],
            size: (20, 16),
            state_dim: 3,
            action_dim: 2,
            nan_at: None,
        }
    }
}

/// A smooth action trajectory: what the policy should learn.
pub fn action(e: usize, f: usize, d: usize) -> f32 {
    let t = f as f32 * 0.3 + e as f32;
    match d % 3 {
        0 => t.sin() * 0.5 + e as f32 * 0.1,
        1 => t.cos() * 0.2 - 0.05 * d as f32,
        _ => 0.02 * f as f32,
    }
}

/// The state: the current action plus a per-dimension offset.
pub fn state(e: usize, f: usize, d: usize) -> f32 {
    action(e, f, d % 2) + 0.1 * d as f32 + 0.01 * e as f32
}

fn png(w: u32, h: u32, e: usize, f: usize, c: usize) -> Vec<u8> {
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        let v = ((x as usize * 7 + y as usize * 3 + f * 11 + e * 29 + c * 53) % 256) as u8;
        image::Rgb([v, (f * 20 % 256) as u8, (x * 10 % 256) as u8])
    });
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

fn vectors(
    rows: &[(usize, usize)],
    dim: usize,
    f: impl Fn(usize, usize, usize) -> f32,
) -> ArrayRef {
    let mut b = FixedSizeListBuilder::new(Float32Builder::new(), dim as i32);
    for &(e, fr) in rows {
        for d in 0..dim {
            b.values().append_value(f(e, fr, d));
        }
        b.append(true);
    }
    Arc::new(b.finish())
}

/// A dataset on disk.
pub struct Written {
    pub dir: tempfile::TempDir,
    pub root: PathBuf,
}

impl Written {
    pub fn location(&self) -> String {
        self.root.display().to_string()
    }
}

/// Writes `fx` as a one-file LeRobot v3.0 dataset.
pub fn write(fx: &Fixture) -> Written {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let rows: Vec<(usize, usize)> = fx
        .lens
        .iter()
        .enumerate()
        .flat_map(|(e, &l)| (0..l).map(move |f| (e, f)))
        .collect();
    let mut cols: Vec<(String, ArrayRef)> = Vec::new();
    let (w, h) = fx.size;
    for (c, name) in fx.cameras.iter().enumerate() {
        let fields = Fields::from(vec![
            Field::new("bytes", DataType::Binary, true),
            Field::new("path", DataType::Utf8, true),
        ]);
        let enc: Vec<Vec<u8>> = rows.iter().map(|&(e, f)| png(w, h, e, f, c)).collect();
        let bytes: ArrayRef = Arc::new(BinaryArray::from_iter_values(enc.iter()));
        let paths: ArrayRef = Arc::new(StringArray::from(vec![None::<&str>; rows.len()]));
        cols.push((
            format!("observation.images.{name}"),
            Arc::new(StructArray::new(fields, vec![bytes, paths], None)),
        ));
    }
    let nan = fx.nan_at;
    cols.push((
        "observation.state".into(),
        vectors(&rows, fx.state_dim, |e, f, d| {
            if nan == Some((e, f)) {
                f32::NAN
            } else {
                state(e, f, d)
            }
        }),
    ));
    cols.push(("action".into(), vectors(&rows, fx.action_dim, action)));
    let ts: Vec<f32> = rows.iter().map(|&(_, f)| f as f32 / 10.0).collect();
    cols.push(("timestamp".into(), Arc::new(Float32Array::from(ts))));
    let i64s = |v: Vec<i64>| -> ArrayRef { Arc::new(Int64Array::from(v)) };
    cols.push((
        "frame_index".into(),
        i64s(rows.iter().map(|r| r.1 as i64).collect()),
    ));
    cols.push((
        "episode_index".into(),
        i64s(rows.iter().map(|r| r.0 as i64).collect()),
    ));
    cols.push(("index".into(), i64s((0..rows.len() as i64).collect())));
    cols.push(("task_index".into(), i64s(vec![0; rows.len()])));
    let all = RecordBatch::try_from_iter(cols).unwrap();
    let path = root.join("data/chunk-000/file-000.parquet");
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    let mut wr =
        ArrowWriter::try_new(std::fs::File::create(&path).unwrap(), all.schema(), None).unwrap();
    let mut start = 0;
    for &l in &fx.lens {
        wr.write(&all.slice(start, l)).unwrap();
        wr.flush().unwrap();
        start += l;
    }
    wr.close().unwrap();
    write_meta(fx, &root, &rows);
    Written { dir, root }
}

fn stats(
    rows: &[(usize, usize)],
    dim: usize,
    f: fn(usize, usize, usize) -> f32,
) -> serde_json::Value {
    let col = |d: usize| rows.iter().map(move |&(e, fr)| f64::from(f(e, fr, d)));
    let n = rows.len() as f64;
    let min: Vec<f64> = (0..dim)
        .map(|d| col(d).fold(f64::INFINITY, f64::min))
        .collect();
    let max: Vec<f64> = (0..dim)
        .map(|d| col(d).fold(f64::NEG_INFINITY, f64::max))
        .collect();
    let mean: Vec<f64> = (0..dim).map(|d| col(d).sum::<f64>() / n).collect();
    let std: Vec<f64> = (0..dim)
        .map(|d| (col(d).map(|v| (v - mean[d]).powi(2)).sum::<f64>() / n).sqrt())
        .collect();
    serde_json::json!({"min": min, "max": max, "mean": mean, "std": std, "count": [rows.len()]})
}

fn write_meta(fx: &Fixture, root: &Path, rows: &[(usize, usize)]) {
    let mut features = serde_json::Map::new();
    let (w, h) = fx.size;
    for name in &fx.cameras {
        features.insert(
            format!("observation.images.{name}"),
            serde_json::json!({"dtype": "image", "shape": [h, w, 3], "names": ["height", "width", "channels"]}),
        );
    }
    let names = |p: &str, n: usize| (0..n).map(|i| format!("{p}{i}")).collect::<Vec<_>>();
    features.insert(
        "observation.state".into(),
        serde_json::json!({"dtype": "float32", "shape": [fx.state_dim], "names": names("s", fx.state_dim)}),
    );
    features.insert(
        "action".into(),
        serde_json::json!({"dtype": "float32", "shape": [fx.action_dim], "names": names("a", fx.action_dim)}),
    );
    for k in ["frame_index", "episode_index", "index", "task_index"] {
        features.insert(
            k.into(),
            serde_json::json!({"dtype": "int64", "shape": [1], "names": null}),
        );
    }
    features.insert(
        "timestamp".into(),
        serde_json::json!({"dtype": "float32", "shape": [1], "names": null}),
    );
    let info = serde_json::json!({
        "codebase_version": "v3.0",
        "robot_type": "test_arm",
        "total_episodes": fx.lens.len(),
        "total_frames": rows.len(),
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": 10,
        "splits": {"train": format!("0:{}", fx.lens.len())},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": null,
        "features": features,
        "scaledp": {"rig": "test_rig"},
    });
    let stats = serde_json::json!({
        "observation.state": stats(rows, fx.state_dim, state),
        "action": stats(rows, fx.action_dim, action),
    });
    std::fs::create_dir_all(root.join("meta")).unwrap();
    std::fs::write(
        root.join("meta/info.json"),
        serde_json::to_vec_pretty(&info).unwrap(),
    )
    .unwrap();
    std::fs::write(
        root.join("meta/stats.json"),
        serde_json::to_vec_pretty(&stats).unwrap(),
    )
    .unwrap();
}

/// A tiny model and run: 2-block denoiser of width 32, ResNet trunks of width 8, no
/// validation, one loader thread.
pub fn tiny() -> TrainOptions {
    TrainOptions::default()
        .denoiser(2, 32, 2)
        .resnet_width(8)
        .batch_size(8)
        .steps(4)
        .warmup_steps(2)
        .val_ratio(0.0)
        .val_every(0)
        .checkpoint_every(0)
        .loader_threads(1)
        .obs_horizon(2)
        .action_chunk(4)
}
