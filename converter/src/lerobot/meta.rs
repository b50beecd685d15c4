//! The dataset's own record (`meta/scaledp.json`) and the LeRobot meta files made from it:
//! `meta/info.json`, `meta/stats.json`, `meta/tasks.parquet`, `meta/episodes/chunk-000/file-000.parquet`.

use std::collections::BTreeMap;
use std::path::Path;

use scaledp_schema::ActionSpace;
use serde::{Deserialize, Serialize};

use super::columns::{self as col, stage, stage_parquet, Staged};
use super::depth::{CameraIntrinsics, DepthFeature};
use super::videos::{VideoFormat, VideoSpan, VIDEO_FILE_SIZE_MB};
use crate::error::{Error, Result};
use crate::recorded::Recorded;
use crate::stats::{aggregate_all, Stats, QUANTILES};
use scaledp_align::AlignmentReport;

pub use super::columns::CHUNKS_SIZE;

/// One committed episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeRecord {
    /// Index in the dataset.
    pub episode_index: u64,
    /// Frames.
    pub length: u64,
    /// Index into the task list.
    pub task_index: u64,
    /// Data file (global number; chunk = n / 1000, file = n % 1000).
    pub data_file: u64,
    /// First global frame index.
    pub from_index: u64,
    /// One past the last global frame index.
    pub to_index: u64,
    /// The input it came from.
    pub source: String,
    /// BLAKE3 of the input's bytes.
    pub source_hash: String,
    /// For an input read from object storage, its version (file names, sizes and ETags) when
    /// it was read: a re-run skips that version without reading it again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source_etag: Option<String>,
    /// Per-feature statistics.
    pub stats: BTreeMap<String, Stats>,
    /// Alignment measurements.
    pub report: AlignmentReport,
    /// `header.stamp` or `log_time`.
    pub time_source: String,
    /// Where its frames are in the camera videos (datasets of video features).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoSpan>,
    /// Per camera, the intrinsics its camera_info gave in this episode (cameras without any
    /// left out).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub intrinsics: BTreeMap<String, CameraIntrinsics>,
    /// Operator, label and verdict (empty in datasets converted before they were kept).
    #[serde(default, skip_serializing_if = "Recorded::is_empty")]
    pub recorded: Recorded,
}

/// Everything needed to rebuild the LeRobot meta files, and to resume or merge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sidecar {
    /// Format version of this file.
    pub format: u32,
    /// Frame rate.
    pub fps: f64,
    /// Robot type (the rig's name).
    pub robot_type: String,
    /// The rig, as TOML.
    pub rig: String,
    /// Image width, height.
    pub image_size: (u32, u32),
    /// JPEG quality of the images (absent in datasets written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jpeg_quality: Option<u8>,
    /// How the cameras are encoded when they are video features (None: JPEG images).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub video: Option<VideoFormat>,
    /// Camera names, in column order.
    pub cameras: Vec<String>,
    /// The cameras whose depth is stored (`observation.depth.<camera>`), in camera order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub depth: Vec<DepthFeature>,
    /// Names of state / action dimensions.
    pub state_names: Vec<String>,
    /// Their space (absent in datasets written before joint space: TCP poses).
    #[serde(default)]
    pub action_space: ActionSpace,
    /// Names of joint dimensions.
    pub joint_names: Vec<String>,
    /// Task strings by task index.
    pub tasks: Vec<String>,
    /// Committed episodes, in order.
    pub episodes: Vec<EpisodeRecord>,
    /// Converter version that wrote it.
    pub converter_version: String,
}

/// `data/chunk-XXX/file-YYY.parquet` of a global file number.
pub fn data_path(root: &Path, file: u64) -> std::path::PathBuf {
    root.join(format!(
        "data/chunk-{:03}/file-{:03}.parquet",
        file / CHUNKS_SIZE,
        file % CHUNKS_SIZE
    ))
}

/// Feature names in column order.
pub fn feature_names(s: &Sidecar) -> Vec<String> {
    let mut v: Vec<String> = s
        .cameras
        .iter()
        .map(|c| format!("observation.images.{c}"))
        .collect();
    v.extend(s.depth.iter().map(DepthFeature::key));
    for f in [
        "observation.state",
        "action",
        "observation.joints",
        "timestamp",
        "frame_index",
        "episode_index",
        "index",
        "task_index",
    ] {
        v.push(f.into());
    }
    v
}

fn features_json(s: &Sidecar) -> serde_json::Value {
    let (w, h) = s.image_size;
    let mut m = serde_json::Map::new();
    for c in &s.cameras {
        let mut f = serde_json::json!({"dtype": "image", "shape": [h, w, 3], "names": ["height", "width", "channels"]});
        if let Some(v) = &s.video {
            f["dtype"] = "video".into();
            f["info"] = serde_json::json!({
                "video.height": h,
                "video.width": w,
                "video.codec": v.codec,
                "video.pix_fmt": v.pix_fmt,
                "video.is_depth_map": false,
                "video.fps": fps_json(s.fps),
                "video.channels": 3,
                "has_audio": false,
            });
        }
        m.insert(format!("observation.images.{c}"), f);
    }
    super::depth::features(&s.depth, s.image_size, &mut m);
    let vector = |names: &[String]| serde_json::json!({"dtype": "float32", "shape": [names.len()], "names": names});
    m.insert("observation.state".into(), vector(&s.state_names));
    m.insert("action".into(), vector(&s.state_names));
    m.insert("observation.joints".into(), vector(&s.joint_names));
    m.insert(
        "timestamp".into(),
        serde_json::json!({"dtype": "float32", "shape": [1], "names": null}),
    );
    for f in ["frame_index", "episode_index", "index", "task_index"] {
        m.insert(
            f.into(),
            serde_json::json!({"dtype": "int64", "shape": [1], "names": null}),
        );
    }
    serde_json::Value::Object(m)
}

/// The `huggingface` schema metadata `datasets` writes for the data files.
pub fn huggingface_metadata(s: &Sidecar) -> String {
    let mut f = serde_json::Map::new();
    for c in s.cameras.iter().filter(|_| s.video.is_none()) {
        f.insert(
            format!("observation.images.{c}"),
            serde_json::json!({"_type": "Image"}),
        );
    }
    super::depth::hf_features(&s.depth, s.image_size, &mut f);
    let list = |n: usize| serde_json::json!({"feature": {"dtype": "float32", "_type": "Value"}, "length": n, "_type": "List"});
    f.insert("observation.state".into(), list(s.state_names.len()));
    f.insert("action".into(), list(s.state_names.len()));
    f.insert("observation.joints".into(), list(s.joint_names.len()));
    f.insert(
        "timestamp".into(),
        serde_json::json!({"dtype": "float32", "_type": "Value"}),
    );
    for n in ["frame_index", "episode_index", "index", "task_index"] {
        f.insert(
            n.into(),
            serde_json::json!({"dtype": "int64", "_type": "Value"}),
        );
    }
    serde_json::json!({"info": {"features": f}}).to_string()
}

fn fps_json(fps: f64) -> serde_json::Value {
    if fps.fract() == 0.0 {
        serde_json::json!(fps as u64)
    } else {
        serde_json::json!(fps)
    }
}

/// Stages every meta file made from the sidecar, the sidecar first (see [`Staged`]).
pub fn stage_all(
    root: &Path,
    s: &Sidecar,
    data_files_size_mb: u64,
    staged: &mut Staged,
) -> Result<()> {
    let json = |v: &serde_json::Value| serde_json::to_vec_pretty(v).unwrap_or_default();
    stage(
        &root.join("meta/scaledp.json"),
        &serde_json::to_vec_pretty(s).unwrap_or_default(),
        staged,
    )?;
    let total_frames: u64 = s.episodes.iter().map(|e| e.length).sum();
    let intrinsics: Vec<_> = s
        .episodes
        .iter()
        .map(|e| (e.episode_index, &e.intrinsics))
        .collect();
    let info = serde_json::json!({
        "codebase_version": "v3.0",
        "robot_type": s.robot_type,
        "total_episodes": s.episodes.len(),
        "total_frames": total_frames,
        "total_tasks": s.tasks.len(),
        "chunks_size": CHUNKS_SIZE,
        "data_files_size_in_mb": data_files_size_mb,
        "video_files_size_in_mb": VIDEO_FILE_SIZE_MB,
        "fps": fps_json(s.fps),
        "splits": {"train": format!("0:{}", s.episodes.len())},
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": s.video.as_ref().map(|_| "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"),
        "features": features_json(s),
        "scaledp": {
            "converter_version": s.converter_version,
            "rig": s.rig,
            "fps": s.fps,
            "image_size": [s.image_size.0, s.image_size.1],
            "jpeg_quality": s.jpeg_quality,
            "video": s.video,
            "action_space": s.action_space.name(),
            "action": s.action_space.describe(),
            "cameras": super::depth::cameras_json(&s.cameras, &s.depth, &intrinsics),
            "kinematics": "built-in DH models (fr3/panda: modified DH, pose of the Franka Hand TCP — flange + 0.1034 m along z, −45° about z — in fr3_link0; ur5/ur5e: standard DH, pose of tool0 in the DH base frame) unless the rig names a URDF chain or a TCP offset",
            "time_alignment": "ticks at fps on header.stamp capture times, starting a quarter frame period after the latest camera's first frame so synchronised cameras pick the same capture; latest camera frame at or before each tick; joints linearly interpolated",
            "sources": s.episodes.iter().map(|e| serde_json::json!({"episode_index": e.episode_index, "source": e.source, "blake3": e.source_hash})).collect::<Vec<_>>(),
        },
    });
    stage(&root.join("meta/info.json"), &json(&info), staged)?;
    let agg = aggregate_all(s.episodes.iter().map(|e| &e.stats));
    let stats: serde_json::Map<String, serde_json::Value> = agg
        .iter()
        .map(|(k, v)| (k.clone(), v.to_lerobot_json()))
        .collect();
    stage(
        &root.join("meta/stats.json"),
        &json(&serde_json::Value::Object(stats)),
        staged,
    )?;
    write_tasks(root, &s.tasks, staged)?;
    if !s.episodes.is_empty() {
        write_episodes(root, s, staged)?;
    }
    Ok(())
}

/// The episodes metadata's columns of each video key, as LeRobot names them.
fn video_columns(
    root: &Path,
    s: &Sidecar,
    cols: &mut Vec<(String, arrow_array::ArrayRef)>,
) -> Result<()> {
    let spans: Vec<&VideoSpan> = s
        .episodes
        .iter()
        .map(|e| {
            e.video.as_ref().ok_or_else(|| Error::Dataset {
                path: root.into(),
                reason: format!("episode {} has no video span", e.episode_index),
            })
        })
        .collect::<Result<_>>()?;
    for c in &s.cameras {
        let key = format!("videos/observation.images.{c}");
        let files = |f: fn(u64) -> u64| col::i64s(spans.iter().map(move |v| f(v.file) as i64));
        cols.push((format!("{key}/chunk_index"), files(|n| n / CHUNKS_SIZE)));
        cols.push((format!("{key}/file_index"), files(|n| n % CHUNKS_SIZE)));
        cols.push((
            format!("{key}/from_timestamp"),
            col::f64s(spans.iter().map(|v| v.from_timestamp)),
        ));
        cols.push((
            format!("{key}/to_timestamp"),
            col::f64s(spans.iter().map(|v| v.to_timestamp)),
        ));
    }
    Ok(())
}

const PANDAS_TASKS: &str = r#"{"index_columns": ["__index_level_0__"], "column_indexes": [{"name": null, "field_name": null, "pandas_type": "unicode", "numpy_type": "str", "metadata": {"encoding": "UTF-8"}}], "columns": [{"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": null}, {"name": null, "field_name": "__index_level_0__", "pandas_type": "object", "numpy_type": "str", "metadata": null}], "attributes": {}, "creator": {"library": "pyarrow", "version": "26.0.1"}, "pandas_version": "3.1.1"}"#;

fn write_tasks(root: &Path, tasks: &[String], staged: &mut Staged) -> Result<()> {
    if tasks.is_empty() {
        return Ok(());
    }
    let batch = col::batch(
        vec![
            ("task_index".into(), col::i64s(0..tasks.len() as i64)),
            (
                "__index_level_0__".into(),
                col::large_strings(tasks.iter().map(String::as_str)),
            ),
        ],
        vec![("pandas".into(), PANDAS_TASKS.into())],
    )?;
    stage_parquet(&root.join("meta/tasks.parquet"), &[batch], staged).map(drop)
}

fn write_episodes(root: &Path, s: &Sidecar, staged: &mut Staged) -> Result<()> {
    let eps = &s.episodes;
    let n = eps.len();
    let u = |f: fn(&EpisodeRecord) -> u64| col::i64s(eps.iter().map(move |e| f(e) as i64));
    let mut cols = vec![
        ("episode_index".to_string(), u(|e| e.episode_index)),
        (
            "tasks".into(),
            col::string_lists(
                &eps.iter()
                    .map(|e| vec![s.tasks[e.task_index as usize].clone()])
                    .collect::<Vec<_>>(),
            ),
        ),
        ("length".into(), u(|e| e.length)),
        ("data/chunk_index".into(), u(|e| e.data_file / CHUNKS_SIZE)),
        ("data/file_index".into(), u(|e| e.data_file % CHUNKS_SIZE)),
        ("dataset_from_index".into(), u(|e| e.from_index)),
        ("dataset_to_index".into(), u(|e| e.to_index)),
    ];
    if s.video.is_some() {
        video_columns(root, s, &mut cols)?;
    }
    for feature in feature_names(s) {
        let per: Vec<&Stats> = eps
            .iter()
            .map(|e| {
                e.stats.get(&feature).ok_or_else(|| Error::Dataset {
                    path: root.into(),
                    reason: format!("episode {} has no stats for {feature}", e.episode_index),
                })
            })
            .collect::<Result<_>>()?;
        let dim = per[0].mean.len();
        let depth = if per[0].image { 3 } else { 1 };
        let stat = |pick: &dyn Fn(&Stats) -> &Vec<f64>| {
            col::nested_lists(
                col::f64s(per.iter().flat_map(|p| pick(p).iter().copied())),
                n,
                dim,
                depth,
            )
        };
        let ints = |pick: &dyn Fn(&Stats) -> &Vec<f64>| {
            col::nested_lists(
                col::i64s(per.iter().flat_map(|p| pick(p).iter().map(|&v| v as i64))),
                n,
                dim,
                1,
            )
        };
        if per[0].integer {
            cols.push((format!("stats/{feature}/min"), ints(&|p| &p.min)));
            cols.push((format!("stats/{feature}/max"), ints(&|p| &p.max)));
        } else {
            cols.push((format!("stats/{feature}/min"), stat(&|p| &p.min)));
            cols.push((format!("stats/{feature}/max"), stat(&|p| &p.max)));
        }
        cols.push((format!("stats/{feature}/mean"), stat(&|p| &p.mean)));
        cols.push((format!("stats/{feature}/std"), stat(&|p| &p.std)));
        cols.push((
            format!("stats/{feature}/count"),
            col::nested_lists(col::i64s(per.iter().map(|p| p.count as i64)), n, 1, 1),
        ));
        for (k, (_, name)) in QUANTILES.iter().enumerate() {
            cols.push((
                format!("stats/{feature}/{name}"),
                stat(&|p| &p.quantiles[k]),
            ));
        }
    }
    cols.push((
        "meta/episodes/chunk_index".into(),
        col::i64s(std::iter::repeat_n(0, n)),
    ));
    cols.push((
        "meta/episodes/file_index".into(),
        col::i64s(std::iter::repeat_n(0, n)),
    ));
    cols.push((
        "scaledp/source".into(),
        col::strings(eps.iter().map(|e| e.source.as_str())),
    ));
    cols.push((
        "scaledp/source_blake3".into(),
        col::strings(eps.iter().map(|e| e.source_hash.as_str())),
    ));
    cols.push((
        "scaledp/max_camera_skew_s".into(),
        col::f64s(eps.iter().map(|e| e.report.max_camera_skew_s)),
    ));
    cols.push((
        "scaledp/invalid_ticks".into(),
        u(|e| e.report.invalid as u64),
    ));
    cols.push((
        "scaledp/dropped_frames".into(),
        u(|e| e.report.streams.iter().map(|r| r.dropped).sum()),
    ));
    cols.push((
        "scaledp/reordered_messages".into(),
        u(|e| e.report.reordered as u64),
    ));
    recorded_columns(eps, &mut cols);
    let batch = col::batch(cols, vec![])?;
    stage_parquet(
        &root.join("meta/episodes/chunk-000/file-000.parquet"),
        &[batch],
        staged,
    )
    .map(drop)
}

/// The episodes' operator, label and verdict (`scaledp/operator`, `scaledp/label`,
/// `scaledp/verdict`, `scaledp/verdict_by`, `scaledp/verdict_accepted`,
/// `scaledp/verdict_reason`); null where a dataset converted before they were kept has none.
fn recorded_columns(eps: &[EpisodeRecord], cols: &mut Vec<(String, arrow_array::ArrayRef)>) {
    fn r(e: &EpisodeRecord) -> &Recorded {
        &e.recorded
    }
    fn v(e: &EpisodeRecord) -> Option<&crate::recorded::Verdict> {
        e.recorded.verdict.as_ref()
    }
    cols.push((
        "scaledp/operator".into(),
        col::strings(eps.iter().map(|e| r(e).operator.as_str())),
    ));
    cols.push((
        "scaledp/label".into(),
        col::opt_strings(eps.iter().map(|e| r(e).label.as_deref())),
    ));
    cols.push((
        "scaledp/verdict".into(),
        col::opt_strings(eps.iter().map(|e| v(e).map(|v| v.line.as_str()))),
    ));
    cols.push((
        "scaledp/verdict_by".into(),
        col::opt_strings(eps.iter().map(|e| v(e).map(|v| v.by.as_str()))),
    ));
    cols.push((
        "scaledp/verdict_accepted".into(),
        col::opt_bools(eps.iter().map(|e| v(e).map(|v| v.accepted))),
    ));
    cols.push((
        "scaledp/verdict_reason".into(),
        col::opt_strings(eps.iter().map(|e| v(e).and_then(|v| v.reason.as_deref()))),
    ));
}
