//! `meta/info.json` and `meta/stats.json` of a LeRobot v3.0 dataset: the features (dtype, shape,
//! names), the frame rate and the statistics the normalizer is built from.

use std::collections::BTreeMap;

use serde::Deserialize;

use crate::error::{Error, Result};
use crate::store::Store;

/// One feature of `info.json`.
#[derive(Clone, Debug, Deserialize)]
pub struct Feature {
    /// `float32`, `int64`, `image`, `video`, ...
    pub dtype: String,
    /// Shape (`[H, W, 3]` for images).
    #[serde(default)]
    pub shape: Vec<usize>,
    /// Names of the dimensions, when given (a list; LeRobot sometimes writes a map).
    #[serde(default)]
    pub names: Option<serde_json::Value>,
}

impl Feature {
    /// An image feature's (width, height): where `names` says `height` and `width` are, else
    /// `[H, W, C]` or `[C, H, W]` told apart by which end holds 1, 3 or 4 channels.
    pub fn image_size(&self) -> Option<(u32, u32)> {
        let s = &self.shape;
        if s.len() != 3 {
            return None;
        }
        let named = match &self.names {
            Some(serde_json::Value::Array(a)) => {
                let at = |n: &str| a.iter().position(|v| v.as_str() == Some(n));
                at("height").zip(at("width"))
            }
            _ => None,
        };
        let channels = |c: usize| matches!(c, 1 | 3 | 4);
        let (h, w) = match named {
            Some((h, w)) => (s[h], s[w]),
            None if channels(s[2]) => (s[0], s[1]),
            None if channels(s[0]) => (s[1], s[2]),
            None => return None,
        };
        Some((u32::try_from(w).ok()?, u32::try_from(h).ok()?))
    }

    /// The names of a vector feature's dimensions, or `dim_i`.
    pub fn dim_names(&self) -> Vec<String> {
        let n = self.shape.iter().product::<usize>();
        let listed: Option<Vec<String>> = match &self.names {
            Some(serde_json::Value::Array(a)) => {
                a.iter().map(|v| v.as_str().map(String::from)).collect()
            }
            Some(serde_json::Value::Object(o)) => o.values().next().and_then(|v| {
                v.as_array()
                    .and_then(|a| a.iter().map(|x| x.as_str().map(String::from)).collect())
            }),
            _ => None,
        };
        match listed {
            Some(l) if l.len() == n => l,
            _ => (0..n).map(|i| format!("dim_{i}")).collect(),
        }
    }
}

#[derive(Deserialize)]
struct InfoJson {
    codebase_version: String,
    fps: f64,
    features: BTreeMap<String, Feature>,
    #[serde(default)]
    total_episodes: Option<usize>,
    #[serde(default)]
    total_frames: Option<usize>,
    #[serde(default)]
    data_path: Option<String>,
    #[serde(default)]
    video_path: Option<String>,
    /// What `scaledp convert` records beside LeRobot's keys (cameras' depth units,
    /// intrinsics).
    #[serde(default)]
    scaledp: Option<serde_json::Value>,
}

/// A path template of `info.json` must stay inside the dataset: relative, no `..`.
pub(crate) fn check_template(key: &str, template: &str) -> std::result::Result<(), String> {
    let inside = !template.starts_with('/')
        && !template.contains('\\')
        && template.split('/').all(|part| part != "..")
        && !template.contains("://");
    if inside {
        Ok(())
    } else {
        Err(format!("{key} '{template}' points outside the dataset"))
    }
}

/// The parts of `info.json` and `stats.json` the loader needs.
#[derive(Clone, Debug)]
pub struct Meta {
    /// Frames per second.
    pub fps: f64,
    /// Every feature, by key (sorted).
    pub features: BTreeMap<String, Feature>,
    /// `stats.json`: feature → statistic (`min`, `max`, `mean`, `std`) → flattened values.
    pub stats: BTreeMap<String, BTreeMap<String, Vec<f64>>>,
    /// `total_episodes` and `total_frames`, when given: what the data files must hold.
    pub totals: Option<(usize, usize)>,
    /// `video_path`, the template of video file paths (None: LeRobot's default, or no video).
    pub video_path: Option<String>,
    /// `scaledp.cameras` of a dataset `scaledp convert` wrote: per camera its `intrinsics` and
    /// `depth` (unit, encoding, the depth image's intrinsics).
    pub cameras: serde_json::Map<String, serde_json::Value>,
}

impl Meta {
    /// Reads `meta/info.json` and (when present) `meta/stats.json`.
    pub(crate) fn read(store: &Store) -> Result<Self> {
        let info_rel = "meta/info.json";
        let bytes = store.read(info_rel)?;
        let info: InfoJson = serde_json::from_slice(&bytes)
            .map_err(|e| Error::format(store.describe(info_rel), e))?;
        if !info.codebase_version.starts_with("v3") {
            return Err(Error::format(
                store.describe(info_rel),
                format!(
                    "codebase_version {} (this loader reads LeRobot v3.x)",
                    info.codebase_version
                ),
            ));
        }
        for (key, template) in [
            ("data_path", &info.data_path),
            ("video_path", &info.video_path),
        ] {
            if let Some(t) = template {
                check_template(key, t).map_err(|e| Error::format(store.describe(info_rel), e))?;
            }
        }
        let stats_rel = "meta/stats.json";
        let stats = match store.read(stats_rel) {
            Ok(bytes) => {
                parse_stats(&bytes).map_err(|e| Error::format(store.describe(stats_rel), e))?
            }
            Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                BTreeMap::new()
            }
            Err(e) => return Err(e),
        };
        if !(info.fps.is_finite() && info.fps > 0.0) {
            return Err(Error::format(
                store.describe(info_rel),
                format!("fps {} is not a positive rate", info.fps),
            ));
        }
        Ok(Meta {
            fps: info.fps,
            features: info.features,
            stats,
            totals: info.total_episodes.zip(info.total_frames),
            video_path: info.video_path,
            cameras: info
                .scaledp
                .and_then(|v| v.get("cameras").and_then(|c| c.as_object().cloned()))
                .unwrap_or_default(),
        })
    }

    /// The unit (`mm`, `m`) `info.json` gives camera `name`'s depth.
    pub fn depth_unit(&self, name: &str) -> Option<String> {
        let unit = self.cameras.get(name)?.get("depth")?.get("unit")?;
        unit.as_str().map(String::from)
    }

    /// Keys of the image features, sorted.
    pub fn image_keys(&self) -> Vec<String> {
        self.features
            .iter()
            .filter(|(_, f)| f.dtype == "image" || f.dtype == "video")
            .map(|(k, _)| k.clone())
            .collect()
    }
}

/// Flattens each statistic (nested lists for image stats) into one vector of numbers.
fn parse_stats(
    bytes: &[u8],
) -> std::result::Result<BTreeMap<String, BTreeMap<String, Vec<f64>>>, String> {
    let v: serde_json::Value = serde_json::from_slice(bytes).map_err(|e| e.to_string())?;
    let obj = v.as_object().ok_or("not a JSON object")?;
    let mut out = BTreeMap::new();
    for (feature, stats) in obj {
        let Some(stats) = stats.as_object() else {
            continue;
        };
        let mut per = BTreeMap::new();
        for (name, value) in stats {
            let mut flat = Vec::new();
            flatten(value, &mut flat);
            per.insert(name.clone(), flat);
        }
        out.insert(feature.clone(), per);
    }
    Ok(out)
}

fn flatten(v: &serde_json::Value, out: &mut Vec<f64>) {
    match v {
        serde_json::Value::Array(a) => a.iter().for_each(|x| flatten(x, out)),
        serde_json::Value::Number(n) => out.extend(n.as_f64()),
        // What NaN becomes in JSON: kept (as NaN) so the statistic is refused where it is used,
        // not silently shortened.
        serde_json::Value::Null => out.push(f64::NAN),
        _ => {}
    }
}
