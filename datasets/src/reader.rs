//! The data files of a dataset: at open, the small per-frame columns (episode and frame
//! indices, state, action) of every file are read into memory; encoded images are read on
//! demand, only the pages that hold the requested rows (page index + row selection), only the
//! requested camera columns.

use std::ops::Range;
use std::sync::atomic::AtomicU64;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int64Type};
use arrow_array::{Array, ArrayRef, RecordBatch, StructArray};
use arrow_schema::DataType;
use parquet::arrow::arrow_reader::{
    ArrowReaderMetadata, ArrowReaderOptions, ParquetRecordBatchReaderBuilder, RowSelection,
    RowSelectionPolicy, RowSelector,
};
use parquet::arrow::ProjectionMask;

use crate::error::{Error, Result};
use crate::store::{DataFile, Store};

/// One data file and its parsed footer (with page index), shared by every read.
pub(crate) struct FileEntry {
    pub file: DataFile,
    meta: ArrowReaderMetadata,
    /// First row of each row group, and the file's row count at the end.
    rg_starts: Vec<usize>,
}

/// An episode: its rows in one data file, and where its state/action rows start in memory.
#[derive(Clone, Debug)]
pub(crate) struct EpisodeRows {
    pub episode_index: i64,
    pub file: usize,
    pub first_row: usize,
    pub len: usize,
    /// Row of frame 0 in the in-memory state / action arrays.
    pub offset: usize,
}

/// Every data file, every episode, and the state / action of every frame.
pub(crate) struct Data {
    pub files: Vec<FileEntry>,
    pub episodes: Vec<EpisodeRows>,
    pub state: Vec<f32>,
    pub action: Vec<f32>,
    /// `timestamp` of every frame (same rows as `state`), when every data file has the column:
    /// video frames are found by it.
    pub timestamp: Option<Vec<f32>>,
    pub state_dim: usize,
    pub action_dim: usize,
    /// Rows read so far over all files.
    rows: usize,
}

impl Data {
    /// Opens every `data/**.parquet` file and reads its small columns.
    pub fn open(
        store: &Store,
        state_key: &str,
        action_key: &str,
        counter: Arc<AtomicU64>,
    ) -> Result<Self> {
        let rels = store.list("data", ".parquet")?;
        if rels.is_empty() {
            return Err(Error::format(
                store.describe("data"),
                "no parquet data files",
            ));
        }
        let mut data = Data {
            files: Vec::new(),
            episodes: Vec::new(),
            state: Vec::new(),
            action: Vec::new(),
            timestamp: Some(Vec::new()),
            state_dim: 0,
            action_dim: 0,
            rows: 0,
        };
        for rel in &rels {
            let file = store.file(rel, counter.clone())?;
            let name = file.name.clone();
            let bad = |e: &dyn std::fmt::Display| Error::format(name.clone(), e);
            // Read when the file has one (ours do; other writers may not).
            let options = ArrowReaderOptions::new()
                .with_page_index_policy(parquet::file::metadata::PageIndexPolicy::Optional);
            let meta = ArrowReaderMetadata::load(&file, options).map_err(|e| bad(&e))?;
            let mut rg_starts = vec![0usize];
            for rg in meta.metadata().row_groups() {
                let last = rg_starts.last().copied().unwrap_or(0);
                rg_starts.push(last + rg.num_rows() as usize);
            }
            let entry = FileEntry {
                file,
                meta,
                rg_starts,
            };
            let index = data.files.len();
            data.read_small(&entry, index, state_key, action_key)?;
            data.files.push(entry);
        }
        data.episodes.sort_by_key(|e| e.episode_index);
        for w in data.episodes.windows(2) {
            if w[0].episode_index == w[1].episode_index {
                return Err(Error::format(
                    data.files[w[1].file].file.name.clone(),
                    format!(
                        "episode {} is split across data files or row ranges",
                        w[1].episode_index
                    ),
                ));
            }
        }
        Ok(data)
    }

    fn read_small(
        &mut self,
        entry: &FileEntry,
        index: usize,
        state_key: &str,
        action_key: &str,
    ) -> Result<()> {
        let name = &entry.file.name;
        let bad = |e: &dyn std::fmt::Display| Error::format(name.clone(), e);
        let schema = entry.meta.schema().clone();
        let has_ts = schema.index_of("timestamp").is_ok();
        let mut keys = vec!["episode_index", "frame_index", state_key, action_key];
        if has_ts {
            keys.push("timestamp");
        } else {
            self.timestamp = None;
        }
        let roots: Vec<usize> = keys
            .iter()
            .map(|k| {
                schema
                    .index_of(k)
                    .map_err(|_| Error::format(name.clone(), format!("no column {k}")))
            })
            .collect::<Result<_>>()?;
        let mask = ProjectionMask::roots(entry.meta.parquet_schema(), roots);
        let reader = ParquetRecordBatchReaderBuilder::new_with_metadata(
            entry.file.clone(),
            entry.meta.clone(),
        )
        .with_projection(mask)
        .with_batch_size(8192)
        .build()
        .map_err(|e| bad(&e))?;
        let mut row = 0usize;
        for batch in reader {
            let batch = batch.map_err(|e| bad(&e))?;
            let col = |k: &str| {
                batch
                    .column_by_name(k)
                    .cloned()
                    .ok_or_else(|| bad(&format!("no column {k}")))
            };
            let ep =
                ints(&col("episode_index")?).map_err(|e| bad(&format!("episode_index: {e}")))?;
            let fr = ints(&col("frame_index")?).map_err(|e| bad(&format!("frame_index: {e}")))?;
            let sd = floats(&col(state_key)?, &mut self.state)
                .map_err(|e| bad(&format!("{state_key}: {e}")))?;
            let ad = floats(&col(action_key)?, &mut self.action)
                .map_err(|e| bad(&format!("{action_key}: {e}")))?;
            if let Some(ts) = self.timestamp.as_mut() {
                let col = col("timestamp")?;
                timestamps(&col, ts).map_err(|e| bad(&format!("timestamp: {e}")))?;
            }
            for (dim, seen) in [(sd, &mut self.state_dim), (ad, &mut self.action_dim)] {
                if *seen != 0 && *seen != dim {
                    return Err(bad(&format!("vector width {dim}, other files have {seen}")));
                }
                *seen = dim;
            }
            for (i, (&e, &f)) in ep.iter().zip(&fr).enumerate() {
                let file_row = row + i;
                let offset = self.rows + i;
                match self.episodes.last_mut() {
                    Some(last) if last.file == index && last.episode_index == e => {
                        if f != last.len as i64 {
                            return Err(bad(&format!(
                                "episode {e}: frame_index {f} at row {file_row}, expected {}",
                                last.len
                            )));
                        }
                        last.len += 1;
                    }
                    _ => {
                        if f != 0 {
                            return Err(bad(&format!(
                                "episode {e} starts at frame_index {f}, not 0"
                            )));
                        }
                        self.episodes.push(EpisodeRows {
                            episode_index: e,
                            file: index,
                            first_row: file_row,
                            len: 1,
                            offset,
                        });
                    }
                }
            }
            row += ep.len();
            self.rows += ep.len();
        }
        Ok(())
    }

    /// Rows `rows` of one file, the columns of `mask`: only the pages holding those rows are
    /// read (page index + row selection); a range may cross row groups (one read each).
    pub fn read_rows(
        &self,
        file: usize,
        rows: Range<usize>,
        mask: ProjectionMask,
    ) -> Result<Vec<RecordBatch>> {
        let entry = &self.files[file];
        let bad = |e: &dyn std::fmt::Display| Error::format(entry.file.name.clone(), e);
        let mut out = Vec::new();
        let mut start = rows.start;
        while start < rows.end {
            let rg = entry.rg_starts.partition_point(|&s| s <= start) - 1;
            let rg_end = entry
                .rg_starts
                .get(rg + 1)
                .copied()
                .unwrap_or(rows.end)
                .min(rows.end);
            let skip = start - entry.rg_starts[rg];
            let take = rg_end - start;
            let selection =
                RowSelection::from(vec![RowSelector::skip(skip), RowSelector::select(take)]);
            let reader = ParquetRecordBatchReaderBuilder::new_with_metadata(
                entry.file.clone(),
                entry.meta.clone(),
            )
            .with_projection(mask.clone())
            .with_row_groups(vec![rg])
            .with_row_selection(selection)
            .with_row_selection_policy(RowSelectionPolicy::Selectors)
            .with_batch_size(take.max(1))
            .build()
            .map_err(|e| bad(&e))?;
            for batch in reader {
                out.push(batch.map_err(|e| bad(&e))?);
            }
            start = rg_end;
        }
        Ok(out)
    }

    /// The Parquet schema of file `file`, for projections.
    pub fn parquet_schema(&self, file: usize) -> &parquet::schema::types::SchemaDescriptor {
        self.files[file].meta.parquet_schema()
    }

    /// Encoded images of rows `rows` (of one file) for the image columns `cams` (root keys):
    /// one array of `bytes` per camera, in `cams` order.
    pub fn read_images(
        &self,
        file: usize,
        rows: Range<usize>,
        cams: &[String],
    ) -> Result<Vec<ImageColumn>> {
        let entry = &self.files[file];
        let name = &entry.file.name;
        let bad = |e: &dyn std::fmt::Display| Error::format(name.clone(), e);
        let pschema = entry.meta.parquet_schema();
        let leaves: Vec<usize> = cams
            .iter()
            .map(|cam| {
                (0..pschema.num_columns())
                    .find(|&i| {
                        let p = pschema.column(i).path().parts().to_vec();
                        p.len() == 2 && p[0] == *cam && p[1] == "bytes"
                    })
                    .ok_or_else(|| bad(&format!("no image column {cam}.bytes")))
            })
            .collect::<Result<_>>()?;
        let mut out: Vec<Vec<ArrayRef>> = vec![Vec::new(); cams.len()];
        let mask = ProjectionMask::leaves(pschema, leaves.iter().copied());
        for batch in self.read_rows(file, rows.clone(), mask)? {
            for (c, cam) in cams.iter().enumerate() {
                let col = batch
                    .column_by_name(cam)
                    .ok_or_else(|| bad(&format!("no image column {cam}")))?;
                let s: &StructArray = col
                    .as_struct_opt()
                    .ok_or_else(|| bad(&format!("{cam} is not an image struct")))?;
                let bytes = s
                    .column_by_name("bytes")
                    .ok_or_else(|| bad(&format!("{cam} has no bytes field")))?;
                out[c].push(bytes.clone());
            }
        }
        out.into_iter()
            .zip(cams)
            .map(|(parts, cam)| {
                ImageColumn::new(parts, rows.len()).map_err(|e| bad(&format!("{cam}: {e}")))
            })
            .collect()
    }
}

/// The encoded images of consecutive rows of one camera.
#[derive(Clone, Debug)]
pub(crate) struct ImageColumn {
    parts: Vec<ArrayRef>,
}

impl ImageColumn {
    fn new(parts: Vec<ArrayRef>, rows: usize) -> std::result::Result<Self, String> {
        let mut n = 0;
        for p in &parts {
            match p.data_type() {
                DataType::Binary | DataType::LargeBinary | DataType::BinaryView => n += p.len(),
                other => return Err(format!("image bytes of type {other}")),
            }
        }
        if n != rows {
            return Err(format!("read {n} images for {rows} rows"));
        }
        Ok(ImageColumn { parts })
    }

    /// The encoded image of row `i` (relative to the first row read); None for a null image.
    pub fn get(&self, mut i: usize) -> Option<&[u8]> {
        for p in &self.parts {
            if i < p.len() {
                if p.is_null(i) {
                    return None;
                }
                return Some(match p.data_type() {
                    DataType::Binary => p.as_binary::<i32>().value(i),
                    DataType::LargeBinary => p.as_binary::<i64>().value(i),
                    _ => p.as_binary_view().value(i),
                });
            }
            i -= p.len();
        }
        None
    }
}

/// Appends a `timestamp` column (float32, or float64 as some writers store it) to `out`.
fn timestamps(a: &ArrayRef, out: &mut Vec<f32>) -> std::result::Result<(), String> {
    if a.null_count() > 0 {
        return Err("null values".into());
    }
    match a.data_type() {
        DataType::Float32 => out.extend_from_slice(a.as_primitive::<Float32Type>().values()),
        DataType::Float64 => out.extend(
            a.as_primitive::<Float64Type>()
                .values()
                .iter()
                .map(|&v| v as f32),
        ),
        other => return Err(format!("type {other}, expected float32")),
    }
    Ok(())
}

fn ints(a: &ArrayRef) -> std::result::Result<Vec<i64>, String> {
    if a.null_count() > 0 {
        return Err("null values".into());
    }
    match a.data_type() {
        DataType::Int64 => Ok(a.as_primitive::<Int64Type>().values().to_vec()),
        DataType::Int32 => Ok(a
            .as_primitive::<arrow_array::types::Int32Type>()
            .values()
            .iter()
            .map(|&v| i64::from(v))
            .collect()),
        other => Err(format!("type {other}, expected int64")),
    }
}

/// Appends a vector column's values (fixed-size or variable lists of float32/float64) to `out`;
/// returns the width.
fn floats(a: &ArrayRef, out: &mut Vec<f32>) -> std::result::Result<usize, String> {
    if a.null_count() > 0 {
        return Err("null values".into());
    }
    let (values, width): (ArrayRef, usize) = match a.data_type() {
        DataType::FixedSizeList(_, w) => {
            let l = a.as_fixed_size_list();
            (
                l.values()
                    .slice(l.offset() * *w as usize, l.len() * *w as usize),
                *w as usize,
            )
        }
        DataType::List(_) => {
            let l = a.as_list::<i32>();
            let offs = l.value_offsets();
            let w = if l.is_empty() {
                0
            } else {
                (offs[1] - offs[0]) as usize
            };
            if offs.windows(2).any(|p| (p[1] - p[0]) as usize != w) {
                return Err("rows of different lengths".into());
            }
            let start = offs[0] as usize;
            (l.values().slice(start, l.len() * w), w)
        }
        other => return Err(format!("type {other}, expected a list of floats")),
    };
    match values.data_type() {
        DataType::Float32 => out.extend_from_slice(values.as_primitive::<Float32Type>().values()),
        DataType::Float64 => out.extend(
            values
                .as_primitive::<Float64Type>()
                .values()
                .iter()
                .map(|&v| v as f32),
        ),
        other => return Err(format!("values of type {other}, expected float32")),
    }
    Ok(width)
}
