//! Depth features (`observation.depth.<camera>`, as `scaledp convert` writes them): a 2-D
//! numeric feature per frame in the data files — `uint16` millimetres or `float32` metres,
//! `list<list<…>>` or fixed-size lists — read for a sample's observation window and handed over
//! as `f32` in the stored unit (holes stay 0 or NaN), resized by nearest neighbour when the
//! batch's image size is another (never interpolated across a hole).

use std::ops::Range;
use std::sync::Arc;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, UInt16Type};
use arrow_array::{Array, ArrayRef};
use arrow_schema::DataType;
use parquet::arrow::ProjectionMask;

use crate::error::{Error, Result};
use crate::meta::Meta;
use crate::reader::{Data, EpisodeRows};

/// The depth features a loader reads, and how.
pub(crate) struct DepthSource {
    pub data: Arc<Data>,
    /// Feature keys, in batch order.
    pub keys: Vec<String>,
    /// Stored (width, height).
    pub stored: (u32, u32),
    /// Batch (width, height).
    pub out: (u32, u32),
}

/// The depth features a loader reads: keys, units, stored (width, height).
pub(crate) struct Picked {
    pub keys: Vec<String>,
    pub units: Vec<String>,
    pub size: (u32, u32),
}

/// The depth keys of `cameras` (image keys) that have one, and each one's unit (`mm`, `m`):
/// `scaledp.cameras.<camera>.depth.unit` of `info.json`, else `mm` for `uint16` and `m` for
/// floats; and their stored (width, height), which must be one for all.
pub(crate) fn pick(meta: &Meta, cameras: &[String], info_file: &str) -> Result<Picked> {
    let mut keys = Vec::new();
    let mut units = Vec::new();
    let mut size = None;
    for cam in cameras {
        let name = cam.strip_prefix("observation.images.").unwrap_or(cam);
        let key = format!("observation.depth.{name}");
        let Some(f) = meta.features.get(&key) else {
            continue;
        };
        let bad = |why: String| Error::format(info_file, format!("{key}: {why}"));
        let (h, w) = match f.shape.as_slice() {
            [h, w] | [h, w, 1] => (*h as u32, *w as u32),
            other => return Err(bad(format!("shape {other:?}, not [height, width]"))),
        };
        match size {
            Some(s) if s != (w, h) => {
                return Err(bad(format!("{w}×{h}, other depth features are {s:?}")));
            }
            _ => size = Some((w, h)),
        }
        let unit = meta.depth_unit(name).unwrap_or(match f.dtype.as_str() {
            "uint16" => "mm".into(),
            "float32" | "float64" => "m".into(),
            other => return Err(bad(format!("dtype {other}, not uint16 or float32"))),
        });
        keys.push(key);
        units.push(unit);
    }
    if keys.is_empty() {
        return Err(Error::format(
            info_file,
            format!("depth asked for, but none of the cameras {cameras:?} has an observation.depth feature"),
        ));
    }
    Ok(Picked {
        keys,
        units,
        size: size.unwrap_or((0, 0)),
    })
}

impl DepthSource {
    /// Depth of rows `frames` (episode frame indices) of `ep`: per key, per frame, the values
    /// at the batch size.
    pub fn read(&self, ep: &EpisodeRows, frames: Range<usize>) -> Result<Vec<Vec<Vec<f32>>>> {
        let name = self.data.files[ep.file].file.name.clone();
        let bad = |e: String| Error::format(name.clone(), e);
        let rows = ep.first_row + frames.start..ep.first_row + frames.end;
        let pschema = self.data.parquet_schema(ep.file);
        let roots: Vec<usize> = self
            .keys
            .iter()
            .map(|k| {
                let fields = pschema.root_schema().get_fields();
                fields
                    .iter()
                    .position(|f| f.name() == k)
                    .ok_or_else(|| bad(format!("no depth column {k}")))
            })
            .collect::<Result<_>>()?;
        let mask = ProjectionMask::roots(pschema, roots);
        let mut out = vec![Vec::with_capacity(frames.len()); self.keys.len()];
        for batch in self.data.read_rows(ep.file, rows, mask)? {
            for (d, key) in self.keys.iter().enumerate() {
                let col = batch
                    .column_by_name(key)
                    .ok_or_else(|| bad(format!("no depth column {key}")))?;
                let per_row = values(col, self.stored)
                    .map_err(|e| bad(format!("episode {}: {key}: {e}", ep.episode_index)))?;
                out[d].extend(per_row.into_iter().map(|v| self.resized(v)));
            }
        }
        if out.iter().any(|k| k.len() != frames.len()) {
            return Err(bad(format!(
                "episode {}: read fewer depth frames than {frames:?}",
                ep.episode_index
            )));
        }
        Ok(out)
    }

    fn resized(&self, v: Vec<f32>) -> Vec<f32> {
        if self.stored == self.out {
            return v;
        }
        let ((sw, sh), (dw, dh)) = (self.stored, self.out);
        let near = |i: u32, from: u32, to: u32| {
            ((u64::from(2 * i + 1) * u64::from(from)) / (2 * u64::from(to))) as usize
        };
        let xs: Vec<usize> = (0..dw).map(|x| near(x, sw, dw)).collect();
        let mut out = Vec::with_capacity(dw as usize * dh as usize);
        for y in 0..dh {
            let row = near(y, sh, dh) * sw as usize;
            out.extend(xs.iter().map(|&x| v[row + x]));
        }
        out
    }
}

/// The rows of a depth column (`list<list<T>>`, fixed-size lists, or a flat list of
/// `width × height` values per row) as `f32`, each checked to hold `width × height` values.
fn values(col: &ArrayRef, (w, h): (u32, u32)) -> std::result::Result<Vec<Vec<f32>>, String> {
    let n = w as usize * h as usize;
    let mut rows = Vec::with_capacity(col.len());
    for r in 0..col.len() {
        if col.is_null(r) {
            return Err(format!("row {r} is null"));
        }
        let flat = leaf(&row(col, r)?)?;
        if flat.len() != n {
            return Err(format!(
                "row {r} holds {} values, the feature {w}×{h}",
                flat.len()
            ));
        }
        rows.push(flat);
    }
    Ok(rows)
}

fn row(col: &ArrayRef, r: usize) -> std::result::Result<ArrayRef, String> {
    match col.data_type() {
        DataType::List(_) => Ok(col.as_list::<i32>().value(r)),
        DataType::LargeList(_) => Ok(col.as_list::<i64>().value(r)),
        DataType::FixedSizeList(_, _) => Ok(col.as_fixed_size_list().value(r)),
        other => Err(format!("type {other}, not a list")),
    }
}

/// The values under any nesting of lists, as `f32`.
fn leaf(a: &ArrayRef) -> std::result::Result<Vec<f32>, String> {
    match a.data_type() {
        DataType::UInt16 => Ok(a
            .as_primitive::<UInt16Type>()
            .values()
            .iter()
            .map(|&v| f32::from(v))
            .collect()),
        DataType::Float32 => Ok(a.as_primitive::<Float32Type>().values().to_vec()),
        DataType::Float64 => Ok(a
            .as_primitive::<Float64Type>()
            .values()
            .iter()
            .map(|&v| v as f32)
            .collect()),
        DataType::List(_) | DataType::LargeList(_) | DataType::FixedSizeList(_, _) => {
            let mut out = Vec::new();
            for i in 0..a.len() {
                out.extend(leaf(&row(a, i)?)?);
            }
            Ok(out)
        }
        other => Err(format!("values of type {other}, not uint16 or float32")),
    }
}
