//! Arrow columns of LeRobot parquet files as plain Rust values: integers, float vectors (fixed
//! or variable lists of float32/float64), strings and string lists, and the `bytes` of image
//! structs.

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, Float64Type, Int32Type, Int64Type, UInt64Type};
use arrow_array::{Array, ArrayRef};
use arrow_schema::DataType;

/// Integers of an int32/int64/uint64 column.
pub(crate) fn ints(a: &ArrayRef) -> Result<Vec<i64>, String> {
    Ok(match a.data_type() {
        DataType::Int64 => a.as_primitive::<Int64Type>().values().to_vec(),
        DataType::Int32 => a
            .as_primitive::<Int32Type>()
            .values()
            .iter()
            .map(|&v| i64::from(v))
            .collect(),
        DataType::UInt64 => a
            .as_primitive::<UInt64Type>()
            .values()
            .iter()
            .map(|&v| v as i64)
            .collect(),
        t => return Err(format!("expected integers, found {t}")),
    })
}

/// Floats of a float32/float64 column.
pub(crate) fn floats(a: &dyn Array) -> Result<Vec<f64>, String> {
    Ok(match a.data_type() {
        DataType::Float32 => a
            .as_primitive::<Float32Type>()
            .values()
            .iter()
            .map(|&v| f64::from(v))
            .collect(),
        DataType::Float64 => a.as_primitive::<Float64Type>().values().to_vec(),
        t => return Err(format!("expected floats, found {t}")),
    })
}

/// One float vector per row (fixed-size or variable lists of floats; a float column is one
/// value per row).
pub(crate) fn vectors(a: &ArrayRef) -> Result<Vec<Vec<f32>>, String> {
    let rows = |values: &dyn Array, ranges: Vec<(usize, usize)>| -> Result<Vec<Vec<f32>>, String> {
        let v = floats(values)?;
        ranges
            .into_iter()
            .map(|(s, e)| {
                v.get(s..e)
                    .map(|x| x.iter().map(|&f| f as f32).collect())
                    .ok_or_else(|| "list offsets out of range".to_string())
            })
            .collect()
    };
    match a.data_type() {
        DataType::FixedSizeList(_, n) => {
            let l = a.as_fixed_size_list();
            let n = *n as usize;
            let base = l.offset() * n;
            rows(
                l.values().as_ref(),
                (0..l.len())
                    .map(|i| (base + i * n, base + (i + 1) * n))
                    .collect(),
            )
        }
        DataType::List(_) => {
            let l = a.as_list::<i32>();
            let o = l.value_offsets();
            rows(
                l.values().as_ref(),
                o.windows(2)
                    .map(|w| (w[0] as usize, w[1] as usize))
                    .collect(),
            )
        }
        DataType::LargeList(_) => {
            let l = a.as_list::<i64>();
            let o = l.value_offsets();
            rows(
                l.values().as_ref(),
                o.windows(2)
                    .map(|w| (w[0] as usize, w[1] as usize))
                    .collect(),
            )
        }
        DataType::Float32 | DataType::Float64 => Ok(floats(a.as_ref())?
            .into_iter()
            .map(|v| vec![v as f32])
            .collect()),
        t => Err(format!("expected float vectors, found {t}")),
    }
}

/// Strings of a (large) string column; a list of strings per row gives its elements joined
/// with "; ".
pub(crate) fn strings(a: &ArrayRef) -> Result<Vec<String>, String> {
    let plain = |a: &dyn Array| -> Result<Vec<String>, String> {
        Ok(match a.data_type() {
            DataType::Utf8 => a
                .as_string::<i32>()
                .iter()
                .map(|s| s.unwrap_or_default().to_string())
                .collect(),
            DataType::LargeUtf8 => a
                .as_string::<i64>()
                .iter()
                .map(|s| s.unwrap_or_default().to_string())
                .collect(),
            DataType::Utf8View => a
                .as_string_view()
                .iter()
                .map(|s| s.unwrap_or_default().to_string())
                .collect(),
            t => return Err(format!("expected strings, found {t}")),
        })
    };
    match a.data_type() {
        DataType::List(_) => {
            let l = a.as_list::<i32>();
            (0..l.len())
                .map(|i| plain(l.value(i).as_ref()).map(|v| v.join("; ")))
                .collect()
        }
        DataType::LargeList(_) => {
            let l = a.as_list::<i64>();
            (0..l.len())
                .map(|i| plain(l.value(i).as_ref()).map(|v| v.join("; ")))
                .collect()
        }
        _ => plain(a.as_ref()),
    }
}

/// The encoded bytes of each row of an image column (LeRobot's `{bytes, path}` struct, or a
/// plain binary column).
pub(crate) fn image_bytes(a: &ArrayRef) -> Result<Vec<&[u8]>, String> {
    match a.data_type() {
        DataType::Struct(_) => {
            let bytes = a
                .as_struct()
                .column_by_name("bytes")
                .ok_or("image struct without a 'bytes' field")?;
            binary(bytes.as_ref())
        }
        _ => binary(a.as_ref()),
    }
}

fn binary(b: &dyn Array) -> Result<Vec<&[u8]>, String> {
    Ok(match b.data_type() {
        DataType::Binary => b
            .as_binary::<i32>()
            .iter()
            .map(Option::unwrap_or_default)
            .collect(),
        DataType::LargeBinary => b
            .as_binary::<i64>()
            .iter()
            .map(Option::unwrap_or_default)
            .collect(),
        DataType::BinaryView => b
            .as_binary_view()
            .iter()
            .map(Option::unwrap_or_default)
            .collect(),
        t => return Err(format!("expected image bytes, found {t}")),
    })
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use arrow_array::builder::{FixedSizeListBuilder, Float32Builder, ListBuilder};

    use super::*;

    #[test]
    fn vectors_from_fixed_and_variable_lists() {
        let mut b = FixedSizeListBuilder::new(Float32Builder::new(), 2);
        for row in [[1.0, 2.0], [3.0, 4.0]] {
            b.values().append_slice(&row);
            b.append(true);
        }
        let a: ArrayRef = Arc::new(b.finish());
        assert_eq!(vectors(&a).unwrap(), vec![vec![1.0, 2.0], vec![3.0, 4.0]]);
        assert_eq!(vectors(&a.slice(1, 1)).unwrap(), vec![vec![3.0, 4.0]]);
        let mut l = ListBuilder::new(Float32Builder::new());
        l.values().append_slice(&[5.0]);
        l.append(true);
        l.values().append_slice(&[6.0, 7.0]);
        l.append(true);
        let a: ArrayRef = Arc::new(l.finish());
        assert_eq!(vectors(&a).unwrap(), vec![vec![5.0], vec![6.0, 7.0]]);
    }
}
