//! Where each episode's video frames are: the `videos/{key}/…` columns of
//! `meta/episodes/**/*.parquet` (LeRobot v3.0, `datasets/utils.py`): per episode and video key
//! the file (`chunk_index`, `file_index`, put into `info.json`'s `video_path`) and the time of
//! the episode's first frame in it (`from_timestamp`; `to_timestamp` ends it). Many episodes
//! share one file, one after another.

use std::collections::HashMap;
use std::sync::atomic::AtomicU64;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int32Type, Int64Type};
use arrow_array::{Array, ArrayRef};
use arrow_schema::DataType;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ProjectionMask;

use crate::error::{Error, Result};
use crate::store::Store;

/// LeRobot's `video_path` when `info.json` gives none.
pub(crate) const DEFAULT_VIDEO_PATH: &str =
    "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4";

/// An episode's frames of one video key.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Segment {
    /// The video file, relative to the dataset root.
    pub file: String,
    /// Time of the episode's frame 0 in the file, seconds.
    pub from_s: f64,
    /// End of the episode in the file, seconds.
    pub to_s: f64,
}

/// `episode_index` → one segment per video key (in the order asked for).
pub(crate) type Segments = HashMap<i64, Vec<Segment>>;

/// Reads the segments of `keys` for every episode listed in `meta/episodes`.
pub(crate) fn read_segments(store: &Store, keys: &[String], video_path: &str) -> Result<Segments> {
    let rels = store.list("meta/episodes", ".parquet")?;
    if rels.is_empty() {
        return Err(Error::format(
            store.describe("meta/episodes"),
            "no episodes metadata (video features need meta/episodes/*.parquet)",
        ));
    }
    let mut out = Segments::new();
    for rel in rels {
        let file = store.file(&rel, Arc::new(AtomicU64::new(0)))?;
        let name = file.name.clone();
        let bad = |e: &dyn std::fmt::Display| Error::format(name.clone(), e);
        let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| bad(&e))?;
        let schema = builder.schema().clone();
        let mut columns = vec!["episode_index".to_string()];
        for key in keys {
            for c in [
                "chunk_index",
                "file_index",
                "from_timestamp",
                "to_timestamp",
            ] {
                columns.push(format!("videos/{key}/{c}"));
            }
        }
        let roots: Vec<usize> = columns
            .iter()
            .map(|c| {
                schema
                    .index_of(c)
                    .map_err(|_| bad(&format!("no column {c}")))
            })
            .collect::<Result<_>>()?;
        let mask = ProjectionMask::roots(builder.parquet_schema(), roots);
        let reader = builder.with_projection(mask).build().map_err(|e| bad(&e))?;
        for batch in reader {
            let batch = batch.map_err(|e| bad(&e))?;
            let col = |c: &str| -> Result<ArrayRef> {
                batch
                    .column_by_name(c)
                    .cloned()
                    .ok_or_else(|| bad(&format!("no column {c}")))
            };
            let episodes =
                numbers(&col("episode_index")?).map_err(|e| bad(&format!("episode_index: {e}")))?;
            let mut per_key = Vec::new();
            for key in keys {
                let get = |c: &str| {
                    let name = format!("videos/{key}/{c}");
                    numbers(&col(&name)?).map_err(|e| bad(&format!("{name}: {e}")))
                };
                per_key.push([
                    get("chunk_index")?,
                    get("file_index")?,
                    get("from_timestamp")?,
                    get("to_timestamp")?,
                ]);
            }
            for (row, &ep) in episodes.iter().enumerate() {
                let mut segs = Vec::with_capacity(keys.len());
                for (key, [chunk, file, from, to]) in keys.iter().zip(&per_key) {
                    let (from_s, to_s) = (from[row], to[row]);
                    if !(from_s.is_finite() && to_s.is_finite() && from_s >= 0.0) {
                        return Err(bad(&format!(
                            "episode {ep}: {key} from_timestamp {from_s} / to_timestamp {to_s}"
                        )));
                    }
                    let file = format_path(video_path, key, chunk[row] as i64, file[row] as i64)
                        .map_err(|e| bad(&e))?;
                    segs.push(Segment { file, from_s, to_s });
                }
                out.insert(ep as i64, segs);
            }
        }
    }
    Ok(out)
}

/// A numeric column as f64 (integers are exact far beyond any index).
fn numbers(a: &ArrayRef) -> std::result::Result<Vec<f64>, String> {
    if a.null_count() > 0 {
        return Err("null values".into());
    }
    Ok(match a.data_type() {
        DataType::Int64 => a
            .as_primitive::<Int64Type>()
            .values()
            .iter()
            .map(|&v| v as f64)
            .collect(),
        DataType::Int32 => a
            .as_primitive::<Int32Type>()
            .values()
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
        DataType::Float64 => a.as_primitive::<Float64Type>().values().to_vec(),
        DataType::Float32 => a
            .as_primitive::<Float32Type>()
            .values()
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
        other => return Err(format!("type {other}, expected a number")),
    })
}

/// Fills LeRobot's path template (Python format fields `{video_key}`, `{chunk_index:03d}`,
/// `{file_index:03d}`).
pub(crate) fn format_path(
    template: &str,
    key: &str,
    chunk: i64,
    file: i64,
) -> std::result::Result<String, String> {
    if chunk < 0 || file < 0 {
        return Err(format!("{key}: chunk_index {chunk} / file_index {file}"));
    }
    let mut out = String::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let close = rest[open..]
            .find('}')
            .ok_or_else(|| format!("video_path '{template}': unclosed field"))?;
        let field = &rest[open + 1..open + close];
        let (name, spec) = field.split_once(':').unwrap_or((field, ""));
        let value = match name {
            "video_key" => key.to_string(),
            "chunk_index" => chunk.to_string(),
            "file_index" => file.to_string(),
            other => return Err(format!("video_path '{template}': unknown field {other}")),
        };
        let width: usize = spec
            .strip_prefix('0')
            .and_then(|s| s.strip_suffix('d'))
            .and_then(|s| s.parse().ok())
            .unwrap_or(0);
        out.push_str(&format!("{value:0>width$}"));
        rest = &rest[open + close + 1..];
    }
    out.push_str(rest);
    Ok(out)
}
