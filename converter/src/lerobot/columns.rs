//! Arrow columns in the exact shapes LeRobot v3.0 writes (see `tests/fixtures/lerobot_v3_example`):
//! vectors as `fixed_size_list<element: float>[N]`, images as `struct<bytes: binary, path:
//! string>`, lists with an `element` child, snappy-compressed Parquet, one row group per episode.

use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use arrow_array::builder::{ListBuilder, StringBuilder};
use arrow_array::{
    ArrayRef, BinaryArray, FixedSizeListArray, Float32Array, Float64Array, Int64Array,
    LargeStringArray, ListArray, RecordBatch, StringArray, StructArray,
};
use arrow_buffer::OffsetBuffer;
use arrow_schema::{DataType, Field, Fields, Schema};
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;

use crate::error::{Error, Result};

/// `fixed_size_list<element: float>[dim]` from row-major values.
pub fn fixed_f32(values: &[f32], dim: usize) -> ArrayRef {
    let field = Arc::new(Field::new("element", DataType::Float32, true));
    Arc::new(FixedSizeListArray::new(
        field,
        dim as i32,
        Arc::new(Float32Array::from(values.to_vec())),
        None,
    ))
}

/// The data type of an image column.
pub fn image_type() -> DataType {
    DataType::Struct(Fields::from(vec![
        Field::new("bytes", DataType::Binary, true),
        Field::new("path", DataType::Utf8, true),
    ]))
}

/// `struct<bytes, path>` with encoded images and null paths.
pub fn images(encoded: &[Vec<u8>]) -> ArrayRef {
    let DataType::Struct(fields) = image_type() else {
        unreachable!("image_type is a struct")
    };
    let bytes: ArrayRef = Arc::new(BinaryArray::from_iter_values(encoded.iter()));
    let paths: ArrayRef = Arc::new(StringArray::from(vec![None::<&str>; encoded.len()]));
    Arc::new(StructArray::new(fields, vec![bytes, paths], None))
}

/// An int64 column.
pub fn i64s(v: impl IntoIterator<Item = i64>) -> ArrayRef {
    Arc::new(Int64Array::from_iter_values(v))
}

/// A float32 column.
pub fn f32s(v: &[f32]) -> ArrayRef {
    Arc::new(Float32Array::from(v.to_vec()))
}

/// A float64 column.
pub fn f64s(v: impl IntoIterator<Item = f64>) -> ArrayRef {
    Arc::new(Float64Array::from_iter_values(v))
}

/// A utf8 column.
pub fn strings<'a>(v: impl IntoIterator<Item = &'a str>) -> ArrayRef {
    Arc::new(StringArray::from_iter_values(v))
}

/// `list<element: string>` with one list per row.
pub fn string_lists(rows: &[Vec<String>]) -> ArrayRef {
    let mut b = ListBuilder::new(StringBuilder::new()).with_field(Arc::new(Field::new(
        "element",
        DataType::Utf8,
        true,
    )));
    for row in rows {
        for s in row {
            b.values().append_value(s);
        }
        b.append(true);
    }
    Arc::new(b.finish())
}

/// `list<element: T>` of `depth` levels around a column of values, one list of `per_row`
/// values per row at the top level; deeper levels wrap each value in its own list
/// (images' `[[[v]]]` per channel).
pub fn nested_lists(values: ArrayRef, rows: usize, per_row: usize, depth: usize) -> ArrayRef {
    let mut arr = values;
    let n = rows * per_row;
    for _ in 1..depth {
        let field = Arc::new(Field::new("element", arr.data_type().clone(), true));
        arr = Arc::new(ListArray::new(
            field,
            OffsetBuffer::from_lengths(vec![1; n]),
            arr,
            None,
        ));
    }
    let field = Arc::new(Field::new("element", arr.data_type().clone(), true));
    Arc::new(ListArray::new(
        field,
        OffsetBuffer::from_lengths(vec![per_row; rows]),
        arr,
        None,
    ))
}

/// `__index_level_0__` large strings (pandas index of tasks.parquet).
pub fn large_strings<'a>(v: impl IntoIterator<Item = &'a str>) -> ArrayRef {
    Arc::new(LargeStringArray::from_iter_values(v))
}

/// A record batch from named columns (nullable fields), with schema metadata.
pub fn batch(
    columns: Vec<(String, ArrayRef)>,
    metadata: Vec<(String, String)>,
) -> Result<RecordBatch> {
    let fields: Vec<Field> = columns
        .iter()
        .map(|(n, a)| Field::new(n, a.data_type().clone(), true))
        .collect();
    let schema = Schema::new(fields).with_metadata(metadata.into_iter().collect());
    RecordBatch::try_new(
        Arc::new(schema),
        columns.into_iter().map(|(_, a)| a).collect(),
    )
    .map_err(|e| Error::Dataset {
        path: "<batch>".into(),
        reason: e.to_string(),
    })
}

/// Files written under temporary names, renamed into place together by [`Staged::commit`].
#[derive(Debug, Default)]
pub struct Staged(Vec<(std::path::PathBuf, std::path::PathBuf)>);

impl Staged {
    /// Renames every staged file into place, in staging order, back to back.
    pub fn commit(self) -> Result<()> {
        for (tmp, path) in self.0 {
            std::fs::rename(&tmp, &path).map_err(Error::io(&path))?;
        }
        Ok(())
    }
}

/// Writes batches (one row group each) to `path` via `path.tmp` and an atomic rename.
pub fn write_parquet(path: &Path, batches: &[RecordBatch]) -> Result<u64> {
    let mut staged = Staged::default();
    let size = stage_parquet(path, batches, &mut staged)?;
    staged.commit()?;
    Ok(size)
}

/// Snappy pages of at most 64 KiB, checked every 8 rows, so a loader reading a few frames reads
/// a few pages, not a whole column chunk; encoded images (the `bytes` of struct columns) are
/// stored as they are: no compression, dictionary or statistics, which JPEG/PNG bytes defeat.
fn writer_properties(schema: &Schema) -> WriterProperties {
    let mut b = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_data_page_size_limit(64 << 10)
        .set_write_batch_size(8);
    for f in schema.fields() {
        if let DataType::Struct(children) = f.data_type() {
            if children.iter().any(|c| c.name() == "bytes") {
                let col = ColumnPath::new(vec![f.name().clone(), "bytes".into()]);
                b = b
                    .set_column_compression(col.clone(), Compression::UNCOMPRESSED)
                    .set_column_dictionary_enabled(col.clone(), false)
                    .set_column_statistics_enabled(col, EnabledStatistics::None);
            }
        }
    }
    b.build()
}

/// Writes batches to `path.tmp` (synced) and stages the rename; returns the file size.
pub fn stage_parquet(path: &Path, batches: &[RecordBatch], staged: &mut Staged) -> Result<u64> {
    let Some(first) = batches.first() else {
        return Err(Error::Dataset {
            path: path.into(),
            reason: "nothing to write".into(),
        });
    };
    let err = |e: parquet::errors::ParquetError| Error::Dataset {
        path: path.into(),
        reason: e.to_string(),
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(Error::io(dir))?;
    }
    let tmp = path.with_extension("parquet.tmp");
    let file = File::create(&tmp).map_err(Error::io(&tmp))?;
    let props = writer_properties(first.schema().as_ref());
    let mut w = ArrowWriter::try_new(file, first.schema(), Some(props)).map_err(err)?;
    for b in batches {
        w.write(b).map_err(err)?;
        w.flush().map_err(err)?;
    }
    let file = w.into_inner().map_err(err)?;
    file.sync_all().map_err(Error::io(&tmp))?;
    drop(file);
    let size = std::fs::metadata(&tmp).map_err(Error::io(&tmp))?.len();
    staged.0.push((tmp, path.to_path_buf()));
    Ok(size)
}

/// Writes `bytes` to `path.tmp` (synced) and stages the rename.
pub fn stage(path: &Path, bytes: &[u8], staged: &mut Staged) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(Error::io(dir))?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(Error::io(&tmp))?;
    File::open(&tmp)
        .and_then(|f| f.sync_all())
        .map_err(Error::io(&tmp))?;
    staged.0.push((tmp, path.to_path_buf()));
    Ok(())
}
