//! Depth and tf as rerun shows them. Depth frames — raw `16UC1` / `32FC1` images, image_transport
//! `compressedDepth` (decoded by the converter's own decoder) and a dataset's
//! `observation.depth.<camera>` columns — become `DepthImage`s with their meter (1000 units per
//! metre for millimetres, 1 for metres), shrunk to `max_width` by nearest neighbour only, so a
//! hole (0, NaN) never bleeds into its neighbours. `/tf` and `/tf_static` (`tf2_msgs/TFMessage`)
//! become `Transform3D`s between named frames, each child frame on its entity under
//! `world/tf/`, with axes, and every tree's root tied to the 3-D scene's `world`.

use std::collections::BTreeSet;

use arrow_array::cast::AsArray;
use arrow_array::types::{Float32Type, UInt16Type};
use arrow_array::{Array, ArrayRef};
use arrow_schema::DataType;
use rerun::datatypes::ChannelDatatype;
use rerun::{
    AsComponents, CoordinateFrame, DepthImage, RecordingStream, Transform3D, TransformAxes3D,
};
use scaledp_converter::depth::{
    decode_compressed_depth, is_compressed_depth, raw_depth_encoding, DepthImage as Depth,
    DepthPixels, RawDepth,
};
use scaledp_converter::Serialization;
use scaledp_schema::msg::{CompressedImage, TfMessage};
use scaledp_schema::RosMessage;

use crate::images::shown_size;
use crate::layout;

/// A decoded depth frame as rerun shows it.
pub(crate) fn depth_image(d: &Depth, max_width: Option<u32>) -> DepthImage {
    let (w, h) = shown_size(d.width, d.height, max_width);
    let d = d.resized(w, h);
    let (datatype, meter) = match d.pixels {
        DepthPixels::U16(_) => (ChannelDatatype::U16, 1000.0),
        DepthPixels::F32(_) => (ChannelDatatype::F32, 1.0),
    };
    DepthImage::from_data_type_and_bytes(d.to_le_bytes(), [w, h], datatype).with_meter(meter)
}

/// A depth message — a raw image in a depth encoding or a `compressedDepth` one — as its
/// capture stamp (ns) and the frame to log; None when the message is not depth.
pub(crate) fn depth_message(
    message_type: &str,
    serialization: Serialization,
    data: &[u8],
    max_width: Option<u32>,
) -> Option<Result<(u64, DepthImage), String>> {
    let compressed = message_type.ends_with("/CompressedImage");
    let stamp = |h: &scaledp_schema::msg::Header| h.stamp.as_ns();
    let decoded: Result<(u64, Depth), String> = match (serialization, compressed) {
        (Serialization::Cdr, false) => {
            let raw = RawDepth::from_cdr(data).ok()?;
            raw_depth_encoding(raw.encoding)?;
            let t = scaledp_schema::msg::header_stamp(data).map_or(0, |t| t.as_ns());
            raw.decode().map(|d| (t, d))
        }
        (Serialization::Ros1, false) => {
            let img = scaledp_converter::ros1::decode::image(data).ok()?;
            raw_depth_encoding(&img.encoding)?;
            let raw = RawDepth {
                width: img.width,
                height: img.height,
                encoding: &img.encoding,
                is_bigendian: img.is_bigendian,
                step: img.step,
                data: &img.data,
            };
            raw.decode().map(|d| (stamp(&img.header), d))
        }
        (_, true) => {
            let c = match serialization {
                Serialization::Cdr => CompressedImage::from_cdr(data).ok()?,
                Serialization::Ros1 => {
                    scaledp_converter::ros1::decode::compressed_image(data).ok()?
                }
            };
            if !is_compressed_depth(&c.format) {
                return None;
            }
            decode_compressed_depth(&c.format, &c.data).map(|d| (stamp(&c.header), d))
        }
    };
    Some(decoded.map(|(t, d)| (t, depth_image(&d, max_width))))
}

/// The depth frames of a dataset's `observation.depth.<camera>` column (`list<list<…>>` of
/// `uint16` mm or `float32` m, `height` rows of `width`), one per row.
pub(crate) fn dataset_rows(
    col: &ArrayRef,
    max_width: Option<u32>,
) -> Result<Vec<DepthImage>, String> {
    let list = col
        .as_list_opt::<i32>()
        .ok_or_else(|| format!("a depth column of type {}", col.data_type()))?;
    let mut out = Vec::with_capacity(list.len());
    for r in 0..list.len() {
        let rows = list.value(r);
        let rows = rows
            .as_list_opt::<i32>()
            .ok_or_else(|| format!("depth rows of type {}", rows.data_type()))?;
        let height = rows.len() as u32;
        let v = rows.values();
        let width = if height == 0 {
            0
        } else {
            (v.len() / height as usize) as u32
        };
        let pixels = match v.data_type() {
            DataType::UInt16 => DepthPixels::U16(v.as_primitive::<UInt16Type>().values().to_vec()),
            DataType::Float32 => {
                DepthPixels::F32(v.as_primitive::<Float32Type>().values().to_vec())
            }
            other => return Err(format!("depth values of type {other}")),
        };
        let d = Depth {
            width,
            height,
            pixels,
        };
        out.push(depth_image(&d, max_width));
    }
    Ok(out)
}

/// Logs a dataset's depth column, read in `batches` of an episode's rows, at `entity`, frame t
/// at the time `at(t)` sets; returns the frames logged.
pub(crate) fn log_column(
    rec: &RecordingStream,
    entity: &str,
    batches: impl Iterator<Item = Result<arrow_array::RecordBatch, arrow_schema::ArrowError>>,
    max_width: Option<u32>,
    at: &dyn Fn(usize),
) -> Result<u64, String> {
    let mut t = 0usize;
    for batch in batches {
        let batch = batch.map_err(|e| e.to_string())?;
        for d in dataset_rows(batch.column(0), max_width)? {
            at(t);
            rec.log(entity, &d).map_err(|e| e.to_string())?;
            t += 1;
        }
    }
    Ok(t as u64)
}

/// Where the frames of tf trees have been placed so far.
#[derive(Debug, Default)]
pub(crate) struct TfTree {
    /// Frames placed by a transform (children).
    placed: BTreeSet<String>,
    /// Frames tied to the scene's `world` as roots.
    roots: BTreeSet<String>,
}

impl TfTree {
    /// Logs a `TFMessage` (CDR): each transform on its child frame's entity, at capture time
    /// (static for `/tf_static`). Returns how many transforms were logged.
    pub fn message(
        &mut self,
        rec: &RecordingStream,
        data: &[u8],
        latched: bool,
    ) -> Result<usize, String> {
        let msg = TfMessage::from_cdr(data).map_err(|e| e.to_string())?;
        for t in &msg.transforms {
            let (parent, child) = (&t.header.frame_id, &t.child_frame_id);
            let (p, q) = (&t.transform.translation, &t.transform.rotation);
            let transform = Transform3D::from_translation_rotation(
                [p.x as f32, p.y as f32, p.z as f32],
                rerun::Quaternion::from_xyzw([q.x as f32, q.y as f32, q.z as f32, q.w as f32]),
            )
            .with_parent_frame(parent.as_str())
            .with_child_frame(child.as_str());
            let parts: [&dyn AsComponents; 3] = [
                &transform,
                &CoordinateFrame::new(child.as_str()),
                &TransformAxes3D::new(0.05),
            ];
            let entity = layout::tf(child);
            let logged = if latched {
                rec.log_static(entity.as_str(), &parts)
            } else {
                rec.set_timestamp_nanos_since_epoch(
                    layout::CAPTURE_TIME,
                    t.header.stamp.as_ns() as i64,
                );
                rec.log(entity.as_str(), &parts)
            };
            logged.map_err(|e| e.to_string())?;
            self.placed.insert(child.clone());
            self.roots.remove(child);
            if !self.placed.contains(parent) && self.roots.insert(parent.clone()) {
                // A frame nothing places yet: the root of its tree, at the scene's origin.
                let root = Transform3D::new()
                    .with_parent_frame(format!("tf#/{}", layout::WORLD))
                    .with_child_frame(parent.as_str());
                rec.log_static(layout::tf(parent), &root)
                    .map_err(|e| e.to_string())?;
            }
        }
        Ok(msg.transforms.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_keeps_holes_when_shrunk() {
        let d = Depth {
            width: 4,
            height: 2,
            pixels: DepthPixels::U16(vec![0, 1, 2, 3, 4, 0, 6, 7]),
        };
        let shown = d.resized(2, 1);
        assert_eq!(shown.pixels, DepthPixels::U16(vec![0, 7]));
        // A frame no wider than max_width is shown as it is.
        assert_eq!(shown_size(4, 2, Some(640)), (4, 2));
    }
}
