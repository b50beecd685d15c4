//! What a dataset holds beside its colour images: each camera's registered depth as the
//! feature `observation.depth.<camera>` and each camera's intrinsics in `meta/info.json`.
//!
//! Depth is a fixed-shape numeric feature in the data files, `uint16` millimetres or `float32`
//! metres as the camera published them, shape `[height, width]` (the stored image size),
//! written as `list<list<…>>`, the storage of `datasets.Array2D`, which LeRobot declares for a
//! two-dimensional feature (`get_hf_features_from_features`): LeRobot 0.4.4 returns it as a
//! tensor. Not `observation.images.*`: LeRobot takes every key there for a camera it decodes
//! as an image or video (3 channels, 8 bits), and its image writer has no depth support.
//!
//! Intrinsics live in `info.json` under `scaledp.cameras.<camera>` (`intrinsics`, and the
//! depth image's own under `depth.intrinsics`): a feature's `info` is rewritten by LeRobot
//! whenever it encodes video, and LeRobot's readers expect only `dtype`, `shape`, `names`
//! (and `info` for video) in a feature.

use std::collections::BTreeMap;
use std::sync::Arc;

use arrow_array::{Array, ArrayRef, Float32Array, ListArray, UInt16Array};
use arrow_buffer::OffsetBuffer;
use arrow_schema::{DataType, Field};
use scaledp_schema::rig::DepthEncoding;
use serde::{Deserialize, Serialize};

use crate::camera_info::Intrinsics;
use crate::episode::Episode;

/// A camera whose depth the dataset stores.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DepthFeature {
    /// The camera's name.
    pub camera: String,
    /// `16UC1` (stored as `uint16` millimetres) or `32FC1` (`float32` metres).
    pub encoding: DepthEncoding,
}

impl DepthFeature {
    /// `observation.depth.<camera>`.
    pub fn key(&self) -> String {
        key(&self.camera)
    }
    /// `uint16` or `float32`.
    pub fn dtype(&self) -> &'static str {
        match self.encoding {
            DepthEncoding::U16Millimetres => "uint16",
            DepthEncoding::F32Metres => "float32",
        }
    }
}

/// The feature key of a camera's depth.
pub fn key(camera: &str) -> String {
    format!("observation.depth.{camera}")
}

/// One episode's intrinsics of a camera: its colour image's and its depth image's.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraIntrinsics {
    /// From the camera's `camera_info_topic`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<Intrinsics>,
    /// From its depth's `camera_info_topic`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<Intrinsics>,
}

/// Adds the `depth` features of images `(w, h)` to `info.json`'s `features`.
pub fn features(
    depth: &[DepthFeature],
    (w, h): (u32, u32),
    m: &mut serde_json::Map<String, serde_json::Value>,
) {
    for d in depth {
        m.insert(
            d.key(),
            serde_json::json!({"dtype": d.dtype(), "shape": [h, w], "names": ["height", "width"]}),
        );
    }
}

/// Adds the `depth` features of images `(w, h)` to the data files' `huggingface` schema
/// metadata.
pub fn hf_features(
    depth: &[DepthFeature],
    (w, h): (u32, u32),
    f: &mut serde_json::Map<String, serde_json::Value>,
) {
    for d in depth {
        f.insert(
            d.key(),
            serde_json::json!({"shape": [h, w], "dtype": d.dtype(), "_type": "Array2D"}),
        );
    }
}

/// Each committed episode's index and intrinsics.
pub type EpisodeIntrinsics<'a> = (u64, &'a BTreeMap<String, CameraIntrinsics>);

/// `scaledp.cameras` of `info.json`: per camera its intrinsics (the first episode's that has
/// them, and the episodes whose own differ) and its depth (feature, encoding, unit, holes,
/// intrinsics).
pub fn cameras_json(
    cameras: &[String],
    depth: &[DepthFeature],
    episodes: &[EpisodeIntrinsics<'_>],
) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    for c in cameras {
        let mut cam = serde_json::Map::new();
        let pick =
            |f: fn(&CameraIntrinsics) -> Option<&Intrinsics>| first_and_differing(episodes, c, f);
        if let Some(v) = pick(|i| i.colour.as_ref()) {
            cam.insert("intrinsics".into(), v);
        }
        if let Some(d) = depth.iter().find(|d| &d.camera == c) {
            let mut depth = serde_json::json!({
                "feature": d.key(),
                "encoding": d.encoding.as_str(),
                "dtype": d.dtype(),
                "unit": d.encoding.unit(),
                "unknown": match d.encoding {
                    DepthEncoding::U16Millimetres => "0",
                    DepthEncoding::F32Metres => "NaN or ±inf",
                },
                "resize": "nearest neighbour",
            });
            if let Some(v) = pick(|i| i.depth.as_ref()) {
                depth["intrinsics"] = v;
            }
            cam.insert("depth".into(), depth);
        }
        if !cam.is_empty() {
            out.insert(c.clone(), serde_json::Value::Object(cam));
        }
    }
    serde_json::Value::Object(out)
}

/// The first episode's intrinsics of camera `c` (by `pick`), with `differ_in_episodes` listing
/// the episodes whose own are other (a recalibration); None when no episode has any.
fn first_and_differing(
    episodes: &[EpisodeIntrinsics<'_>],
    c: &str,
    pick: fn(&CameraIntrinsics) -> Option<&Intrinsics>,
) -> Option<serde_json::Value> {
    let of =
        |e: &EpisodeIntrinsics<'_>| -> Option<Intrinsics> { e.1.get(c).and_then(pick).cloned() };
    let first = episodes.iter().find_map(of)?;
    let mut v = serde_json::to_value(&first).ok()?;
    let differ: Vec<u64> = episodes
        .iter()
        .filter(|e| of(e).is_some_and(|i| i != first))
        .map(|e| e.0)
        .collect();
    if !differ.is_empty() {
        v["differ_in_episodes"] = serde_json::json!(differ);
    }
    Some(v)
}

/// The per-episode intrinsics record of an episode's cameras (cameras without any left out).
pub fn episode_intrinsics(ep: &Episode) -> BTreeMap<String, CameraIntrinsics> {
    ep.cameras
        .iter()
        .filter_map(|c| {
            let i = CameraIntrinsics {
                colour: c.intrinsics.clone(),
                depth: c.depth.as_ref().and_then(|d| d.intrinsics.clone()),
            };
            (i != CameraIntrinsics::default()).then(|| (c.name.clone(), i))
        })
        .collect()
}

/// The cameras of `ep` whose depth it holds.
pub fn depth_features(ep: &Episode) -> Vec<DepthFeature> {
    ep.cameras
        .iter()
        .filter_map(|c| {
            c.depth.as_ref().map(|d| DepthFeature {
                camera: c.name.clone(),
                encoding: d.encoding,
            })
        })
        .collect()
}

/// A depth column: per row a `list<list<T>>` of `height` rows of `width` values, from each
/// frame's little-endian values.
pub fn column(frames: &[Vec<u8>], encoding: DepthEncoding, width: u32, height: u32) -> ArrayRef {
    let (w, h) = (width as usize, height as usize);
    let values: ArrayRef = match encoding {
        DepthEncoding::U16Millimetres => {
            Arc::new(UInt16Array::from_iter_values(frames.iter().flat_map(|f| {
                f.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]]))
            })))
        }
        DepthEncoding::F32Metres => Arc::new(Float32Array::from_iter_values(
            frames.iter().flat_map(|f| {
                f.chunks_exact(4)
                    .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            }),
        )),
    };
    let field = |t: &DataType| Arc::new(Field::new("element", t.clone(), true));
    let rows = Arc::new(ListArray::new(
        field(values.data_type()),
        OffsetBuffer::from_lengths(vec![w; frames.len() * h]),
        values,
        None,
    ));
    Arc::new(ListArray::new(
        field(rows.data_type()),
        OffsetBuffer::from_lengths(vec![h; frames.len()]),
        rows,
        None,
    ))
}

/// Bytes a depth frame must hold at the stored size.
pub fn frame_bytes(encoding: DepthEncoding, (w, h): (u32, u32)) -> usize {
    w as usize * h as usize * encoding.bytes_per_pixel()
}
