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
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;

use crate::error::{Error, Result};

/// Files per chunk directory.
pub const CHUNKS_SIZE: u64 = 1000;

/// An [`Error::Dataset`] about `path`.
pub fn derr(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Dataset {
        path: path.into(),
        reason: e.to_string(),
    }
}

/// Reads row group `group` of a data file.
pub fn read_row_group(path: &Path, group: usize) -> Result<RecordBatch> {
    let file = File::open(path).map_err(Error::io(path))?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(file)
        .map_err(|e| derr(path, e))?
        .with_row_groups(vec![group])
        .with_batch_size(1 << 20)
        .build()
        .map_err(|e| derr(path, e))?;
    let batches: Vec<RecordBatch> = reader
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| derr(path, e))?;
    let schema = batches
        .first()
        .map(RecordBatch::schema)
        .ok_or_else(|| derr(path, format!("row group {group} is empty")))?;
    arrow_select_concat(&schema, &batches).map_err(|e| derr(path, e))
}

fn arrow_select_concat(
    schema: &arrow_schema::SchemaRef,
    batches: &[RecordBatch],
) -> std::result::Result<RecordBatch, String> {
    if batches.len() == 1 {
        return Ok(batches[0].clone());
    }
    Err(format!(
        "row group read as {} batches for {} columns; expected one",
        batches.len(),
        schema.fields().len()
    ))
}

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

/// A nullable utf8 column.
pub fn opt_strings<'a>(v: impl IntoIterator<Item = Option<&'a str>>) -> ArrayRef {
    Arc::new(StringArray::from_iter(v))
}

/// A nullable boolean column.
pub fn opt_bools(v: impl IntoIterator<Item = Option<bool>>) -> ArrayRef {
    Arc::new(arrow_array::BooleanArray::from_iter(v))
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

/// Snappy pages closed once past 2 KiB, checked after every row: a page closes after the row
/// that crosses the limit, so every encoded frame (2 KB for a 64×48 thumbnail, ~15 KB at
/// 320×240) gets a page of its own and a loader reading a sample's frames reads just those
/// images (with 64 KiB pages checked every 8 rows it read 8 frames for each one it used: 9× the
/// dataset per epoch), while small columns still get pages of dozens to hundreds of rows.
/// Encoded images (the `bytes` of struct columns) are stored as they are: no compression,
/// dictionary or statistics, which JPEG/PNG bytes defeat.
fn writer_properties(schema: &Schema) -> WriterProperties {
    let mut b = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_data_page_size_limit(PAGE_BYTES)
        .set_write_batch_size(1);
    for f in schema.fields() {
        // Depth values (`list<list<…>>`): up to 65 536 distinct values per page, which a
        // dictionary only slows down before falling back to plain.
        if let DataType::List(rows) = f.data_type() {
            if matches!(rows.data_type(), DataType::List(_)) {
                let leaf = [f.name().as_str(), "list", "element", "list", "element"];
                let col = ColumnPath::new(leaf.iter().map(|s| s.to_string()).collect());
                b = b.set_column_dictionary_enabled(col, false);
            }
        }
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

/// Page size limit of every column (see [`writer_properties`]).
const PAGE_BYTES: usize = 2 << 10;

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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use arrow_array::Int64Array;
    use parquet::file::reader::{FileReader, SerializedFileReader};
    use parquet::file::serialized_reader::ReadOptionsBuilder;

    use super::*;

    #[test]
    fn each_image_gets_a_page_and_small_columns_share_pages() {
        let rows = 300;
        // Incompressible "JPEGs" of 3 to 6 KB, each past the 2 KiB limit by itself.
        let encoded: Vec<Vec<u8>> = (0..rows)
            .map(|i| {
                (0..3000 + (i * 37) % 3000)
                    .map(|k| ((k * 7919 + i * 31) % 251) as u8)
                    .collect()
            })
            .collect();
        let index: ArrayRef = Arc::new(Int64Array::from_iter_values(0..rows as i64));
        let schema = Arc::new(Schema::new(vec![
            Field::new("index", DataType::Int64, false),
            Field::new("observation.images.top", image_type(), true),
        ]));
        let batch = RecordBatch::try_new(schema, vec![index, images(&encoded)]).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("file-000.parquet");
        let mut staged = Staged::default();
        stage_parquet(&path, &[batch], &mut staged).unwrap();
        let tmp = &staged.0[0].0;
        let options = ReadOptionsBuilder::new().with_page_index().build();
        let r = SerializedFileReader::new_with_options(File::open(tmp).unwrap(), options).unwrap();
        let md = r.metadata();
        let offsets = &md.offset_index().unwrap()[0];
        let pages = |path: &str| {
            let c = (0..md.row_group(0).num_columns())
                .find(|&c| md.row_group(0).column(c).column_path().string() == path)
                .unwrap();
            offsets[c].page_locations().len()
        };
        assert_eq!(pages("observation.images.top.bytes"), rows);
        assert!(pages("index") <= 2, "{} pages of int64", pages("index"));
    }
}
