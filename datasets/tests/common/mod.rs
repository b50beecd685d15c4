//! Hand-built LeRobot v3.0 datasets for the loader's tests: every value says which episode and
//! frame it belongs to, so a batch can be checked against the window it should hold.
//!
//! Files are written like `scaledp convert` writes them (see converter/src/lerobot/columns.rs):
//! snappy, 2 KiB pages checked every row (a page per image), image bytes uncompressed without dictionary or
//! statistics, one row group per episode — or, to test other writers, fixed-size row groups that
//! cross episodes, `List<f32>` vectors, or no page index.
#![allow(dead_code, clippy::unwrap_used)]

pub mod video;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow_array::builder::{FixedSizeListBuilder, Float32Builder, ListBuilder};
use arrow_array::{
    ArrayRef, BinaryArray, Float32Array, Int64Array, RecordBatch, StringArray, StructArray,
};
use arrow_schema::{DataType, Field, Fields};
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;

/// `observation.state[d]` of frame `f` of episode `e`: exact in f32.
pub fn state_value(e: usize, f: usize, d: usize) -> f32 {
    (e * 1000 + f) as f32 + d as f32 * 0.125
}

/// `action[d]` of frame `f` of episode `e`.
pub fn action_value(e: usize, f: usize, d: usize) -> f32 {
    -((e * 1000 + f) as f32) - d as f32 * 0.25
}

/// The solid colour of camera `c`'s image of frame `f` of episode `e`: steps of 8 so that JPEG's
/// errors (±3 on saturated colours) still decode to the right (episode, frame), both modulo 32.
pub fn pixel(e: usize, f: usize, c: usize) -> [u8; 3] {
    [
        ((f % 32) * 8) as u8,
        ((e % 32) * 8) as u8,
        (c * 64 + 32) as u8,
    ]
}

/// (episode % 32, frame % 32) read back from a decoded pixel.
pub fn decode_pixel(rgb: [u8; 3]) -> (usize, usize) {
    let q = |v: u8| ((f32::from(v) / 8.0).round()) as usize % 32;
    (q(rgb[1]), q(rgb[0]))
}

/// What to write.
#[derive(Clone, Debug)]
pub struct Fixture {
    /// Frames of each episode (episode_index = position).
    pub lens: Vec<usize>,
    /// Episodes per data file.
    pub episodes_per_file: usize,
    /// None: one row group per episode (the converter); Some(n): row groups of n rows.
    pub row_group_rows: Option<usize>,
    /// (short name, width, height) per camera.
    pub cameras: Vec<(String, u32, u32)>,
    /// PNG (lossless) instead of JPEG.
    pub png: bool,
    /// Noise in images (makes JPEGs a realistic few KB instead of a few hundred bytes).
    pub noise: bool,
    /// `List<f32>` vectors (what some LeRobot versions write) instead of `FixedSizeList`.
    pub list_vectors: bool,
    /// Write the page index (offset + column index); pyarrow does not by default.
    pub page_index: bool,
    /// 64 KiB pages checked every 8 rows (several frames per page, as other writers do) instead
    /// of the converter's 2 KiB checked every row (a page per frame).
    pub big_pages: bool,
    /// State width.
    pub state_dim: usize,
    /// Action width.
    pub action_dim: usize,
}

impl Default for Fixture {
    fn default() -> Self {
        Fixture {
            lens: vec![5, 1, 3, 12, 2, 7],
            episodes_per_file: 4,
            row_group_rows: None,
            cameras: vec![("top".into(), 16, 12), ("wrist".into(), 16, 12)],
            png: true,
            noise: false,
            list_vectors: false,
            page_index: true,
            big_pages: false,
            state_dim: 3,
            action_dim: 2,
        }
    }
}

/// A dataset on disk and what it holds.
pub struct Written {
    /// Keeps the directory alive.
    pub dir: tempfile::TempDir,
    /// The dataset root.
    pub root: PathBuf,
    /// The fixture it was written from.
    pub fixture: Fixture,
    /// Data files, relative to the root.
    pub files: Vec<String>,
}

impl Written {
    /// The root as the loader's location string.
    pub fn location(&self) -> String {
        self.root.display().to_string()
    }
}

fn image(w: u32, h: u32, rgb: [u8; 3], noise: bool, seed: usize, png: bool) -> Vec<u8> {
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb(rgb));
    if noise {
        let mut s = seed as u32 * 2_654_435_761 + 12345;
        for p in img.pixels_mut() {
            for v in p.0.iter_mut() {
                s = s.wrapping_mul(1_103_515_245).wrapping_add(12345);
                *v = (s >> 16) as u8;
            }
        }
    }
    let mut out = std::io::Cursor::new(Vec::new());
    let format = if png {
        image::ImageFormat::Png
    } else {
        image::ImageFormat::Jpeg
    };
    img.write_to(&mut out, format).unwrap();
    out.into_inner()
}

fn vectors(
    rows: &[(usize, usize)],
    dim: usize,
    list: bool,
    f: fn(usize, usize, usize) -> f32,
) -> ArrayRef {
    if list {
        let mut b = ListBuilder::new(Float32Builder::new());
        for &(e, fr) in rows {
            for d in 0..dim {
                b.values().append_value(f(e, fr, d));
            }
            b.append(true);
        }
        Arc::new(b.finish())
    } else {
        let mut b = FixedSizeListBuilder::new(Float32Builder::new(), dim as i32);
        for &(e, fr) in rows {
            for d in 0..dim {
                b.values().append_value(f(e, fr, d));
            }
            b.append(true);
        }
        Arc::new(b.finish())
    }
}

fn image_column(encoded: Vec<Vec<u8>>) -> ArrayRef {
    let fields = Fields::from(vec![
        Field::new("bytes", DataType::Binary, true),
        Field::new("path", DataType::Utf8, true),
    ]);
    let n = encoded.len();
    let bytes: ArrayRef = Arc::new(BinaryArray::from_iter_values(encoded.iter()));
    let paths: ArrayRef = Arc::new(StringArray::from(vec![None::<&str>; n]));
    Arc::new(StructArray::new(fields, vec![bytes, paths], None))
}

fn properties(fx: &Fixture, batch: &RecordBatch) -> WriterProperties {
    let mut b = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_data_page_size_limit(if fx.big_pages { 64 << 10 } else { 2 << 10 })
        .set_write_batch_size(if fx.big_pages { 8 } else { 1 })
        .set_max_row_group_row_count(Some(fx.row_group_rows.unwrap_or(1 << 20)));
    if !fx.page_index {
        b = b
            .set_statistics_enabled(EnabledStatistics::None)
            .set_offset_index_disabled(true);
    }
    for f in batch.schema().fields() {
        if matches!(f.data_type(), DataType::Struct(_)) {
            let col = ColumnPath::new(vec![f.name().clone(), "bytes".into()]);
            b = b
                .set_column_compression(col.clone(), Compression::UNCOMPRESSED)
                .set_column_dictionary_enabled(col.clone(), false)
                .set_column_statistics_enabled(col, EnabledStatistics::None);
        }
    }
    b.build()
}

/// Writes the data files of `fx` (one per `episodes_per_file` episodes) and its meta files.
pub fn write(fx: &Fixture) -> Written {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let mut files = Vec::new();
    let mut global = 0usize;
    let episodes: Vec<usize> = (0..fx.lens.len()).collect();
    for (file_no, eps) in episodes.chunks(fx.episodes_per_file.max(1)).enumerate() {
        let rows: Vec<(usize, usize)> = eps
            .iter()
            .flat_map(|&e| (0..fx.lens[e]).map(move |f| (e, f)))
            .collect();
        let mut cols: Vec<(String, ArrayRef)> = Vec::new();
        for (c, (name, w, h)) in fx.cameras.iter().enumerate() {
            let enc = rows
                .iter()
                .map(|&(e, f)| {
                    image(
                        *w,
                        *h,
                        pixel(e, f, c),
                        fx.noise,
                        e * 100_000 + f * 10 + c,
                        fx.png,
                    )
                })
                .collect();
            cols.push((format!("observation.images.{name}"), image_column(enc)));
        }
        cols.push((
            "observation.state".into(),
            vectors(&rows, fx.state_dim, fx.list_vectors, state_value),
        ));
        cols.push((
            "action".into(),
            vectors(&rows, fx.action_dim, fx.list_vectors, action_value),
        ));
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
        cols.push((
            "index".into(),
            i64s((global..global + rows.len()).map(|i| i as i64).collect()),
        ));
        cols.push(("task_index".into(), i64s(vec![0; rows.len()])));
        global += rows.len();
        let all = RecordBatch::try_from_iter(cols).unwrap();
        let rel = format!("data/chunk-000/file-{file_no:03}.parquet");
        let path = root.join(&rel);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let props = properties(fx, &all);
        let mut w = ArrowWriter::try_new(
            std::fs::File::create(&path).unwrap(),
            all.schema(),
            Some(props),
        )
        .unwrap();
        if fx.row_group_rows.is_some() {
            w.write(&all).unwrap();
        } else {
            let mut start = 0;
            for &e in eps {
                w.write(&all.slice(start, fx.lens[e])).unwrap();
                w.flush().unwrap();
                start += fx.lens[e];
            }
        }
        w.close().unwrap();
        files.push(rel);
    }
    write_meta(fx, &root);
    Written {
        dir,
        root,
        fixture: fx.clone(),
        files,
    }
}

fn stats_of(rows: &[Vec<f64>]) -> serde_json::Value {
    let dim = rows.first().map_or(0, Vec::len);
    let n = rows.len() as f64;
    let col = |d: usize| rows.iter().map(move |r| r[d]);
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

/// `meta/info.json` and `meta/stats.json` as LeRobot writes them.
pub fn write_meta(fx: &Fixture, root: &Path) {
    let mut features = serde_json::Map::new();
    for (name, w, h) in &fx.cameras {
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
    let total: usize = fx.lens.iter().sum();
    let info = serde_json::json!({
        "codebase_version": "v3.0",
        "robot_type": "test",
        "total_episodes": fx.lens.len(),
        "total_frames": total,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": 10,
        "splits": {"train": format!("0:{}", fx.lens.len())},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": null,
        "features": features,
    });
    let rows = |dim: usize, f: fn(usize, usize, usize) -> f32| -> Vec<Vec<f64>> {
        fx.lens
            .iter()
            .enumerate()
            .flat_map(|(e, &l)| {
                (0..l).map(move |fr| (0..dim).map(|d| f64::from(f(e, fr, d))).collect())
            })
            .collect()
    };
    let mut stats = BTreeMap::new();
    stats.insert(
        "observation.state",
        stats_of(&rows(fx.state_dim, state_value)),
    );
    stats.insert("action", stats_of(&rows(fx.action_dim, action_value)));
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

/// Every sample of a loader's epoch as (episode_index, frame_index), batch after batch.
pub fn samples_of(loader: &mut scaledp_datasets::Loader) -> Vec<(i64, i64)> {
    let mut out = Vec::new();
    for b in loader.iter() {
        let b = b.unwrap();
        out.extend(
            b.episode_index
                .iter()
                .copied()
                .zip(b.frame_index.iter().copied()),
        );
    }
    out
}
