//! LeRobot v3.0 datasets (ours or LeRobot's, local or `s3://`): an episode's stored frames at
//! their frame index and timestamp, its state and action, and the episode's metadata. Frames
//! stream from the data file in small batches (only the episode's rows, one camera column at a
//! time), so memory stays at a few frames whatever the dataset's size.

use std::collections::BTreeMap;

use parquet::arrow::arrow_reader::{ParquetRecordBatchReaderBuilder, RowSelection, RowSelector};
use parquet::arrow::ProjectionMask;
use rerun::{RecordingStream, TextLog};
use scaledp_converter::Sidecar;
use scaledp_datasets::DatasetFiles;
use scaledp_schema::rig::Rig;
use scaledp_schema::ActionSpace;
use serde::Deserialize;

use crate::columns::{image_bytes, ints, strings, vectors};
use crate::episode::{log_rows, predicted_rows, Prediction, Rows};
use crate::error::{Error, Result};
use crate::images::encoded_frame;
use crate::layout;

/// Rows per batch read for images.
const IMAGE_BATCH: usize = 16;

#[derive(Debug, Clone, Deserialize)]
struct Feature {
    dtype: String,
    #[serde(default)]
    names: Option<serde_json::Value>,
}

impl Feature {
    fn names(&self) -> Vec<String> {
        match &self.names {
            Some(serde_json::Value::Array(a)) => a
                .iter()
                .filter_map(|v| v.as_str().map(String::from))
                .collect(),
            Some(serde_json::Value::Object(o)) => o
                .values()
                .next()
                .and_then(|v| v.as_array())
                .map(|a| {
                    a.iter()
                        .filter_map(|v| v.as_str().map(String::from))
                        .collect()
                })
                .unwrap_or_default(),
            _ => Vec::new(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
struct Info {
    codebase_version: String,
    fps: f64,
    #[serde(default)]
    robot_type: Option<String>,
    #[serde(default = "default_data_path")]
    data_path: String,
    features: BTreeMap<String, Feature>,
}

fn default_data_path() -> String {
    "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet".into()
}

/// One row of `meta/episodes`.
#[derive(Debug, Clone, Default)]
pub(crate) struct EpisodeMeta {
    /// `episode_index`.
    pub index: u64,
    length: u64,
    tasks: String,
    chunk: u64,
    file: u64,
    /// Other scalar columns worth showing (`scaledp/*`), as text.
    extra: BTreeMap<String, String>,
}

/// A dataset opened for viewing.
pub(crate) struct Dataset {
    files: DatasetFiles,
    location: String,
    info: Info,
    /// Every episode, by index.
    pub episodes: Vec<EpisodeMeta>,
    sidecar: Option<Sidecar>,
}

fn format_path(template: &str, chunk: u64, file: u64) -> String {
    template
        .replace("{chunk_index:03d}", &format!("{chunk:03}"))
        .replace("{file_index:03d}", &format!("{file:03}"))
        .replace("{chunk_index}", &chunk.to_string())
        .replace("{file_index}", &file.to_string())
}

impl Dataset {
    /// Reads `meta/info.json`, `meta/episodes/**.parquet` and (ours) `meta/scaledp.json`.
    pub fn open(location: &str) -> Result<Self> {
        let files = DatasetFiles::open(location)?;
        let info_rel = "meta/info.json";
        let info: Info = serde_json::from_slice(&files.read(info_rel)?)
            .map_err(|e| Error::input(files.describe(info_rel), e))?;
        if !info.codebase_version.starts_with("v3") {
            return Err(Error::input(
                files.describe(info_rel),
                format!(
                    "codebase_version {} (the viewer reads LeRobot v3.x)",
                    info.codebase_version
                ),
            ));
        }
        let sidecar = files
            .read("meta/scaledp.json")
            .ok()
            .and_then(|b| serde_json::from_slice::<Sidecar>(&b).ok());
        let mut episodes = Vec::new();
        for rel in files.list("meta/episodes", ".parquet")? {
            read_episodes(&files, &rel, &mut episodes)?;
        }
        episodes.sort_by_key(|e| e.index);
        Ok(Self {
            files,
            location: location.to_string(),
            info,
            episodes,
            sidecar,
        })
    }

    /// A name for recordings of this dataset: its last path part.
    pub fn name(&self) -> String {
        self.location
            .trim_end_matches('/')
            .rsplit('/')
            .next()
            .unwrap_or("dataset")
            .to_string()
    }

    /// The location, for messages.
    pub fn location(&self) -> &str {
        &self.location
    }

    /// The rig the dataset was converted with (ours), or `rig` given.
    /// The space of the state and action (the converter's sidecar says; TCP poses without one).
    fn space(&self) -> ActionSpace {
        self.sidecar
            .as_ref()
            .map(|s| s.action_space)
            .unwrap_or_default()
    }

    fn rig(&self, given: Option<&Rig>) -> Option<Rig> {
        given.cloned().or_else(|| {
            let s = self.sidecar.as_ref()?;
            Rig::parse(&s.rig, std::path::Path::new("meta/scaledp.json")).ok()
        })
    }

    /// Logs episode `ep` into `rec`; returns the frames logged per camera entity.
    pub fn show_episode(
        &self,
        rec: &RecordingStream,
        ep: &EpisodeMeta,
        rig: Option<&Rig>,
        max_width: Option<u32>,
        chunk: usize,
        prediction: Option<&Prediction>,
    ) -> Result<(usize, BTreeMap<String, u64>, Vec<String>)> {
        let rel = format_path(&self.info.data_path, ep.chunk, ep.file);
        let file = self.files.parquet(&rel)?;
        let name = self.files.describe(&rel);
        let bad = |e: &dyn std::fmt::Display| Error::input(&name, e);
        let builder =
            ParquetRecordBatchReaderBuilder::try_new(file.clone()).map_err(|e| bad(&e))?;
        let schema = builder.schema().clone();
        let parquet_schema = builder.parquet_schema().clone();
        let root = |k: &str| schema.index_of(k).ok();
        // Rows of the episode: one pass over `episode_index`.
        let ep_col = root("episode_index").ok_or_else(|| bad(&"no episode_index column"))?;
        let reader = builder
            .with_projection(ProjectionMask::roots(&parquet_schema, [ep_col]))
            .with_batch_size(65536)
            .build()
            .map_err(|e| bad(&e))?;
        let (mut first, mut count, mut row) = (None, 0usize, 0usize);
        for batch in reader {
            let batch = batch.map_err(|e| bad(&e))?;
            for (i, e) in ints(batch.column(0))
                .map_err(|e| bad(&e))?
                .into_iter()
                .enumerate()
            {
                if e == ep.index as i64 {
                    first.get_or_insert(row + i);
                    count += 1;
                }
            }
            row += batch.num_rows();
        }
        let first = first.ok_or_else(|| bad(&format!("no rows of episode {}", ep.index)))?;
        let selection =
            RowSelection::from(vec![RowSelector::skip(first), RowSelector::select(count)]);
        let read = |cols: Vec<usize>, batch: usize| -> Result<_> {
            ParquetRecordBatchReaderBuilder::try_new(file.clone())
                .map_err(|e| bad(&e))?
                .with_projection(ProjectionMask::roots(&parquet_schema, cols))
                .with_row_selection(selection.clone())
                .with_batch_size(batch)
                .build()
                .map_err(|e| bad(&e))
        };
        // Small columns, whole episode.
        let keys = [
            "frame_index",
            "timestamp",
            "observation.state",
            "action",
            "observation.joints",
        ];
        let cols: Vec<usize> = keys.iter().filter_map(|k| root(k)).collect();
        let mut frame_index = Vec::new();
        let mut timestamps = Vec::new();
        let mut rows = Rows {
            state_names: self.feature_names("observation.state"),
            action_names: self.feature_names("action"),
            joint_names: self.feature_names("observation.joints"),
            plot_joints: true,
            space: self.space(),
            ..Rows::default()
        };
        for batch in read(cols, 65536)? {
            let batch = batch.map_err(|e| bad(&e))?;
            let col = |k: &str| batch.column_by_name(k);
            if let Some(c) = col("frame_index") {
                frame_index.extend(ints(c).map_err(|e| bad(&format!("frame_index: {e}")))?);
            }
            if let Some(c) = col("timestamp") {
                timestamps.extend(
                    vectors(c)
                        .map_err(|e| bad(&format!("timestamp: {e}")))?
                        .into_iter()
                        .map(|v| v.first().copied().unwrap_or(0.0)),
                );
            }
            for (k, dst) in [
                ("observation.state", &mut rows.state),
                ("action", &mut rows.action),
                ("observation.joints", &mut rows.joints),
            ] {
                if let Some(c) = col(k) {
                    dst.extend(vectors(c).map_err(|e| bad(&format!("{k}: {e}")))?);
                }
            }
        }
        let fps = self.info.fps.max(1e-9);
        let time = |t: usize| -> (i64, f64) {
            let f = frame_index.get(t).copied().unwrap_or(t as i64);
            let s = timestamps.get(t).map_or(f as f64 / fps, |&s| f64::from(s));
            (f, s)
        };
        let at = |t: usize| {
            let (f, s) = time(t);
            rec.set_time_sequence(layout::FRAME_INDEX, f);
            rec.set_duration_secs(layout::TIMESTAMP, s);
        };
        if let Some(p) = prediction {
            rows.predicted =
                predicted_rows(&p.frames, &p.values, &frame_index, rows.action_names.len())
                    .map_err(|e| bad(&e))?;
        }
        let rig = self.rig(rig);
        log_rows(rec, &rows, rig.as_ref(), chunk, &at)?;
        // Images: one camera column at a time, a few rows per batch.
        let mut frames = BTreeMap::new();
        let mut warnings = Vec::new();
        let mut pace = crate::sink::Backpressure::default();
        for (key, f) in &self.info.features {
            if f.dtype == "video" {
                warnings.push(format!(
                    "{key}: video features are not shown (image features only)"
                ));
                continue;
            }
            if let (Some(c), Some(camera)) = (root(key), key.strip_prefix("observation.depth.")) {
                let entity = layout::depth(camera);
                let batches = read(vec![c], IMAGE_BATCH)?;
                let n = crate::depth::log_column(rec, &entity, batches, max_width, &at)
                    .map_err(|e| bad(&format!("{key}: {e}")))?;
                *frames.entry(entity).or_insert(0u64) += n;
                continue;
            }
            let (Some(c), true) = (root(key), f.dtype == "image") else {
                continue;
            };
            let camera = key.strip_prefix("observation.images.").unwrap_or(key);
            let entity = layout::camera(camera);
            let mut t = 0usize;
            for batch in read(vec![c], IMAGE_BATCH)? {
                let batch = batch.map_err(|e| bad(&e))?;
                for bytes in
                    image_bytes(batch.column(0)).map_err(|e| bad(&format!("{key}: {e}")))?
                {
                    at(t);
                    match encoded_frame(bytes, max_width) {
                        Ok(frame) => {
                            frame.log(rec, &entity).map_err(Error::rerun)?;
                            *frames.entry(entity.clone()).or_insert(0u64) += 1;
                            pace.logged(rec, bytes.len())?;
                        }
                        Err(e) => warnings.push(format!("{key} frame {}: {e}", time(t).0)),
                    }
                    t += 1;
                }
            }
        }
        self.log_meta(rec, ep, &warnings)?;
        Ok((count, frames, warnings))
    }

    fn feature_names(&self, key: &str) -> Vec<String> {
        self.info
            .features
            .get(key)
            .map(Feature::names)
            .unwrap_or_default()
    }

    /// Text log at the first frame: task, source, quality figures, conversion details.
    fn log_meta(&self, rec: &RecordingStream, ep: &EpisodeMeta, warnings: &[String]) -> Result<()> {
        rec.set_time_sequence(layout::FRAME_INDEX, 0);
        rec.set_duration_secs(layout::TIMESTAMP, 0.0);
        let mut lines = vec![
            format!(
                "dataset {} episode {} ({} frames at {} fps)",
                self.location, ep.index, ep.length, self.info.fps
            ),
            format!("task: {}", ep.tasks),
        ];
        if let Some(r) = &self.info.robot_type {
            lines.push(format!("robot type: {r}"));
        }
        lines.extend(ep.extra.iter().map(|(k, v)| format!("{k}: {v}")));
        if let Some(rec_meta) = self
            .sidecar
            .as_ref()
            .and_then(|s| s.episodes.iter().find(|e| e.episode_index == ep.index))
        {
            let r = &rec_meta.report;
            lines.push(format!(
                "alignment ({}): {} ticks, {} trimmed, {} invalid, max camera skew {:.1} ms, max frame age {:.1} ms",
                rec_meta.time_source, r.ticks, r.trimmed, r.invalid, r.max_camera_skew_s * 1e3, r.max_frame_age_s * 1e3
            ));
            for s in r.streams.iter().filter(|s| s.gaps > 0) {
                lines.push(format!(
                    "{}: {} gaps, {} dropped, longest interval {:.3} s",
                    s.topic, s.gaps, s.dropped, s.max_interval_s
                ));
            }
        }
        for l in lines {
            rec.log(layout::LOG, &TextLog::new(l))
                .map_err(Error::rerun)?;
        }
        for w in warnings {
            rec.log(
                layout::LOG,
                &TextLog::new(w.as_str()).with_level(rerun::TextLogLevel::WARN),
            )
            .map_err(Error::rerun)?;
        }
        Ok(())
    }

    /// Camera entity paths and arm names, for the blueprint.
    pub fn shape(&self, rig: Option<&Rig>) -> layout::Shape {
        let cameras = self
            .info
            .features
            .iter()
            .filter_map(|(k, f)| match k.strip_prefix("observation.depth.") {
                Some(camera) => Some(layout::depth(camera)),
                None if f.dtype == "image" => Some(layout::camera(
                    k.strip_prefix("observation.images.").unwrap_or(k),
                )),
                None => None,
            })
            .collect();
        let rig = self.rig(rig);
        let space = self.space();
        layout::Shape {
            cameras,
            arms: rig
                .iter()
                .flat_map(|r| r.arms.iter().map(|a| a.name.clone()))
                .collect(),
            dims: rig
                .iter()
                .flat_map(|r| r.arms.iter().map(|a| crate::space::labels(a, space)))
                .collect(),
            space,
            topics: Vec::new(),
            quality: false,
            timeline: layout::FRAME_INDEX,
        }
    }
}

/// Appends the rows of one `meta/episodes` file.
fn read_episodes(files: &DatasetFiles, rel: &str, out: &mut Vec<EpisodeMeta>) -> Result<()> {
    let name = files.describe(rel);
    let bad = |e: &dyn std::fmt::Display| Error::input(&name, e);
    let builder =
        ParquetRecordBatchReaderBuilder::try_new(files.parquet(rel)?).map_err(|e| bad(&e))?;
    let schema = builder.schema().clone();
    let wanted: Vec<usize> = schema
        .fields()
        .iter()
        .enumerate()
        .filter(|(_, f)| {
            let n = f.name();
            matches!(
                n.as_str(),
                "episode_index" | "tasks" | "length" | "data/chunk_index" | "data/file_index"
            ) || n.starts_with("scaledp/")
        })
        .map(|(i, _)| i)
        .collect();
    let mask = ProjectionMask::roots(builder.parquet_schema(), wanted);
    for batch in builder.with_projection(mask).build().map_err(|e| bad(&e))? {
        let batch = batch.map_err(|e| bad(&e))?;
        let int = |k: &str| -> Result<Vec<i64>> {
            match batch.column_by_name(k) {
                Some(c) => ints(c).map_err(|e| bad(&format!("{k}: {e}"))),
                None => Ok(vec![0; batch.num_rows()]),
            }
        };
        let (index, length, chunk, file) = (
            int("episode_index")?,
            int("length")?,
            int("data/chunk_index")?,
            int("data/file_index")?,
        );
        let tasks = match batch.column_by_name("tasks") {
            Some(c) => strings(c).map_err(|e| bad(&format!("tasks: {e}")))?,
            None => vec![String::new(); batch.num_rows()],
        };
        for i in 0..batch.num_rows() {
            let mut extra = BTreeMap::new();
            for (f, c) in batch.schema().fields().iter().zip(batch.columns()) {
                if !f.name().starts_with("scaledp/") {
                    continue;
                }
                let v = strings(c)
                    .ok()
                    .and_then(|s| s.get(i).cloned())
                    .or_else(|| ints(c).ok().and_then(|v| v.get(i).map(i64::to_string)))
                    .or_else(|| {
                        crate::columns::floats(c.as_ref())
                            .ok()
                            .and_then(|v| v.get(i).map(|x| format!("{x:.4}")))
                    });
                if let Some(v) = v {
                    extra.insert(f.name().trim_start_matches("scaledp/").to_string(), v);
                }
            }
            out.push(EpisodeMeta {
                index: index[i] as u64,
                length: length[i] as u64,
                tasks: tasks[i].clone(),
                chunk: chunk[i] as u64,
                file: file[i] as u64,
                extra,
            });
        }
    }
    Ok(())
}
