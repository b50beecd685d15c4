//! A LeRobot v3.0 dataset that grows one episode at a time and is valid after every episode.
//!
//! Committing an episode first writes, under temporary names and synced, the open data file
//! with the episode's rows added, `meta/scaledp.json` (the authoritative record) and every
//! LeRobot meta file; then renames them into place back to back, data first. Only a kill inside
//! that burst of renames (a few syscalls) can leave rows that no metadata lists; `open` finds
//! and removes them (and any orphan or temporary file), so the next run starts consistent.
//! A data file is closed once it reaches the size target; the next episode starts a new one.

mod columns;
mod depth;
mod layout;
mod meta;
mod repair;
mod videos;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use arrow_array::{ArrayRef, RecordBatch};
use scaledp_codec::EncodedVideo;

use columns::{derr, read_row_group};
pub use depth::{CameraIntrinsics, DepthFeature};
pub use meta::{data_path, EpisodeRecord, Sidecar};
use videos::VideoTail;
pub use videos::{VideoFormat, VideoSpan, VIDEO_FILE_SIZE_MB};

use crate::episode::Episode;
use crate::error::{Error, Result};
use crate::stats::Stats;

/// Where an episode came from, as its record keeps it.
struct Provenance {
    source: String,
    source_hash: String,
    source_etag: Option<String>,
    report: scaledp_align::AlignmentReport,
    time_source: String,
    intrinsics: BTreeMap<String, CameraIntrinsics>,
    recorded: crate::recorded::Recorded,
}

/// The open data file and the episodes (row groups) it holds.
struct Tail {
    file: u64,
    batches: Vec<RecordBatch>,
}

/// A dataset being written.
pub struct Dataset {
    root: PathBuf,
    sidecar: Option<Sidecar>,
    tail: Option<Tail>,
    /// The video file still open (datasets whose cameras are video features).
    video_tail: Option<VideoTail>,
    file_size_mb: u64,
}

impl Dataset {
    /// Opens the dataset at `root` (creating it if absent; emptied first with `overwrite`),
    /// repairing what a killed job may have left.
    pub fn open(root: &Path, overwrite: bool, file_size_mb: u64) -> Result<Self> {
        if overwrite && root.exists() {
            for sub in ["data", "meta", "videos"] {
                let p = root.join(sub);
                if p.exists() {
                    std::fs::remove_dir_all(&p).map_err(Error::io(&p))?;
                }
            }
        }
        std::fs::create_dir_all(root).map_err(Error::io(root))?;
        let record = root.join("meta/scaledp.json");
        let sidecar: Option<Sidecar> = if record.exists() {
            let text = std::fs::read(&record).map_err(Error::io(&record))?;
            Some(
                serde_json::from_slice(&text)
                    .map_err(|e| derr(&record, format!("unreadable: {e}")))?,
            )
        } else if root.join("meta/info.json").exists() {
            return Err(derr(
                root,
                "a LeRobot dataset not written by scaledp; convert into a new directory",
            ));
        } else {
            None
        };
        let mut ds = Self {
            root: root.into(),
            sidecar,
            tail: None,
            video_tail: None,
            file_size_mb,
        };
        ds.repair()?;
        Ok(ds)
    }

    /// A dataset at the local `root` whose committed episodes are `sidecar`'s, their data
    /// files elsewhere (in object storage): nothing is checked or repaired, and new episodes go
    /// to new data files.
    pub fn continue_from(root: &Path, sidecar: Option<Sidecar>, file_size_mb: u64) -> Result<Self> {
        std::fs::create_dir_all(root).map_err(Error::io(root))?;
        Ok(Self {
            root: root.into(),
            sidecar,
            tail: None,
            video_tail: None,
            file_size_mb,
        })
    }

    /// The record of the dataset (None before the first episode).
    pub fn sidecar(&self) -> Option<&Sidecar> {
        self.sidecar.as_ref()
    }

    /// The data file still open for more episodes (the others are complete).
    pub fn open_file(&self) -> Option<u64> {
        self.tail.as_ref().map(|t| t.file)
    }

    /// The dataset's root.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Writes every meta file from the record (as each commit does).
    pub fn write_meta(&self) -> Result<()> {
        if let Some(s) = &self.sidecar {
            let mut staged = columns::Staged::default();
            meta::stage_all(&self.root, s, self.file_size_mb, &mut staged)?;
            staged.commit()?;
        }
        Ok(())
    }

    /// Committed episodes.
    pub fn episodes(&self) -> &[EpisodeRecord] {
        self.sidecar.as_ref().map_or(&[], |s| &s.episodes)
    }

    /// True when an input with this BLAKE3 hash is already in the dataset.
    pub fn contains(&self, source_hash: &str) -> bool {
        self.episodes().iter().any(|e| e.source_hash == source_hash)
    }

    /// Appends a converted episode and commits it: `source_hash` is its input's content hash,
    /// `source_etag` the object version it was read from, if it came from object storage.
    pub fn add(
        &mut self,
        ep: &Episode,
        source_hash: &str,
        source_etag: Option<String>,
    ) -> Result<EpisodeRecord> {
        Self::check_shapes(ep)?;
        self.check_layout(ep)?;
        if self.sidecar.is_none() {
            self.sidecar = Some(Sidecar {
                format: 1,
                fps: ep.fps,
                robot_type: ep.rig.name.clone(),
                rig: toml::to_string(&ep.rig).unwrap_or_default(),
                image_size: ep.image_size,
                jpeg_quality: ep.video.is_none().then_some(ep.jpeg_quality),
                video: ep.video.as_ref().map(VideoFormat::of),
                cameras: ep.cameras.iter().map(|c| c.name.clone()).collect(),
                depth: depth::depth_features(ep),
                state_names: ep.state_names.clone(),
                action_space: ep.action_space,
                joint_names: ep.joint_names.clone(),
                tasks: vec![],
                episodes: vec![],
                converter_version: env!("CARGO_PKG_VERSION").into(),
            });
        }
        let n = ep.len();
        let mut cols: Vec<(String, ArrayRef)> = ep
            .cameras
            .iter()
            .filter(|c| c.video.is_none())
            .map(|c| {
                (
                    format!("observation.images.{}", c.name),
                    columns::images(&c.jpeg),
                )
            })
            .collect();
        let (w, h) = ep.image_size;
        for c in &ep.cameras {
            if let Some(d) = &c.depth {
                let col = depth::column(&d.frames, d.encoding, w, h);
                cols.push((depth::key(&c.name), col));
            }
        }
        let dim = ep.state_names.len();
        cols.push((
            "observation.state".into(),
            columns::fixed_f32(&ep.state, dim),
        ));
        cols.push(("action".into(), columns::fixed_f32(&ep.action, dim)));
        cols.push((
            "observation.joints".into(),
            columns::fixed_f32(&ep.joints, ep.joint_names.len()),
        ));
        cols.push(("timestamp".into(), columns::f32s(&ep.timestamps)));
        cols.push(("frame_index".into(), columns::i64s(0..n as i64)));
        let mut stats = BTreeMap::new();
        let f64v = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
        stats.insert(
            "observation.state".to_string(),
            Stats::of_rows(&f64v(&ep.state), dim),
        );
        stats.insert("action".into(), Stats::of_rows(&f64v(&ep.action), dim));
        stats.insert(
            "observation.joints".into(),
            Stats::of_rows(&f64v(&ep.joints), ep.joint_names.len()),
        );
        stats.insert("timestamp".into(), Stats::of_rows(&f64v(&ep.timestamps), 1));
        stats.insert(
            "frame_index".into(),
            Stats::of_integers(&(0..n as i64).collect::<Vec<_>>()),
        );
        for c in &ep.cameras {
            stats.insert(
                format!("observation.images.{}", c.name),
                Stats::of_image(&c.histogram),
            );
            if let Some(d) = &c.depth {
                stats.insert(depth::key(&c.name), d.stats.clone());
            }
        }
        let provenance = Provenance {
            source: ep.source.display().to_string(),
            source_hash: source_hash.into(),
            source_etag,
            report: ep.report.clone(),
            time_source: ep.time_source.clone(),
            intrinsics: depth::episode_intrinsics(ep),
            recorded: ep.recorded.clone(),
        };
        let streams: Vec<EncodedVideo> =
            ep.cameras.iter().filter_map(|c| c.video.clone()).collect();
        let video = (!streams.is_empty()).then_some(streams);
        self.commit(cols, n, &ep.task, stats, provenance, video)
    }

    /// Appends one episode of another scaledp dataset (for `merge`), re-indexed.
    pub fn add_from(
        &mut self,
        other: &Path,
        o: &Sidecar,
        rec: &EpisodeRecord,
    ) -> Result<EpisodeRecord> {
        if o.video.is_some() {
            return Err(derr(
                other,
                "its cameras are video features; merging video datasets is not supported yet",
            ));
        }
        match &self.sidecar {
            None => {
                let mut s = o.clone();
                s.tasks.clear();
                s.episodes.clear();
                self.sidecar = Some(s);
            }
            Some(s)
                if s.cameras != o.cameras
                    || s.depth != o.depth
                    || s.state_names != o.state_names
                    || s.action_space != o.action_space
                    || s.joint_names != o.joint_names
                    || s.image_size != o.image_size
                    || s.jpeg_quality != o.jpeg_quality
                    || (s.fps - o.fps).abs() > 1e-9 =>
            {
                return Err(derr(other, "its features differ from the merged dataset's"));
            }
            Some(_) => {}
        }
        let path = data_path(other, rec.data_file);
        let group = o
            .episodes
            .iter()
            .filter(|e| e.data_file == rec.data_file)
            .position(|e| e.episode_index == rec.episode_index)
            .unwrap_or(0);
        let batch = read_row_group(&path, group)?;
        let keep = ["episode_index", "index", "task_index"];
        let cols: Vec<(String, ArrayRef)> = batch
            .schema()
            .fields()
            .iter()
            .zip(batch.columns())
            .filter(|(f, _)| !keep.contains(&f.name().as_str()))
            .map(|(f, a)| (f.name().clone(), a.clone()))
            .collect();
        let mut stats = rec.stats.clone();
        for k in keep {
            stats.remove(k);
        }
        let task = &o.tasks[rec.task_index as usize];
        let frames = batch.num_rows();
        let provenance = Provenance {
            source: rec.source.clone(),
            source_hash: rec.source_hash.clone(),
            source_etag: rec.source_etag.clone(),
            report: rec.report.clone(),
            time_source: rec.time_source.clone(),
            intrinsics: rec.intrinsics.clone(),
            recorded: rec.recorded.clone(),
        };
        self.commit(cols, frames, task, stats, provenance, None)
    }

    fn commit(
        &mut self,
        mut cols: Vec<(String, ArrayRef)>,
        n: usize,
        task: &str,
        mut stats: BTreeMap<String, Stats>,
        provenance: Provenance,
        video: Option<Vec<EncodedVideo>>,
    ) -> Result<EpisodeRecord> {
        let s = self
            .sidecar
            .as_mut()
            .ok_or_else(|| derr(&self.root, "no layout"))?;
        let task_index = match s.tasks.iter().position(|t| t == task) {
            Some(i) => i,
            None => {
                s.tasks.push(task.into());
                s.tasks.len() - 1
            }
        } as u64;
        let episode_index = s.episodes.len() as u64;
        let from = s.episodes.last().map_or(0, |e| e.to_index);
        let to = from + n as u64;
        stats.insert(
            "episode_index".into(),
            Stats::of_integers(&vec![episode_index as i64; n]),
        );
        stats.insert(
            "index".into(),
            Stats::of_integers(&(from as i64..to as i64).collect::<Vec<_>>()),
        );
        stats.insert(
            "task_index".into(),
            Stats::of_integers(&vec![task_index as i64; n]),
        );
        cols.push((
            "episode_index".into(),
            columns::i64s(std::iter::repeat_n(episode_index as i64, n)),
        ));
        cols.push(("index".into(), columns::i64s(from as i64..to as i64)));
        cols.push((
            "task_index".into(),
            columns::i64s(std::iter::repeat_n(task_index as i64, n)),
        ));
        let hf = meta::huggingface_metadata(s);
        let batch = columns::batch(cols, vec![("huggingface".into(), hf)])?;

        let next_file = s
            .episodes
            .iter()
            .map(|e| e.data_file + 1)
            .max()
            .unwrap_or(0);
        let tail = self.tail.get_or_insert(Tail {
            file: next_file,
            batches: vec![],
        });
        tail.batches.push(batch);
        let path = data_path(&self.root, tail.file);
        // Everything is written under temporary names first; the renames then follow one
        // another with nothing in between, so the window in which a kill leaves rows that no
        // metadata lists is a few syscalls long (and `open` repairs even that).
        let mut staged = columns::Staged::default();
        let size = columns::stage_parquet(&path, &tail.batches, &mut staged)?;
        let video = match video {
            None => None,
            Some(streams) => Some(stage_video(
                &self.root,
                &mut self.video_tail,
                s,
                streams,
                n as u64,
                &mut staged,
            )?),
        };
        let record = EpisodeRecord {
            episode_index,
            length: n as u64,
            task_index,
            data_file: tail.file,
            from_index: from,
            to_index: to,
            source: provenance.source,
            source_hash: provenance.source_hash,
            source_etag: provenance.source_etag,
            stats,
            report: provenance.report,
            time_source: provenance.time_source,
            video: video.as_ref().map(|v| v.0.clone()),
            intrinsics: provenance.intrinsics,
            recorded: provenance.recorded,
        };
        if video.is_some_and(|v| v.1 >= VIDEO_FILE_SIZE_MB << 20) {
            self.video_tail = None;
        }
        if size >= self.file_size_mb << 20 {
            self.tail = None;
        }
        s.episodes.push(record.clone());
        meta::stage_all(&self.root, s, self.file_size_mb, &mut staged)?;
        staged.commit()?;
        Ok(record)
    }
}

/// Appends an episode's streams to the open video file (a new one when none is open or the
/// streams do not fit it) and stages its MP4s; the episode's span and the largest MP4's size.
fn stage_video(
    root: &Path,
    tail: &mut Option<VideoTail>,
    s: &Sidecar,
    streams: Vec<EncodedVideo>,
    frames: u64,
    staged: &mut columns::Staged,
) -> Result<(VideoSpan, u64)> {
    let refs: Vec<&EncodedVideo> = streams.iter().collect();
    if tail.as_ref().is_some_and(|t| !t.accepts(&refs)) {
        *tail = None;
    }
    let t = tail.get_or_insert_with(|| {
        let next = s
            .episodes
            .iter()
            .filter_map(|e| e.video.as_ref().map(|v| v.file + 1))
            .max()
            .unwrap_or(0);
        VideoTail::new(next, s.cameras.len())
    });
    let keys: Vec<String> = s
        .cameras
        .iter()
        .map(|c| format!("observation.images.{c}"))
        .collect();
    t.add_and_stage(root, &keys, streams, frames, s.fps, staged)
}
